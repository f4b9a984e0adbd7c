#pragma once
// Exact-predicate geometry of slice regions shared by the validation rules (slice_rules.cpp) and
// the snapping of rounding overlaps (overlap_snapping.cpp): CGAL rings, boundary sweeps and the
// measured overlap of two regions. Defined in polygon_checks.cpp. CGAL types: include it only
// where the exact work is done.
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_2.h>
#include <CGAL/Polygon_with_holes_2.h>

#include <optional>
#include <string>
#include <vector>

#include "ring_checks.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::detail {

using IK = CGAL::Exact_predicates_inexact_constructions_kernel;
using EK = CGAL::Exact_predicates_exact_constructions_kernel;
using ExactPolygon = CGAL::Polygon_2<EK>;
using ExactPolygonWithHoles = CGAL::Polygon_with_holes_2<EK>;
using Segments = std::vector<IK::Segment_2>;
using Points = std::vector<IK::Point_2>;

/// A ring's points for the exact predicates.
Points to_points(const Ring2& ring);

/// A ring as an exact polygon turned to `wanted`.
ExactPolygon to_exact(const Ring2& ring, CGAL::Orientation wanted);
/// A region (valid rings) as an exact polygon with holes: outer ring counter-clockwise, holes
/// clockwise.
ExactPolygonWithHoles to_exact(const Ring2& outer, const std::vector<Ring2>& holes);

/// Whether `inner_ccw` lies inside `outer_ccw` (their exact difference is empty).
bool exact_inside(const ExactPolygon& inner_ccw, const ExactPolygon& outer_ccw);

/// The boundary of a region as exact-predicate points and segments, for the cheap overlap tests.
struct RegionRings {
  Points outer;
  std::vector<Points> holes;
  Segments segments;  ///< outer and holes together
};

/// Appends the closed ring's edges to `out`.
void add_segments(const Points& ring, Segments& out);
/// The closed ring's edges.
Segments segments_of(const Points& ring);

/// Whether a segment of `a` meets a segment of `b` (exact predicates; a sweep over x).
bool boundaries_meet(const Segments& a, const Segments& b);

/// Whether `p` lies in the open interior of `ring`.
bool strictly_inside(const IK::Point_2& p, const Points& ring);

/// Interiors of two regions whose boundaries do not meet overlap exactly when a boundary curve of
/// one lies inside the other; each curve lies wholly inside or outside, so one vertex tells.
bool disjoint_boundaries_overlap(const RegionRings& a, const RegionRings& b);

/// The overlap of two regions of one slice.
struct OverlapMeasure {
  double area = 0.0;   ///< all components together, in the file's units squared
  double width = 0.0;  ///< the widest component's 2·area/perimeter: the thickness of a sliver
  Vec2 location = Vec2::Zero();          ///< a point inside the largest component (slice coords)
  Box2 box{Vec2::Zero(), Vec2::Zero()};  ///< box of every component
};

/// The exact intersection of two regions (valid rings); nullopt when their interiors are
/// disjoint (shared edges and touching corners are not overlaps).
std::optional<OverlapMeasure> measure_overlap(const ExactPolygonWithHoles& a,
                                              const ExactPolygonWithHoles& b);

/// Bounding-box diagonal of a slice's regions: the scale of its rounding tolerance.
double slice_extent(const LabeledSlice& slice);

/// "12.3 mm² around (x, y), world (x, y, z)": where an overlap is, for messages.
std::string overlap_text(const LabeledSlice& slice, const OverlapMeasure& overlap,
                         const std::string& units);

}  // namespace sonoshape::detail
