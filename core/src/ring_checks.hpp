#pragma once
// The checks of one ring (polygon) by the rules of docs/formats/slices.md, with exact predicates
// (defined in polygon_checks.cpp). No CGAL types here: the readers include it.
#include <cstddef>
#include <string>

#include "sonoshape/core/slice.hpp"

namespace sonoshape::detail {

/// Two points of a ring closer than this fraction of the ring's size count as the same point.
constexpr double kRepeatedPointRelTol = 1e-9;

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
