#include "chain_tree.hpp"

#include <algorithm>
#include <cmath>

#include "mean_value.hpp"

namespace sonoshape::recon {
namespace {

// Edges per leaf: below this a node is summed edge by edge.
constexpr std::uint32_t kLeafEdges = 8;
// Opening criterion: a node is used whole when its bounding radius is below this fraction of its
// distance to the point (region-term error of order kOpening^5, measured in chain_tree_test).
constexpr double kOpening = 0.2;

// The integral of x^a y^b over a loop's region, from its edge p -> q (coordinates about the
// node's centre), by Green's theorem: for a polygon, the sum over its edges of
//   cross(p, q) sum_{k<=a, l<=b} C(k+l, l) C(a+b-k-l, b-l) q.x^k p.x^(a-k) q.y^l p.y^(b-l)
//   / ((a+b+2)(a+b+1) C(a+b, a)).
// Powers: px[n] = p.x^n and so on. A template, so that the loops unroll and the constants fold
// (the trees are built for every long part of every face image the online engine rebuilds).
constexpr double kBinomial[5][5] = {
    {1, 0, 0, 0, 0}, {1, 1, 0, 0, 0}, {1, 2, 1, 0, 0}, {1, 3, 3, 1, 0}, {1, 4, 6, 4, 1}};
template <int A, int B>
double edge_moment(const double* px, const double* py, const double* qx, const double* qy) {
  double sum = 0.0;
  for (int k = 0; k <= A; ++k)
    for (int l = 0; l <= B; ++l)
      sum += kBinomial[k + l][l] * kBinomial[A + B - k - l][B - l] * qx[k] * px[A - k] * qy[l] *
             py[B - l];
  constexpr double kScale = 1.0 / ((A + B + 2) * (A + B + 1) * kBinomial[A + B][A]);
  return kScale * sum;
}

// Adds the edge p -> q of a closed loop to the node's third and fourth moments.
void add_high_moments(const Vec2& p, const Vec2& q, ChainNode& node) {
  const double cross = p.x() * q.y() - q.x() * p.y();
  double px[5] = {1, p.x()}, py[5] = {1, p.y()}, qx[5] = {1, q.x()}, qy[5] = {1, q.y()};
  for (int n = 2; n <= 4; ++n) {
    px[n] = px[n - 1] * p.x();
    py[n] = py[n - 1] * p.y();
    qx[n] = qx[n - 1] * q.x();
    qy[n] = qy[n - 1] * q.y();
  }
  node.m3[0] += cross * edge_moment<3, 0>(px, py, qx, qy);
  node.m3[1] += cross * edge_moment<2, 1>(px, py, qx, qy);
  node.m3[2] += cross * edge_moment<1, 2>(px, py, qx, qy);
  node.m3[3] += cross * edge_moment<0, 3>(px, py, qx, qy);
  node.m4[0] += cross * edge_moment<4, 0>(px, py, qx, qy);
  node.m4[1] += cross * edge_moment<3, 1>(px, py, qx, qy);
  node.m4[2] += cross * edge_moment<2, 2>(px, py, qx, qy);
  node.m4[3] += cross * edge_moment<1, 3>(px, py, qx, qy);
  node.m4[4] += cross * edge_moment<0, 4>(px, py, qx, qy);
}

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
    node.m2xy +=
        (p.x() * q.y() + 2.0 * p.x() * p.y() + 2.0 * q.x() * q.y() + q.x() * p.y()) * cross / 24.0;
    add_high_moments(p, q, node);
  }
  if (last - first > kLeafEdges) {
    const std::uint32_t middle = first + (last - first) / 2;
    node.left = static_cast<std::int32_t>(build(points, count, first, middle, nodes));
    node.right = static_cast<std::int32_t>(build(points, count, middle, last, nodes));
  }
  nodes[index] = node;
  return index;
}

// Fourth-order Taylor expansion of the integral of K = 2 h^2 / (|y - foot|^2 + h^2)^2 over the
// node's region, about its centre: with d = centre - foot, s = |d|^2 + h^2 and y = centre + z,
//   K = 2 h^2 / s^2 (1 + u)^-2,  u = a + b,  a = 2 d.z / s,  b = |z|^2 / s,
// and (1 + u)^-2 = 1 - 2u + 3u^2 - 4u^3 + 5u^4 - ... collected by degree in z:
//   1 - 2a + (3a^2 - 2b) + (6ab - 4a^3) + (3b^2 - 12a^2 b + 5a^4) + O(|z|^5),
// integrated term by term against the region's moments.
double region_term(const ChainNode& node, const Vec2& d, double s, double h2) {
  const double inv_s = 1.0 / s;
  const double dx = d.x(), dy = d.y(), dx2 = dx * dx, dy2 = dy * dy, dxy = dx * dy;
  const double* m3 = node.m3;
  const double* m4 = node.m4;
  // Integrals of (d.z), (d.z)^2, |z|^2, (d.z)|z|^2, (d.z)^3, |z|^4, (d.z)^2|z|^2, (d.z)^4.
  const double d_z = dx * node.m1x + dy * node.m1y;
  const double d_z2 = dx2 * node.m2xx + 2.0 * dxy * node.m2xy + dy2 * node.m2yy;
  const double z2 = node.m2xx + node.m2yy;
  const double d_z_z2 = dx * (m3[0] + m3[2]) + dy * (m3[1] + m3[3]);
  const double d_z3 =
      dx * dx2 * m3[0] + 3.0 * dx2 * dy * m3[1] + 3.0 * dx * dy2 * m3[2] + dy * dy2 * m3[3];
  const double z4 = m4[0] + 2.0 * m4[2] + m4[4];
  const double d_z2_z2 =
      dx2 * (m4[0] + m4[2]) + 2.0 * dxy * (m4[1] + m4[3]) + dy2 * (m4[2] + m4[4]);
  const double d_z4 = dx2 * dx2 * m4[0] + 4.0 * dx2 * dxy * m4[1] + 6.0 * dx2 * dy2 * m4[2] +
                      4.0 * dxy * dy2 * m4[3] + dy2 * dy2 * m4[4];
  // The terms of the series over powers of 1 / s (a carries 2 / s, b 1 / s).
  const double series =
      node.area + inv_s * (-4.0 * d_z - 2.0 * z2 +
                           inv_s * (12.0 * d_z2 + 12.0 * d_z_z2 + 3.0 * z4 +
                                    inv_s * (-32.0 * d_z3 - 48.0 * d_z2_z2 + inv_s * 80.0 * d_z4)));
  return 2.0 * h2 * inv_s * inv_s * series;
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

std::uint32_t build_chain_tree(const Vec2* points, std::size_t count,
                               std::vector<ChainNode>& nodes) {
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
      [&](const Vec2& a, const Vec2& b) {
        return edge_projected_angle_split(a, b, h2, planar, remainder);
      });
  return split ? split_result(planar, remainder, plain) : plain;
}

double projected_angle_tree_plain(const Vec2* points, std::size_t count, const ChainNode* nodes,
                                  std::uint32_t root, const Vec2& foot, double height) {
  if (count < 2 || !(height > 0.0)) return 0.0;
  const double h2 = height * height;
  // The edges to sum exactly (those of opened leaves and the chords of nodes used whole) are
  // gathered and summed in SIMD lanes (edge_projected_angle_sum): summed one by one, they were
  // most of the time of a field evaluation on contour-heavy sets.
  constexpr std::size_t kBatch = 64;
  alignas(32) double ax[kBatch], ay[kBatch], bx[kBatch], by[kBatch];
  std::size_t pending = 0;
  double regions = 0.0, edges = 0.0;
  const auto push = [&](const Vec2& a, const Vec2& b) {
    ax[pending] = a.x();
    ay[pending] = a.y();
    bx[pending] = b.x();
    by[pending] = b.y();
    if (++pending == kBatch) {
      edges += edge_projected_angle_sum(ax, ay, bx, by, pending, h2);
      pending = 0;
    }
    return true;
  };
  visit(
      points, count, nodes, root, foot, h2,
      [&](const ChainNode& node, const Vec2& d, double s) {
        regions += region_term(node, d, s, h2);
        return push(points[node.first % count] - foot, points[node.last % count] - foot);
      },
      push);
  if (pending > 0) edges += edge_projected_angle_sum(ax, ay, bx, by, pending, h2);
  return edges + regions;
}

}  // namespace sonoshape::recon
