#pragma once
// A closed test mesh built in code, for the tests of every module: an axis-aligned cube.
#include <cstdint>

#include "sonoshape/core/mesh.hpp"

namespace sonoshape::testing {

/// Outward axis-aligned box from `lo` to `hi`, 12 triangles.
inline TriangleMesh cube(const Vec3& lo = Vec3::Constant(-1.0),
                         const Vec3& hi = Vec3::Constant(1.0)) {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i)
    mesh.vertices.emplace_back((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                               (i & 4) ? hi.z() : lo.z());
  // Faces as quads, counter-clockwise seen from outside.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    mesh.triangles.push_back({std::uint32_t(q[0]), std::uint32_t(q[1]), std::uint32_t(q[2])});
    mesh.triangles.push_back({std::uint32_t(q[0]), std::uint32_t(q[2]), std::uint32_t(q[3])});
  }
  return mesh;
}

}  // namespace sonoshape::testing
