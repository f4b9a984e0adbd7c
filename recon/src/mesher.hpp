#pragma once
// Zero-set meshes of the label regions by marching tetrahedra on the finest cells of the band.
//
// Written here rather than taken from a library because it must run on the sparse band the octree
// produced (not a full grid) and guarantee closed, manifold, oriented output for every label:
// each cube is split into the six Kuhn tetrahedra around its main diagonal, a triangulation that
// is conforming across cubes, and the surface of a binary labelling of the vertices of a
// conforming triangulation is a closed 2-manifold. Labels that touch share their interface.
#include <vector>

#include "octree_field.hpp"
#include "sonoshape/core/mesh.hpp"

namespace sonoshape::recon {

/// One mesh per material 1..function_count-1 (index m-1), outward oriented. A label region is
/// where the label is the argmax of the functions; vertices sit where f_m - max_{k != m} f_k
/// changes sign along the tetrahedron edges, linearly interpolated.
std::vector<TriangleMesh> extract_label_surfaces(const SampledField& field);

}  // namespace sonoshape::recon
