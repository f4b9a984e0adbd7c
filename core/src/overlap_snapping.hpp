#pragma once
// The repair of rounding overlaps (docs/formats/slices.md, "Rounding overlaps"): two regions of
// a slice cut apart by a polygon library and rounded overlap by a sliver along their shared edge;
// the readers snap them back onto one boundary.
#include "repair_log.hpp"
#include "slice_rules.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::detail {

/// Snaps the given pairs of regions (valid regions whose overlap validate_slice_set_named found
/// thin): vertices of the later region within kRoundingOverlapRelTol of the slice's extent of the
/// earlier one's vertices move onto them, and each region's vertices that near the other's edges
/// are inserted into those edges, so the two share the edge exactly. A pair is changed only when
/// the result no longer overlaps under the exact test. Records a "rounding_overlap" repair per
/// snapped pair (InputError under strict).
void snap_rounding_overlaps(SliceSet& set, const RegionPairs& pairs, const SliceNaming& naming,
                            RepairLog& repairs);

}  // namespace sonoshape::detail
