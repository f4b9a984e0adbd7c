#pragma once
// Whether a polygon with holes satisfies the precondition of CGAL's Boolean set operations.
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Polygon_with_holes_2.h>

namespace sonoshape::detail {

/// True when CGAL's Boolean operations with the segment traits (CGAL::do_intersect and
/// CGAL::intersection called with CGAL::Tag_false()) accept `pwh`: a closed, relatively simple
/// outer ring counter-clockwise, holes clockwise inside it, meeting it and each other at most in
/// corners. Release builds do not check that precondition, and an invalid polygon crashes CGAL's
/// sweep (found by fuzzing), so callers check first.
bool valid_for_boolean_ops(const CGAL::Polygon_with_holes_2<CGAL::Epeck>& pwh);

}  // namespace sonoshape::detail
