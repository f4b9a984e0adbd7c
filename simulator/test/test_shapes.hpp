#pragma once
// Closed test meshes built in code: a UV sphere (vertices exactly on the sphere) and a cube
// (sonoshape/testing/cube.hpp).
#include <cmath>
#include <numbers>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/testing/cube.hpp"

namespace sonoshape::simulator::test {

/// Outward UV sphere (simulator::make_sphere) moved to `centre`: `segments` around z, `rings` from
/// pole to pole (even `rings` puts a vertex ring on the equator z = centre.z).
inline TriangleMesh uv_sphere(double radius, const Vec3& centre = Vec3::Zero(), int segments = 256,
                              int rings = 128) {
  TriangleMesh mesh = make_sphere(radius, segments, rings);
  for (Vec3& p : mesh.vertices) p += centre;
  return mesh;
}

using sonoshape::testing::cube;  // an outward axis-aligned box, 12 triangles

/// The same mesh with every triangle reversed (inward-facing).
inline TriangleMesh flipped(TriangleMesh mesh) {
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  return mesh;
}

/// Two meshes as one (e.g. a shell: outer surface plus a flipped inner one).
inline TriangleMesh merged(const TriangleMesh& a, const TriangleMesh& b) {
  TriangleMesh out = a;
  const auto offset = static_cast<std::uint32_t>(a.vertices.size());
  out.vertices.insert(out.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (auto t : b.triangles) out.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  return out;
}

}  // namespace sonoshape::simulator::test
