#pragma once
// The checks of one ring (polygon) by the rules of docs/formats/slices.md, with exact predicates
// (defined in polygon_checks.cpp). No CGAL types here: the readers include it.
#include <cstddef>
#include <string>

#include "sonoshape/core/slice.hpp"

namespace sonoshape::detail {

/// Two points of a ring closer than this fraction of the ring's size count as the same point.
constexpr double kRepeatedPointRelTol = 1e-9;

/// Closed 2D box of one ring, for cheap rejection before the exact tests.
struct Box2 {
  Vec2 lo;
  Vec2 hi;
  /// `other` lies in this box (closed).
  bool contains(const Box2& other) const {
    return (lo.array() <= other.lo.array()).all() && (hi.array() >= other.hi.array()).all();
  }
  /// Interiors overlap: boxes that merely touch cannot hold overlapping polygons.
  bool interiors_overlap(const Box2& other) const {
    return lo.x() < other.hi.x() && other.lo.x() < hi.x() && lo.y() < other.hi.y() &&
           other.lo.y() < hi.y();
  }
  /// Closed boxes meet: boxes that touch can hold polygons that touch.
  bool meets(const Box2& other) const {
    return lo.x() <= other.hi.x() && other.lo.x() <= hi.x() && lo.y() <= other.hi.y() &&
           other.lo.y() <= hi.y();
  }
};

/// The box of a ring (at least one point).
Box2 box_of(const Ring2& ring);

/// Bounding-box diagonal of a ring (0 for fewer than 2 points).
double ring_size(const Ring2& ring);

/// Drops consecutive repeated points (closer than kRepeatedPointRelTol * ring size), including a
/// last point that repeats the first. Returns how many points were dropped.
std::size_t drop_repeated_points(Ring2& ring);

/// Empty when `ring` (free of repeated consecutive points) is a usable polygon: finite, at least 3
/// distinct points, simple (exact predicates), non-zero area. Otherwise what is wrong and the fix.
std::string ring_problem(const Ring2& ring);

/// What check_ring found: the readers repair a ring whose only fault is that it crosses itself.
struct RingCheck {
  std::string problem;           ///< empty when the ring is usable; else ring_problem's text
  bool self_intersects = false;  ///< the fault is that the ring crosses or touches itself
  Vec2 crossing = Vec2::Zero();  ///< then a point where it does
};

/// ring_problem, telling a self-intersection apart from the other faults.
RingCheck check_ring(const Ring2& ring);

/// True when `inner` lies inside the closed region bounded by `outer` (exact predicates). Meant
/// for rings that do not cross each other: it decides by the first vertex of `inner` that is not
/// on the boundary of `outer`; when every vertex is on it, by their exact difference.
bool ring_inside_ring(const Ring2& inner, const Ring2& outer);

}  // namespace sonoshape::detail
