#include "sonoshape/core/mesh_slicer.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_2_algorithms.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace sonoshape {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point2 = Kernel::Point_2;

// One closed cut curve of one mesh, in the plane's (u, v) coordinates.
struct Loop {
  int mesh = 0;
  int label = 1;
  Ring2 ring;
  double area = 0.0;  // signed, as walked
  Eigen::AlignedBox2d box;
  std::vector<Point2> points;  // the ring as CGAL points, for exact containment tests
};

std::uint64_t undirected_edge_key(std::uint32_t a, std::uint32_t b) {
  return (static_cast<std::uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
}

// Removes consecutive (near) duplicates and the spikes a-b-a they leave behind, so the ring is a
// valid simple polygon for the slice-set reader when the plane runs through mesh vertices.
Ring2 clean_ring(const Ring2& ring, double tolerance) {
  Ring2 out;
  out.reserve(ring.size());
  auto same = [&](const Vec2& a, const Vec2& b) { return (a - b).norm() <= tolerance; };
  for (const Vec2& p : ring) {
    if (!out.empty() && same(out.back(), p)) continue;
    if (out.size() >= 2 && same(out[out.size() - 2], p)) {  // spike: back out of it
      out.pop_back();
      continue;
    }
    out.push_back(p);
  }
  // The same rules across the closing seam.
  bool changed = true;
  while (changed && out.size() >= 3) {
    changed = false;
    if (same(out.front(), out.back())) {
      out.pop_back();
      changed = true;
    } else if (same(out[out.size() - 2], out.front())) {
      out.pop_back();
      out.pop_back();
      changed = true;
    } else if (same(out.back(), out[1])) {
      out.erase(out.begin());
      out.pop_back();
      changed = true;
    }
  }
  return out;
}

// Chains the segments (index pairs into `points`) through their shared points into closed
// rings; an open chain (an open mesh) is not a boundary and is dropped.
std::vector<Ring2> chain_segments(const std::vector<Vec2>& points,
                                  const std::vector<std::array<int, 2>>& segments) {
  // Incidence lists; a closed manifold gives every point exactly two segments.
  std::vector<std::vector<int>> incident(points.size());
  for (std::size_t s = 0; s < segments.size(); ++s)
    for (int end : segments[s]) incident[end].push_back(static_cast<int>(s));
  std::vector<Ring2> rings;
  std::vector<char> used(segments.size(), 0);
  for (std::size_t first = 0; first < segments.size(); ++first) {
    if (used[first]) continue;
    used[first] = 1;
    const int start = segments[first][0];
    int current = segments[first][1];
    Ring2 ring{points[start]};
    bool closed = false;
    while (true) {
      if (current == start) {
        closed = true;
        break;
      }
      ring.push_back(points[current]);
      int next_segment = -1;
      for (int s : incident[current])
        if (!used[s]) {
          next_segment = s;
          break;
        }
      if (next_segment < 0) break;  // an open mesh leaves an open chain: not a boundary
      used[next_segment] = 1;
      const auto& seg = segments[next_segment];
      current = seg[0] == current ? seg[1] : seg[0];
    }
    if (closed) rings.push_back(std::move(ring));
  }
  return rings;
}

// Cuts one mesh: every crossing edge gives one point (zero distance counts as positive, a
// symbolic perturbation that keeps each vertex on one side), every crossing triangle one
// segment, and segments chain through shared edges into closed loops.
std::vector<Ring2> cut_mesh(const TriangleMesh& mesh, const SlicePlane& plane) {
  const Vec3 normal = plane.u.cross(plane.v).normalized();
  const std::size_t vertex_count = mesh.vertices.size();
  std::vector<double> distance(vertex_count);
  std::vector<char> positive(vertex_count);
  for (std::size_t i = 0; i < vertex_count; ++i) {
    distance[i] = (mesh.vertices[i] - plane.origin_mm).dot(normal);
    positive[i] = distance[i] >= 0.0;
  }

  std::unordered_map<std::uint64_t, int> point_of_edge;
  std::vector<Vec2> points;
  auto edge_point = [&](std::uint32_t a, std::uint32_t b) {
    const auto [it, inserted] = point_of_edge.try_emplace(undirected_edge_key(a, b), 0);
    if (!inserted) return it->second;
    // Interpolate from the lower index so the point does not depend on the triangle.
    const std::uint32_t i = std::min(a, b);
    const std::uint32_t j = std::max(a, b);
    Vec3 p;
    if (distance[i] == 0.0)
      p = mesh.vertices[i];
    else if (distance[j] == 0.0)
      p = mesh.vertices[j];
    else {
      const double t = distance[i] / (distance[i] - distance[j]);
      p = mesh.vertices[i] + t * (mesh.vertices[j] - mesh.vertices[i]);
    }
    const Vec3 d = p - plane.origin_mm;
    points.emplace_back(d.dot(plane.u), d.dot(plane.v));
    it->second = static_cast<int>(points.size()) - 1;
    return it->second;
  };

  std::vector<std::array<int, 2>> segments;
  for (const auto& t : mesh.triangles) {
    const bool s0 = positive[t[0]], s1 = positive[t[1]], s2 = positive[t[2]];
    if (s0 == s1 && s1 == s2) continue;
    std::array<int, 2> segment{};
    int found = 0;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[k], b = t[(k + 1) % 3];
      if (positive[a] != positive[b]) segment[found++] = edge_point(a, b);
    }
    segments.push_back(segment);
  }

  return chain_segments(points, segments);
}

bool contains(const Loop& outer, const Loop& inner) {
  if (!outer.box.contains(inner.box)) return false;
  // The first vertex of `inner` that is not on `outer` decides (loops of disjoint surfaces do
  // not cross, so any such vertex gives the same answer).
  for (const Point2& p : inner.points) {
    const CGAL::Bounded_side side =
        CGAL::bounded_side_2(outer.points.begin(), outer.points.end(), p, Kernel());
    if (side != CGAL::ON_BOUNDARY) return side == CGAL::ON_BOUNDED_SIDE;
  }
  return false;
}

// Whether two loops trace the same curve: equal areas and every point of one on the other.
bool same_curve(const Loop& a, const Loop& b, double tolerance) {
  if (std::abs(std::abs(a.area) - std::abs(b.area)) > 1e-9 * std::abs(a.area)) return false;
  if (!a.box.isApprox(b.box, 1e-9)) return false;
  for (const Point2& p : b.points)
    if (CGAL::bounded_side_2(a.points.begin(), a.points.end(), p, Kernel()) != CGAL::ON_BOUNDARY) {
      // Interpolated points of two different meshes may sit a rounding error off the curve.
      const Vec2 q(p.x(), p.y());
      bool near = false;
      for (std::size_t k = 0; k < a.ring.size() && !near; ++k) {
        const Vec2& s = a.ring[k];
        const Vec2& e = a.ring[(k + 1) % a.ring.size()];
        const double t =
            std::clamp((q - s).dot(e - s) / std::max((e - s).squaredNorm(), 1e-300), 0.0, 1.0);
        near = (s + t * (e - s) - q).norm() <= tolerance;
      }
      if (!near) return false;
    }
  return true;
}

Ring2 oriented(const Loop& loop, bool counter_clockwise) {
  Ring2 ring = loop.ring;
  if ((loop.area > 0.0) != counter_clockwise) std::reverse(ring.begin(), ring.end());
  return ring;
}

}  // namespace

namespace {

// The cleaned loops of every mesh in the plane, without the degenerate ones (fewer than three
// points or no area, relative to `diagonal`).
std::vector<Loop> mesh_loops(const std::vector<LabeledMesh>& meshes, const SlicePlane& plane,
                             double diagonal) {
  const double duplicate_tolerance = 1e-9 * diagonal;
  const double min_area = 1e-10 * diagonal * diagonal;
  std::vector<Loop> loops;
  for (std::size_t m = 0; m < meshes.size(); ++m) {
    for (const Ring2& raw : cut_mesh(meshes[m].mesh, plane)) {
      Loop loop;
      loop.mesh = static_cast<int>(m);
      loop.label = meshes[m].label;
      loop.ring = clean_ring(raw, duplicate_tolerance);
      if (loop.ring.size() < 3) continue;
      loop.area = signed_area(loop.ring);
      if (std::abs(loop.area) < min_area) continue;
      for (const Vec2& p : loop.ring) {
        loop.box.extend(p);
        loop.points.emplace_back(p.x(), p.y());
      }
      loops.push_back(std::move(loop));
    }
  }
  return loops;
}

// Each loop's parent: the smallest loop (of any mesh) that contains it, or -1.
std::vector<int> loop_parents(const std::vector<Loop>& loops) {
  const std::size_t n = loops.size();
  std::vector<int> parent(n, -1);
  for (std::size_t i = 0; i < n; ++i) {
    double best_area = std::numeric_limits<double>::infinity();
    for (std::size_t j = 0; j < n; ++j) {
      if (i == j || std::abs(loops[j].area) <= std::abs(loops[i].area)) continue;
      if (std::abs(loops[j].area) < best_area && contains(loops[j], loops[i])) {
        best_area = std::abs(loops[j].area);
        parent[i] = static_cast<int>(j);
      }
    }
  }
  return parent;
}

// The regions of the loops: a loop bounds material of its own mesh from outside when an even
// number of loops of the same mesh surround it (otherwise it bounds a cavity of that mesh), and
// every loop directly inside an outer loop is a hole of its region: a cavity of the same mesh,
// or another mesh nested inside (which also gets its own region), so regions never overlap.
std::vector<Region> loop_regions(const std::vector<Loop>& loops, const std::vector<int>& parent,
                                 double duplicate_tolerance) {
  const std::size_t n = loops.size();
  std::vector<char> is_outer(n);
  for (std::size_t i = 0; i < n; ++i) {
    int same_mesh_depth = 0;
    for (int p = parent[i]; p >= 0; p = parent[p])
      if (loops[p].mesh == loops[i].mesh) ++same_mesh_depth;
    is_outer[i] = same_mesh_depth % 2 == 0;
  }
  std::vector<Region> regions;
  std::vector<int> region_of_loop(n, -1);
  for (std::size_t i = 0; i < n; ++i) {
    if (!is_outer[i]) continue;
    region_of_loop[i] = static_cast<int>(regions.size());
    regions.push_back(Region{loops[i].label, oriented(loops[i], true), {}});
  }
  std::vector<std::vector<int>> hole_loops(n);
  for (std::size_t i = 0; i < n; ++i) {
    const int p = parent[i];
    if (p < 0 || !is_outer[p]) continue;
    // Two labels sharing an interface (an organ filling another's cavity) give the same loop
    // twice; the region needs it once.
    const bool duplicate = std::any_of(hole_loops[p].begin(), hole_loops[p].end(), [&](int h) {
      return same_curve(loops[h], loops[i], duplicate_tolerance);
    });
    if (duplicate) continue;
    hole_loops[p].push_back(static_cast<int>(i));
    regions[region_of_loop[p]].holes.push_back(oriented(loops[i], false));
  }
  return regions;
}

}  // namespace

LabeledSlice slice_meshes(const std::vector<LabeledMesh>& meshes, const SlicePlane& plane) {
  LabeledSlice slice;
  slice.origin_mm = plane.origin_mm;
  slice.u = plane.u;
  slice.v = plane.v;
  Box3 all{Vec3::Constant(std::numeric_limits<double>::infinity()),
           Vec3::Constant(-std::numeric_limits<double>::infinity())};
  for (const LabeledMesh& m : meshes) {
    if (m.mesh.vertices.empty()) continue;
    const Box3 b = m.mesh.bounds();
    all.min = all.min.cwiseMin(b.min);
    all.max = all.max.cwiseMax(b.max);
  }
  if (!(all.max.array() >= all.min.array()).all()) return slice;
  const double diagonal = std::max(all.diagonal(), std::numeric_limits<double>::min());
  const std::vector<Loop> loops = mesh_loops(meshes, plane, diagonal);
  slice.regions = loop_regions(loops, loop_parents(loops), 1e-9 * diagonal);
  return slice;
}

}  // namespace sonoshape
