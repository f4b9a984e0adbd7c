// Mesh health and volume: the checks `sonoshape evaluate` reports.
#include "sonoshape/core/mesh.hpp"

#include <gtest/gtest.h>

#include "sonoshape/core/mesh_components.hpp"

namespace sonoshape::mesh_test {
namespace {

// The unit cube [0,1]^3, 12 triangles, counter-clockwise seen from outside.
TriangleMesh unit_cube() {
  TriangleMesh mesh;
  for (int k = 0; k < 8; ++k) mesh.vertices.emplace_back(k & 1, (k >> 1) & 1, (k >> 2) & 1);
  mesh.triangles = {{0, 2, 1}, {1, 2, 3},   // z = 0, normal -z
                    {4, 5, 6}, {5, 7, 6},   // z = 1, normal +z
                    {0, 1, 4}, {1, 5, 4},   // y = 0, normal -y
                    {2, 6, 3}, {3, 6, 7},   // y = 1, normal +y
                    {0, 4, 2}, {2, 4, 6},   // x = 0, normal -x
                    {1, 3, 5}, {3, 7, 5}};  // x = 1, normal +x
  return mesh;
}

TEST(MeshHealth, ClosedCubeIsHealthy) {
  const TriangleMesh cube = unit_cube();
  const MeshHealth health = check_mesh_health(cube);
  EXPECT_TRUE(health.closed_manifold_oriented());
  EXPECT_EQ(health.boundary_edges, 0u);
  EXPECT_NEAR(signed_volume(cube), 1.0, 1e-12);
  const Box3 box = cube.bounds();
  EXPECT_EQ(box.min, Vec3::Zero());
  EXPECT_EQ(box.max, Vec3::Ones());
}

TEST(MeshHealth, VolumeIsTranslationInvariantAndSigned) {
  TriangleMesh cube = unit_cube();
  for (Vec3& p : cube.vertices) p = 2.0 * p + Vec3(10, -5, 3);
  EXPECT_NEAR(signed_volume(cube), 8.0, 1e-9);
  for (auto& t : cube.triangles) std::swap(t[1], t[2]);  // inside out
  EXPECT_NEAR(signed_volume(cube), -8.0, 1e-9);
  EXPECT_EQ(check_mesh_health(cube).misoriented_edges, 0u);  // consistently flipped is oriented
}

TEST(MeshHealth, MissingFaceLeavesABoundary) {
  TriangleMesh cube = unit_cube();
  cube.triangles.erase(cube.triangles.begin() + 2, cube.triangles.begin() + 4);  // drop z = 1
  const MeshHealth health = check_mesh_health(cube);
  EXPECT_EQ(health.boundary_edges, 4u);
  EXPECT_EQ(health.non_manifold_edges, 0u);
  EXPECT_EQ(health.misoriented_edges, 0u);
  EXPECT_FALSE(health.closed_manifold_oriented());
}

TEST(MeshHealth, FlippedFaceIsMisoriented) {
  TriangleMesh cube = unit_cube();
  std::swap(cube.triangles[0][1], cube.triangles[0][2]);
  const MeshHealth health = check_mesh_health(cube);
  EXPECT_EQ(health.misoriented_edges, 3u);
  EXPECT_EQ(health.boundary_edges, 0u);
  EXPECT_FALSE(health.closed_manifold_oriented());
}

TEST(MeshHealth, EdgeSharedByThreeTrianglesIsNonManifold) {
  TriangleMesh cube = unit_cube();
  cube.vertices.emplace_back(0.5, 0.5, -1.0);
  cube.triangles.push_back({0, 1, 8});  // a fin on the edge 0-1
  const MeshHealth health = check_mesh_health(cube);
  EXPECT_EQ(health.non_manifold_edges, 1u);
  EXPECT_FALSE(health.closed_manifold_oriented());
}

TEST(MeshHealth, BowTieVertexIsNonManifold) {
  // Two closed tetrahedra sharing only vertex 0.
  TriangleMesh mesh;
  mesh.vertices = {Vec3(0, 0, 0),  Vec3(1, 0, 0),  Vec3(0, 1, 0), Vec3(0, 0, 1),
                   Vec3(-1, 0, 0), Vec3(0, -1, 0), Vec3(0, 0, -1)};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3},
                    {0, 4, 5}, {0, 6, 4}, {0, 5, 6}, {4, 6, 5}};
  const MeshHealth health = check_mesh_health(mesh);
  EXPECT_EQ(health.boundary_edges, 0u);
  EXPECT_EQ(health.non_manifold_edges, 0u);
  EXPECT_EQ(health.misoriented_edges, 0u);
  EXPECT_EQ(health.non_manifold_vertices, 1u);
  EXPECT_FALSE(health.closed_manifold_oriented());
  EXPECT_NEAR(signed_volume(mesh), 2.0 / 6.0, 1e-12);
}

TEST(MeshHealth, DegenerateTriangleIsCounted) {
  TriangleMesh cube = unit_cube();
  cube.triangles.push_back({3, 3, 5});
  EXPECT_EQ(check_mesh_health(cube).degenerate_triangles, 1u);
  EXPECT_FALSE(check_mesh_health(cube).closed_manifold_oriented());
}

TEST(MeshParts, TrianglesJoinThroughSharedVerticesOnly) {
  TriangleMesh mesh = unit_cube();
  const std::size_t first_cube_triangles = mesh.triangles.size();
  // A second cube, 5 units away: its own part.
  TriangleMesh far = unit_cube();
  const auto offset = static_cast<std::uint32_t>(mesh.vertices.size());
  for (const Vec3& v : far.vertices) mesh.vertices.push_back(v + Vec3(5, 0, 0));
  for (const auto& t : far.triangles)
    mesh.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  // A triangle touching the first cube at one corner only: joined to it (a bow tie is one part).
  const auto apex = static_cast<std::uint32_t>(mesh.vertices.size());
  mesh.vertices.push_back(Vec3(-2, -2, -2));
  mesh.vertices.push_back(Vec3(-2, -1, -2));
  mesh.triangles.push_back({0, apex, apex + 1});

  const MeshParts parts = mesh_parts(mesh);
  EXPECT_EQ(parts.count, 2u);
  ASSERT_EQ(parts.part_of_triangle.size(), mesh.triangles.size());
  EXPECT_EQ(parts.part_of_triangle.front(), 0u);
  EXPECT_EQ(parts.part_of_triangle[first_cube_triangles], 1u);
  EXPECT_EQ(parts.part_of_triangle.back(), 0u);
  EXPECT_EQ(mesh_parts(TriangleMesh{}).count, 0u);
}

}  // namespace
}  // namespace sonoshape::mesh_test
