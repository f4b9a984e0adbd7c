#pragma once
// Cutting closed labelled meshes with planes: exact plane-triangle intersection, loops nested
// into polygons with holes. The ground truth of every test and the core of `sonoshape slice`.
#include <string>
#include <vector>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape {

/// A closed mesh with its material label.
struct LabeledMesh {
  int label = 1;
  std::string name;
  TriangleMesh mesh;
};

/// A cutting plane: through `origin_mm`, spanned by orthonormal `u`, `v`.
struct SlicePlane {
  Vec3 origin_mm = Vec3::Zero();
  Vec3 u = Vec3::UnitX();
  Vec3 v = Vec3::UnitY();
};

/// Cuts every mesh with the plane and returns the slice: one region per outer loop, holes
/// nested by containment (a mesh inside another mesh's region becomes a hole of it and a region
/// of its own label). Loops of (near) zero area are dropped.
LabeledSlice slice_meshes(const std::vector<LabeledMesh>& meshes, const SlicePlane& plane);

}  // namespace sonoshape
