#pragma once
// Connected parts of a triangle mesh: what tests and benchmarks count to tell one tube from
// beads, one sheet from fragments.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "sonoshape/core/mesh.hpp"

namespace sonoshape {

/// The connected parts of `mesh` (triangles joined through shared vertices): `part_of_triangle`
/// numbers each triangle's part 0..count-1, in the order of each part's first triangle.
struct MeshParts {
  std::size_t count = 0;
  std::vector<std::uint32_t> part_of_triangle;
};
MeshParts mesh_parts(const TriangleMesh& mesh);

}  // namespace sonoshape
