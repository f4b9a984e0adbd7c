#pragma once
// A slice region cut by a polygon, exactly: the simulator's fields of view and unknown blobs.
#include <vector>

#include "sonoshape/core/slice.hpp"

namespace sonoshape {

/// The parts of `region` inside `shape` (keep_inside) or outside it, computed by CGAL's Boolean
/// operations on exact coordinates and rounded to doubles once at the end; each part keeps the
/// region's label. `shape` is a simple polygon of either orientation; `region` has valid rings
/// (outer and holes of any orientation). Empty when nothing is left.
std::vector<Region> clip_region(const Region& region, const Ring2& shape, bool keep_inside);

}  // namespace sonoshape
