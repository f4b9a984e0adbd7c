#pragma once
// The repair of a self-intersecting contour (ring_repair.cpp, Clipper): the simple polygons it
// encloses by the non-zero rule, and the record of that repair.
#include <cstddef>
#include <string>
#include <vector>

#include "sonoshape/core/repairs.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::detail {

/// One ring of a repaired contour. Depth 0 is an outer boundary of what the contour encloses,
/// depth 1 a hole in the ring `parent`, depth 2 an island in that hole, and so on.
struct NestedRing {
  Ring2 ring;
  std::size_t depth = 0;
  std::size_t parent = 0;  ///< index in ContourRepair::rings of the enclosing ring (depth > 0)
};

/// The simple polygons a self-intersecting contour encloses.
struct ContourRepair {
  std::vector<NestedRing> rings;  ///< parents before their children; empty: encloses no area
  /// Area (the ring's units squared) where the non-zero and even-odd rules disagree: covered
  /// twice or more by the contour, so the choice of rule decided it.
  double area_changed = 0.0;
  /// How many rings are outer boundaries (even depth).
  std::size_t polygons() const;
};

/// The region that `ring` (at least 3 points) encloses by the non-zero winding rule, as simple,
/// strictly non-touching rings (Clipper's union). Corners of `ring` keep their exact coordinates;
/// new corners (where the ring crosses itself) are computed to 1e-12 of the ring's size. Meant
/// for rings check_ring reports as self-intersecting.
ContourRepair repair_contour(const Ring2& ring);

/// The record of a repair_contour: kind "self_intersection", `where` the ring as messages name
/// it, `crossing` the point where it crossed itself as text, `hole` whether the ring is a hole.
Repair self_intersection_repair(const std::string& where, const std::string& crossing,
                                const ContourRepair& result, bool hole);

}  // namespace sonoshape::detail
