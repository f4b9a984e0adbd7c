#include "sonoshape/core/mesh_slicer.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/simulator/plane_generator.hpp"
#include "test_shapes.hpp"

namespace sonoshape::simulator::mesh_slicer_test {
namespace {

SlicePlane plane_through(const Vec3& origin, const Vec3& normal) {
  const Vec3 n = normal.normalized();
  const Vec3 reference = std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  SlicePlane plane;
  plane.origin_mm = origin;
  plane.u = reference.cross(n).normalized();
  plane.v = n.cross(plane.u);
  return plane;
}

double cross2(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

bool segments_cross(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& d) {
  const double d1 = cross2(b - a, c - a), d2 = cross2(b - a, d - a);
  const double d3 = cross2(d - c, a - c), d4 = cross2(d - c, b - c);
  return ((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0)) && d1 != 0 && d2 != 0 && d3 != 0 &&
         d4 != 0;
}

// A ring the slice-set reader accepts: >= 3 points, no repeated point, no crossing edges.
void expect_simple(const Ring2& ring) {
  ASSERT_GE(ring.size(), 3u);
  const std::size_t n = ring.size();
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_GT((ring[i] - ring[(i + 1) % n]).norm(), 0.0) << "repeated point " << i;
    for (std::size_t j = i + 2; j < n; ++j) {
      if (i == 0 && j == n - 1) continue;
      ASSERT_FALSE(segments_cross(ring[i], ring[(i + 1) % n], ring[j], ring[(j + 1) % n]))
          << "edges " << i << " and " << j << " cross";
    }
  }
}

TEST(MeshSlicer, SphereCutsAreCirclesOfTheAnalyticRadius) {
  const double radius = 50.0;
  const Vec3 centre(3.0, -2.0, 1.0);
  const TriangleMesh sphere = test::uv_sphere(radius, centre);
  ASSERT_GT(signed_volume(sphere), 0.0);
  const std::vector<LabeledMesh> meshes{{1, "ball", sphere}};
  for (const Vec3& normal : {Vec3(0, 0, 1), Vec3(0.3, -0.2, 1.0), Vec3(1, 0.1, 0.05)}) {
    for (double height : {0.0123, 17.3, 31.0}) {
      const Vec3 n = normal.normalized();
      const SlicePlane plane = plane_through(centre + height * n + Vec3(0.7, 0.4, 0.0).cross(n), n);
      const LabeledSlice slice = slice_meshes(meshes, plane);
      ASSERT_EQ(slice.regions.size(), 1u);
      const Region& region = slice.regions[0];
      EXPECT_EQ(region.label, 1);
      EXPECT_TRUE(region.holes.empty());
      EXPECT_GT(signed_area(region.outer), 0.0);
      const double expected = std::sqrt(radius * radius - height * height);
      const Vec2 c = slice.to_plane(centre);
      for (const Vec2& p : region.outer) {
        EXPECT_NEAR((p - c).norm(), expected, 1e-3 * expected);
        EXPECT_NEAR((slice.to_world(p) - centre).norm(), radius, 1e-3 * radius);
      }
      expect_simple(region.outer);
    }
  }
}

TEST(MeshSlicer, PlaneThroughAVertexRingGivesThatRing) {
  // Even ring count: the equator is a ring of 256 vertices exactly on z = 0.
  const std::vector<LabeledMesh> meshes{{1, "", test::uv_sphere(10.0)}};
  const LabeledSlice slice = slice_meshes(meshes, plane_through(Vec3::Zero(), Vec3::UnitZ()));
  ASSERT_EQ(slice.regions.size(), 1u);
  EXPECT_EQ(slice.regions[0].outer.size(), 256u);
  for (const Vec2& p : slice.regions[0].outer) EXPECT_NEAR(p.norm(), 10.0, 1e-12);
  expect_simple(slice.regions[0].outer);
}

TEST(MeshSlicer, CubeCutsAreSquaresAndRectangles) {
  const std::vector<LabeledMesh> meshes{{2, "box", test::cube()}};
  const LabeledSlice middle = slice_meshes(meshes, plane_through(Vec3(0, 0, 0.3), Vec3::UnitZ()));
  ASSERT_EQ(middle.regions.size(), 1u);
  EXPECT_EQ(middle.regions[0].label, 2);
  EXPECT_NEAR(signed_area(middle.regions[0].outer), 4.0, 1e-12);
  expect_simple(middle.regions[0].outer);

  // Exactly through the top face: its vertices count as above, so the face itself is the cut.
  const LabeledSlice top = slice_meshes(meshes, plane_through(Vec3(0, 0, 1), Vec3::UnitZ()));
  ASSERT_EQ(top.regions.size(), 1u);
  EXPECT_NEAR(signed_area(top.regions[0].outer), 4.0, 1e-12);
  expect_simple(top.regions[0].outer);
  // Exactly through the bottom face: every vertex is on or above the plane, nothing is cut.
  EXPECT_TRUE(slice_meshes(meshes, plane_through(Vec3(0, 0, -1), Vec3::UnitZ())).regions.empty());

  // A diagonal plane through four vertices: a 2 x 2*sqrt(2) rectangle.
  const LabeledSlice diagonal = slice_meshes(meshes, plane_through(Vec3::Zero(), Vec3(1, 1, 0)));
  ASSERT_EQ(diagonal.regions.size(), 1u);
  EXPECT_NEAR(signed_area(diagonal.regions[0].outer), 4.0 * std::numbers::sqrt2, 1e-12);
  expect_simple(diagonal.regions[0].outer);

  // A plane missing the object gives an empty slice.
  EXPECT_TRUE(slice_meshes(meshes, plane_through(Vec3(0, 0, 5), Vec3::UnitZ())).regions.empty());
}

TEST(MeshSlicer, NestedMeshesGiveAnAnnulusAndAnInnerDisc) {
  const std::vector<LabeledMesh> meshes{{1, "liver", test::uv_sphere(20.0)},
                                        {2, "tumour", test::uv_sphere(8.0, Vec3(1, 1, 0))}};
  const LabeledSlice slice = slice_meshes(meshes, plane_through(Vec3(0, 0, 2.5), Vec3::UnitZ()));
  ASSERT_EQ(slice.regions.size(), 2u);
  const Region& outer = slice.regions[0].label == 1 ? slice.regions[0] : slice.regions[1];
  const Region& inner = slice.regions[0].label == 1 ? slice.regions[1] : slice.regions[0];
  EXPECT_EQ(outer.label, 1);
  EXPECT_EQ(inner.label, 2);
  ASSERT_EQ(outer.holes.size(), 1u);
  EXPECT_TRUE(inner.holes.empty());
  EXPECT_GT(signed_area(outer.outer), 0.0);
  EXPECT_LT(signed_area(outer.holes[0]), 0.0);
  EXPECT_GT(signed_area(inner.outer), 0.0);
  // The hole is exactly the inner disc's boundary.
  EXPECT_NEAR(-signed_area(outer.holes[0]), signed_area(inner.outer), 1e-9);
  const double r_outer2 = 400.0 - 6.25, r_inner2 = 64.0 - 6.25;
  EXPECT_NEAR(signed_area(outer.outer), std::numbers::pi * r_outer2,
              2e-3 * std::numbers::pi * r_outer2);
  EXPECT_NEAR(signed_area(inner.outer), std::numbers::pi * r_inner2,
              2e-3 * std::numbers::pi * r_inner2);
}

TEST(MeshSlicer, ShellOfOneMeshGivesARegionWithAHole) {
  const TriangleMesh shell =
      test::merged(test::uv_sphere(20.0, Vec3::Zero(), 64, 32),
                   test::flipped(test::uv_sphere(10.0, Vec3::Zero(), 64, 32)));
  // A third mesh inside the cavity keeps its own region and is no hole of the shell.
  const std::vector<LabeledMesh> meshes{
      {1, "shell", shell}, {3, "core", test::cube(Vec3::Constant(-2), Vec3::Constant(2))}};
  const LabeledSlice slice = slice_meshes(meshes, plane_through(Vec3(0, 0, 0.5), Vec3::UnitZ()));
  ASSERT_EQ(slice.regions.size(), 2u);
  for (const Region& r : slice.regions) {
    if (r.label == 1) {
      ASSERT_EQ(r.holes.size(), 1u);
      EXPECT_LT(signed_area(r.holes[0]), 0.0);
    } else {
      EXPECT_EQ(r.label, 3);
      EXPECT_TRUE(r.holes.empty());
      EXPECT_NEAR(signed_area(r.outer), 16.0, 1e-9);
    }
  }
}

TEST(MeshSlicer, SharedInterfaceIsOneHoleNotTwo) {
  // A shell whose cavity is exactly filled by another label: the cavity loop and the filler's
  // loop coincide, and the shell's region must list that boundary once.
  const TriangleMesh filler = test::cube(Vec3::Constant(-4), Vec3::Constant(4));
  const std::vector<LabeledMesh> meshes{
      {1, "wall",
       test::merged(test::cube(Vec3::Constant(-10), Vec3::Constant(10)), test::flipped(filler))},
      {2, "fill", filler}};
  const LabeledSlice slice = slice_meshes(meshes, plane_through(Vec3(0, 0, 1.5), Vec3::UnitZ()));
  ASSERT_EQ(slice.regions.size(), 2u);
  const Region& wall = slice.regions[0].label == 1 ? slice.regions[0] : slice.regions[1];
  ASSERT_EQ(wall.holes.size(), 1u);
  EXPECT_NEAR(signed_area(wall.holes[0]), -64.0, 1e-9);
}

TEST(MeshSlicer, EveryFamilyGivesSlicesTheReaderAccepts) {
  // Nested labels, a cavity and an axis-aligned cube (planes through its vertices and faces).
  const std::vector<LabeledMesh> meshes{
      {1, "shell",
       test::merged(test::uv_sphere(30.0, Vec3::Zero(), 96, 48),
                    test::flipped(test::uv_sphere(12.0, Vec3(2, 0, 0), 64, 32)))},
      {2, "core", test::uv_sphere(6.0, Vec3(3, 1, 0), 64, 32)},
      {3, "box", test::cube(Vec3(-20, -20, -8), Vec3(-14, -14, 8))}};
  Box3 box = meshes[0].mesh.bounds();
  for (const char* name : {"parallel", "orthogonal", "random", "sweep"}) {
    SliceSet set;
    set.labels = {{1, "shell"}, {2, "core"}, {3, "box"}};
    set.bounds = box.padded(0.1 * box.diagonal());
    for (const SlicePlane& plane : generate_planes(parse_plane_family(name), 24, box, 5))
      set.slices.push_back(slice_meshes(meshes, plane));
    const Status valid = validate_slice_set(set, name);
    EXPECT_TRUE(valid) << valid.message();
  }
  SliceSet exact;
  exact.bounds = box;
  for (double z : {-8.0, 8.0, 0.0})
    exact.slices.push_back(slice_meshes(meshes, plane_through(Vec3(0, 0, z), Vec3::UnitZ())));
  const Status valid = validate_slice_set(exact, "planes through vertices");
  EXPECT_TRUE(valid) << valid.message();
}

TEST(PlaneGenerator, FamiliesAreDeterministicOrthonormalAndCutTheBox) {
  const Box3 box{Vec3(-40, -30, -20), Vec3(60, 30, 25)};
  for (const char* name : {"parallel", "orthogonal", "random", "sweep"}) {
    const PlaneFamily family = parse_plane_family(name);
    const auto planes = generate_planes(family, 25, box, 42);
    ASSERT_EQ(planes.size(), 25u) << name;
    const auto again = generate_planes(family, 25, box, 42);
    for (std::size_t i = 0; i < planes.size(); ++i) {
      const SlicePlane& p = planes[i];
      EXPECT_EQ(p.origin_mm, again[i].origin_mm);
      EXPECT_NEAR(p.u.norm(), 1.0, 1e-12);
      EXPECT_NEAR(p.v.norm(), 1.0, 1e-12);
      EXPECT_NEAR(p.u.dot(p.v), 0.0, 1e-12);
      EXPECT_TRUE(box.contains(p.origin_mm)) << name << " plane " << i;
      // Never through the exact centre of the box.
      const Vec3 centre = 0.5 * (box.min + box.max);
      EXPECT_GT(std::abs((centre - p.origin_mm).dot(p.u.cross(p.v))), 1e-9) << name;
    }
  }
  const auto parallel = generate_planes(PlaneFamily::kParallel, 10, box, 1);
  for (const SlicePlane& p : parallel)
    EXPECT_NEAR(p.u.cross(p.v).dot(parallel[0].u.cross(parallel[0].v)), 1.0, 1e-12);
  const auto sweep = generate_planes(PlaneFamily::kSweep, 40, box, 7);
  for (const SlicePlane& p : sweep)  // longest axis is x; tilt stays near 20 degrees or less
    EXPECT_GT(std::abs(p.u.cross(p.v).x()), std::cos(25.0 * std::numbers::pi / 180.0));
  EXPECT_NE(generate_planes(PlaneFamily::kRandom, 3, box, 1)[0].origin_mm,
            generate_planes(PlaneFamily::kRandom, 3, box, 2)[0].origin_mm);
  EXPECT_THROW(parse_plane_family("spiral"), std::invalid_argument);
}

}  // namespace
}  // namespace sonoshape::simulator::mesh_slicer_test
