// End-to-end checks of the engine on analytic shapes.
#include "sonoshape/recon/reconstruct.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "sonoshape/core/errors.hpp"
#include "test_shapes.hpp"

namespace sonoshape::recon::reconstruct_test {
namespace {

using test::circle;

// A slice of a sphere of radius r centred at the origin through the plane (origin, u, v).
LabeledSlice sphere_slice(const Vec3& origin, const Vec3& u, const Vec3& v, double r, int label) {
  LabeledSlice s;
  s.origin_mm = origin;
  s.u = u.normalized();
  s.v = v.normalized();
  const Vec3 n = s.u.cross(s.v);
  const double d = n.dot(origin);
  if (std::abs(d) < r) {
    const Vec3 c3 = n * d;  // centre of the circle in world
    const Vec2 c = s.to_plane(c3);
    s.regions.push_back({label, circle(c, std::sqrt(r * r - d * d), 96), {}});
  }
  return s;
}

SliceSet sphere_set(double r) {
  SliceSet set;
  set.bounds = Box3{Vec3::Constant(-1.5 * r), Vec3::Constant(1.5 * r)};
  const double offsets[] = {-0.55, -0.1, 0.35, 0.7};
  for (double o : offsets)
    set.slices.push_back(sphere_slice(Vec3(0, 0, o * r), Vec3::UnitX(), Vec3::UnitY(), r, 1));
  for (double o : {-0.4, 0.25})
    set.slices.push_back(sphere_slice(Vec3(o * r, 0, 0), Vec3::UnitY(), Vec3::UnitZ(), r, 1));
  for (double o : {-0.3, 0.45})
    set.slices.push_back(sphere_slice(Vec3(0, o * r, 0), Vec3::UnitZ(), Vec3::UnitX(), r, 1));
  set.slices.push_back(sphere_slice(Vec3(0.1, 0.05, 0), Vec3(1, 1, 0.3),
                                    Vec3(-1, 1, 0)
                                            .normalized()
                                            .cross(Vec3(1, 1, 0.3).normalized())
                                            .cross(Vec3(1, 1, 0.3).normalized()) *
                                        -1,
                                    r, 1));
  return set;
}

TEST(Reconstruct, SphereFromOrthogonalSlicesIsClosedAndClose) {
  const double r = 40.0;
  const SliceSet set = sphere_set(r);
  ReconstructionStats stats;
  const MeshSet meshes = reconstruct(set, {}, &stats);
  ASSERT_EQ(meshes.meshes.size(), 1u);
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  ASSERT_FALSE(mesh.empty());
  const MeshHealth health = check_mesh_health(mesh);
  EXPECT_TRUE(health.closed_manifold_oriented())
      << health.boundary_edges << " " << health.non_manifold_edges << " "
      << health.misoriented_edges << " " << health.non_manifold_vertices;
  const double volume = signed_volume(mesh);
  const double sphere_volume = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  EXPECT_GT(volume, 0.0);
  // 9 slices give 0.988 of the sphere's volume (1.2 % short, at ed734b2 and 11ecf1b); 3 % allows
  // for the octree's rounding, not for a wrong surface (the test read +-15 % before issue 27).
  EXPECT_NEAR(volume / sphere_volume, 1.0, 0.03);
  // Every contour point lies close to the surface: check the slice circles' points against the
  // mesh vertices' distance from the centre (a sphere reconstructed well stays near radius r).
  double max_radius_error = 0.0;
  for (const Vec3& p : mesh.vertices)
    max_radius_error = std::max(max_radius_error, std::abs(p.norm() - r));
  EXPECT_LT(max_radius_error, 0.1 * r);  // 2.6 mm = 0.065 r measured (was: 0.2 r)
  EXPECT_GT(stats.cells, 9u);
  EXPECT_GT(stats.field_evaluations, 1000u);
}

TEST(Reconstruct, UnknownPatchInsideTheSphereCompletesToInside) {
  const double r = 40.0;
  SliceSet set = sphere_set(r);
  // Replace the disc of slice 1 (z = -0.1 r) by a disc with an unknown hole in its middle.
  Region& disc = set.slices[1].regions[0];
  const Ring2 patch = circle(Vec2(0, 0), 0.4 * r, 24);
  disc.holes.push_back(patch);
  set.slices[1].regions.push_back({kUnknownLabel, patch, {}});
  ReconstructionStats stats;
  const MeshSet meshes = reconstruct(set, {}, &stats);
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  const double volume = signed_volume(mesh);
  EXPECT_NEAR(volume / (4.0 / 3.0 * std::numbers::pi * r * r * r), 1.0, 0.15);
  // One closed surface: no cavity at the patch (a cavity would add a second, inner shell whose
  // vertices lie near the centre).
  for (const Vec3& p : mesh.vertices) EXPECT_GT(p.norm(), 0.6 * r);
  EXPECT_GT(stats.unknown_triangles, 0u);
}

}  // namespace
}  // namespace sonoshape::recon::reconstruct_test
