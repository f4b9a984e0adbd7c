#pragma once
// Unknown regions and fields of view (Bermano et al. 2011, Section 5): each slice's plane inside
// the box is partitioned into known materials, known outside and the unknown set (unknown regions
// and everything outside the field of view). The unknown set is later triangulated per face and
// completed from the known data around it.
#include <optional>
#include <vector>

#include "sonoshape/core/slice.hpp"

namespace sonoshape::recon {

/// One connected component of a slice's unknown set: rings (outer counter-clockwise first, then
/// holes clockwise, in the slice's (u, v) mm) and, for each edge i -> i+1 of each ring, the
/// function index (0 outside, m material) of the known side across it.
struct UnknownComponent {
  std::vector<Ring2> rings;
  std::vector<std::vector<int>> edge_labels;
};

/// The partition of one slice. `materials[m]` holds the known rings of material m (index 0 unused):
/// the slice's regions of that material, inside the field of view, outside unknown regions.
struct SlicePartition {
  std::vector<std::vector<Ring2>> materials;
  std::vector<UnknownComponent> unknown;
  /// The known set (materials and the known outside): plane_in_box minus the unknown set, outer
  /// rings counter-clockwise and holes clockwise.
  std::vector<Ring2> known;
};

/// Partitions `slice` inside `plane_in_box` (the convex polygon where the slice's plane meets the
/// reconstruction box, in (u, v)) with CGAL's exact Boolean operations. `material_index(id)`
/// gives the dense index 1..K of a material id.
SlicePartition partition_slice(const LabeledSlice& slice, const std::vector<int>& material_ids,
                               const Ring2& plane_in_box);

/// A point inside a simple ring (the middle of the widest interval the ring cuts from the
/// horizontal line through the middle of its bounding box), if the ring has an interior.
std::optional<Vec2> interior_point(const Ring2& ring);

/// The polygon where the plane (origin, u, v) meets the box, counter-clockwise in (u, v); empty
/// if the plane misses the box's interior.
Ring2 plane_box_polygon(const Vec3& origin, const Vec3& u, const Vec3& v, const Box3& box);

}  // namespace sonoshape::recon
