#pragma once
// Closed test meshes built in code: a UV sphere (vertices exactly on the sphere) and a cube.
#include <cmath>
#include <numbers>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/simulator/phantom.hpp"

namespace sonoshape::sim::test {

/// Outward UV sphere (sim::make_sphere) moved to `centre`: `segments` around z, `rings` from
/// pole to pole (even `rings` puts a vertex ring on the equator z = centre.z).
inline TriangleMesh uv_sphere(double radius, const Vec3& centre = Vec3::Zero(), int segments = 256,
                              int rings = 128) {
  TriangleMesh mesh = make_sphere(radius, segments, rings);
  for (Vec3& p : mesh.vertices) p += centre;
  return mesh;
}

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

}  // namespace sonoshape::sim::test
