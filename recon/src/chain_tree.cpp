#include "chain_tree.hpp"

#include <algorithm>
#include <cmath>

#include "mean_value.hpp"

namespace sonoshape::recon {
namespace {

// Edges per leaf: below this a node is summed edge by edge.
constexpr std::uint32_t kLeafEdges = 8;
// Opening criterion: a node is used whole when its bounding radius is below this fraction of its
// distance to the point (region-term error of order kOpening^3, measured in chain_tree_test).
constexpr double kOpening = 0.1;

std::uint32_t build(const Vec2* points, std::size_t count, std::uint32_t first, std::uint32_t last,
                    std::vector<ChainNode>& nodes) {
  const std::uint32_t index = static_cast<std::uint32_t>(nodes.size());
  nodes.emplace_back();
  ChainNode node;
  node.first = first;
  node.last = last;
  auto point = [&](std::uint32_t i) -> const Vec2& { return points[i % count]; };
  Vec2 lo = point(first), hi = lo;
  for (std::uint32_t i = first; i <= last; ++i) {
    lo = lo.cwiseMin(point(i));
    hi = hi.cwiseMax(point(i));
  }
  node.centre = 0.5 * (lo + hi);
  for (std::uint32_t i = first; i <= last; ++i)
    node.radius_sq = std::max(node.radius_sq, (point(i) - node.centre).squaredNorm());
  // Area and moments of the closed loop first .. last -> first (Green's theorem), about the centre.
  for (std::uint32_t i = first; i <= last; ++i) {
    const Vec2 p = point(i) - node.centre;
    const Vec2 q = (i == last ? point(first) : point(i + 1)) - node.centre;
    const double cross = p.x() * q.y() - q.x() * p.y();
    node.area += 0.5 * cross;
    node.m1x += (p.x() + q.x()) * cross / 6.0;
    node.m1y += (p.y() + q.y()) * cross / 6.0;
    node.m2xx += (p.x() * p.x() + p.x() * q.x() + q.x() * q.x()) * cross / 12.0;
    node.m2yy += (p.y() * p.y() + p.y() * q.y() + q.y() * q.y()) * cross / 12.0;
    node.m2xy += (p.x() * q.y() + 2.0 * p.x() * p.y() + 2.0 * q.x() * q.y() + q.x() * p.y()) * cross / 24.0;
  }
  if (last - first > kLeafEdges) {
    const std::uint32_t middle = first + (last - first) / 2;
    node.left = static_cast<std::int32_t>(build(points, count, first, middle, nodes));
    node.right = static_cast<std::int32_t>(build(points, count, middle, last, nodes));
  }
  nodes[index] = node;
  return index;
}

// Second-order Taylor expansion of the integral of K = 2 h^2 / (|y - foot|^2 + h^2)^2 over the
// node's region, about its centre: with d = centre - foot and s = |d|^2 + h^2,
// K = 2h^2/s^2, grad K = -8h^2 d / s^3, Hessian = 48 h^2 d d^T / s^4 - 8 h^2 I / s^3.
double region_term(const ChainNode& node, const Vec2& d, double s, double h2) {
  const double inv_s = 1.0 / s;
  const double inv_s2 = inv_s * inv_s;
  const double d_m1 = d.x() * node.m1x + d.y() * node.m1y;
  const double d_m2_d = d.x() * d.x() * node.m2xx + 2.0 * d.x() * d.y() * node.m2xy + d.y() * d.y() * node.m2yy;
  return h2 * inv_s2 * (2.0 * node.area - 8.0 * inv_s * d_m1 + 24.0 * inv_s2 * d_m2_d -
                        4.0 * inv_s * (node.m2xx + node.m2yy));
}

// Visits the tree: `far(node, d, s)` for nodes used whole, `edge(a, b)` (relative to the foot)
// for the edges of opened leaves. Returns false as soon as a callback does.
template <typename Far, typename Edge>
bool visit(const Vec2* points, std::size_t count, const ChainNode* nodes, std::uint32_t root,
           const Vec2& foot, double h2, Far&& far, Edge&& edge) {
  std::uint32_t stack[64];
  int top = 0;
  stack[top++] = root;
  const double opening_sq = kOpening * kOpening;
  while (top > 0) {
    const ChainNode& node = nodes[stack[--top]];
    const Vec2 d = node.centre - foot;
    const double s = d.squaredNorm() + h2;
    if (node.radius_sq < opening_sq * s) {
      if (!far(node, d, s)) return false;
      continue;
    }
    if (node.left < 0) {
      Vec2 a = points[node.first % count] - foot;
      for (std::uint32_t i = node.first; i < node.last; ++i) {
        const Vec2 b = points[(i + 1) % count] - foot;
        if (!edge(a, b)) return false;
        a = b;
      }
      continue;
    }
    stack[top++] = static_cast<std::uint32_t>(node.right);
    stack[top++] = static_cast<std::uint32_t>(node.left);
  }
  return true;
}

}  // namespace

std::uint32_t build_chain_tree(const Vec2* points, std::size_t count, std::vector<ChainNode>& nodes) {
  return build(points, count, 0, static_cast<std::uint32_t>(count), nodes);
}

double projected_angle_tree(const Vec2* points, std::size_t count, const ChainNode* nodes,
                            std::uint32_t root, const Vec2& foot, double height) {
  const double plain = projected_angle_tree_plain(points, count, nodes, root, foot, height);
  if (std::abs(plain) >= kSplitBelow || count < 2 || !(height > 0.0)) return plain;
  // A foot outside the ring: the same sum in the cancellation-free split (mean_value.cpp).
  const double h2 = height * height;
  double planar = 0.0, remainder = 0.0;
  const bool split = visit(
      points, count, nodes, root, foot, h2,
      [&](const ChainNode& node, const Vec2& d, double s) {
        remainder += region_term(node, d, s, h2);
        return edge_projected_angle_split(points[node.first % count] - foot,
                                          points[node.last % count] - foot, h2, planar, remainder);
      },
      [&](const Vec2& a, const Vec2& b) { return edge_projected_angle_split(a, b, h2, planar, remainder); });
  return split ? split_result(planar, remainder, plain) : plain;
}

double projected_angle_tree_plain(const Vec2* points, std::size_t count, const ChainNode* nodes,
                                  std::uint32_t root, const Vec2& foot, double height) {
  if (count < 2 || !(height > 0.0)) return 0.0;
  const double h2 = height * height;
  double plain = 0.0;
  visit(points, count, nodes, root, foot, h2,
        [&](const ChainNode& node, const Vec2& d, double s) {
          plain += edge_projected_angle(points[node.first % count] - foot,
                                        points[node.last % count] - foot, h2) +
                   region_term(node, d, s, h2);
          return true;
        },
        [&](const Vec2& a, const Vec2& b) {
          plain += edge_projected_angle(a, b, h2);
          return true;
        });
  return plain;
}

}  // namespace sonoshape::recon
