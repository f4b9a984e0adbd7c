// The thin-plate field (issue 38): its data, its solve, and the properties the engine promises
// for it (interpolation of the contours, thin structures kept whole, nesting, unknown regions
// and fields of view carrying no data, online updates equal to the one-shot result).
#include "thin_plate.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>

#include "cell_field.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/mesh_components.hpp"
#include "sonoshape/recon/reconstruct.hpp"
#include "sonoshape/recon/reconstructor.hpp"
#include "test_shapes.hpp"

namespace sonoshape::recon::thin_plate_test {
namespace {

using test::circle;

ReconstructionOptions thin_plate_options() {
  ReconstructionOptions options;
  options.field = FieldKind::thin_plate;
  return options;
}

// Connected parts of a mesh (triangles sharing a vertex).
std::size_t component_count(const TriangleMesh& mesh) { return mesh_parts(mesh).count; }

// The largest difference between two fields' values (every function) at 2000 points spread over
// the box (a low-discrepancy sequence): how two solves of the same data are compared.
double worst_difference(const ThinPlateField& a, const ThinPlateField& b, const Box3& box,
                        int functions) {
  std::vector<Vec3> points;
  for (int i = 0; i < 2000; ++i)
    points.push_back(box.min + Vec3(std::fmod(0.618034 * i, 1.0), std::fmod(0.414214 * i, 1.0),
                                    std::fmod(0.732051 * i, 1.0))
                                   .cwiseProduct(box.size()));
  const std::size_t count = points.size() * static_cast<std::size_t>(functions);
  std::vector<double> va(count), vb(count);
  a.evaluate(points, va.data());
  b.evaluate(points, vb.data());
  double worst = 0.0;
  for (std::size_t n = 0; n < count; ++n) worst = std::max(worst, std::abs(va[n] - vb[n]));
  return worst;
}

// An online solve against a one-shot solve of the same data, as the mesh sees them: the largest
// difference of a value at 20000 points spread over the box where the one-shot value lies within
// `band_mm` of zero (`near_zero`, at `near_count` values), and anywhere. The online tolerance
// bounds the first; the second stays below the band, so that the signs agree beyond it.
struct FieldComparison {
  double near_zero = 0.0, anywhere = 0.0;
  std::size_t near_count = 0;
};
FieldComparison compare_near_zero(const ThinPlateField& online, const ThinPlateField& once,
                                  const Box3& box, double band_mm) {
  std::vector<Vec3> points;
  for (int i = 0; i < 20000; ++i)
    points.push_back(box.min + Vec3(std::fmod(0.618034 * i, 1.0), std::fmod(0.414214 * i, 1.0),
                                    std::fmod(0.732051 * i, 1.0))
                                   .cwiseProduct(box.size()));
  const std::size_t count = points.size() * static_cast<std::size_t>(once.function_count());
  std::vector<double> va(count), vb(count);
  online.evaluate(points, va.data());
  once.evaluate(points, vb.data());
  FieldComparison out;
  for (std::size_t n = 0; n < count; ++n) {
    const double difference = std::abs(va[n] - vb[n]);
    out.anywhere = std::max(out.anywhere, difference);
    if (std::abs(vb[n]) > band_mm) continue;
    out.near_zero = std::max(out.near_zero, difference);
    ++out.near_count;
  }
  return out;
}

// What an online field's values may differ by from a one-shot solve's near the zero set (mm):
// the online tolerance (of the grid spacing), and the sampled solution's tolerance times the
// Catmull-Rom weights' absolute sum.
double online_bound(double spacing) {
  const ThinPlateOptions options;
  return (options.online_tolerance + 1.25 * 1.25 * 1.25 * options.resample_tolerance) * spacing;
}

LabeledSlice z_slice(double z) {
  LabeledSlice s;
  s.origin_mm = Vec3(0, 0, z);
  return s;
}

// A slice of a sphere (radius r, centre c) through the plane z = const, as circle rings.
Ring2 sphere_section(const Vec3& c, double r, double z) {
  const double d = z - c.z();
  if (std::abs(d) >= r) return {};
  return circle(Vec2(c.x(), c.y()), std::sqrt(r * r - d * d), 96);
}

SliceSet sphere_stack(double r, const std::vector<double>& heights) {
  SliceSet set;
  set.bounds = Box3{Vec3::Constant(-1.5 * r), Vec3::Constant(1.5 * r)};
  for (const double z : heights) {
    LabeledSlice s = z_slice(z);
    if (Ring2 ring = sphere_section(Vec3::Zero(), r, z); !ring.empty())
      s.regions.push_back({1, ring, {}});
    set.slices.push_back(s);
  }
  // Two vertical slices through the centre, so the field is pinned in every direction.
  for (int axis = 0; axis < 2; ++axis) {
    LabeledSlice s;
    s.origin_mm = Vec3::Zero();
    s.u = axis == 0 ? Vec3::UnitX() : Vec3::UnitY();
    s.v = Vec3::UnitZ();
    s.regions.push_back({1, circle(Vec2(0, 0), r, 96), {}});
    set.slices.push_back(s);
  }
  return set;
}

TEST(ThinPlateData, SignedDistanceInsideLiesBetweenTheBoundsOfTrueAndUnseenEdges) {
  // A square of material 1 on [0, 10]^2 whose right edge borders an unknown region.
  LabeledSlice slice = z_slice(0.0);
  slice.regions.push_back({1, Ring2{{0, 0}, {10, 0}, {10, 10}, {0, 10}}, {}});
  slice.regions.push_back({kUnknownLabel, Ring2{{10, 0}, {20, 0}, {20, 10}, {10, 10}}, {}});
  const Box3 box{Vec3(-60, -60, -10), Vec3(60, 60, 10)};
  const PreparedSlice prepared = prepare_slice(slice, 0, {1}, box);
  const double truncation = 10.0;
  const std::vector<Vec2> points{{8, 5}, {5, 5}, {-3, 5}, {15, 5}, {-50, 5}, {5, 12}};
  const std::vector<double> d = slice_signed_distances(prepared, 1, truncation, points);
  // (8, 5): 5 mm from the top and bottom edges (true boundaries: an upper bound); the right edge
  // (2 mm away) is where the slice stops seeing, where the surface may lie or lie beyond (a lower
  // bound): the value is their mean, as at (5, 5), 5 mm from all of them.
  EXPECT_NEAR(d[0], 3.5, 1e-9);
  EXPECT_NEAR(d[1], 5.0, 1e-9);
  EXPECT_NEAR(d[2], -3.0, 1e-9);
  EXPECT_TRUE(std::isnan(d[3]));         // inside the unknown region: no data
  EXPECT_NEAR(d[4], -truncation, 1e-9);  // far away: truncated
  EXPECT_NEAR(d[5], -2.0, 1e-9);
}

TEST(ThinPlateData, AShadowCastersEdgeAlongAnUnknownRegionIsATrueBoundary) {
  // Two squares, materials 1 (a bone: it casts a shadow) and 2, each bordering an unknown region
  // on its right, both cut on the left by the field of view's edge at x = 2.
  LabeledSlice slice = z_slice(0.0);
  slice.fov = Ring2{{2, -60}, {60, -60}, {60, 60}, {2, 60}};
  slice.regions.push_back({1, Ring2{{0, 0}, {10, 0}, {10, 10}, {0, 10}}, {}});
  slice.regions.push_back({kUnknownLabel, Ring2{{10, 0}, {20, 0}, {20, 10}, {10, 10}}, {}});
  slice.regions.push_back({2, Ring2{{0, 20}, {10, 20}, {10, 30}, {0, 30}}, {}});
  slice.regions.push_back({kUnknownLabel, Ring2{{10, 20}, {20, 20}, {20, 30}, {10, 30}}, {}});
  const Box3 box{Vec3(-60, -60, -10), Vec3(60, 60, 10)};
  const PreparedSlice prepared = prepare_slice(slice, 0, {1, 2}, box);
  const std::vector<Vec2> points{{8, 5}, {3, 5}, {12, 5}, {8, 25}, {3, 25}};
  const std::vector<double> d = slice_signed_distances(prepared, 2, 10.0, points, {true, false});
  // Two values per point: materials 1 and 2. (8, 5): 2 mm from the bone's edge along its
  // shadow, its end as drawn; the mean of the bounds (2 and 5 mm) would give 3.5.
  EXPECT_NEAR(d[0], 2.0, 1e-9);
  // (3, 5): 1 mm from the fov's edge, which stays a lower bound only: between 1 and 5 mm.
  EXPECT_NEAR(d[2], 3.0, 1e-9);
  EXPECT_TRUE(std::isnan(d[4]));  // inside the unknown region: no data
  // Material 2 casts no shadow: its edge along the unknown region bounds it from below.
  EXPECT_NEAR(d[7], 3.5, 1e-9);
  EXPECT_NEAR(d[9], 3.0, 1e-9);
  // Without the flag, material 1 is as material 2.
  const std::vector<double> plain = slice_signed_distances(prepared, 2, 10.0, points);
  EXPECT_NEAR(plain[0], 3.5, 1e-9);
  EXPECT_NEAR(plain[2], 3.0, 1e-9);
}

TEST(ThinPlateData, AMaterialAbsentFromASliceIsFarOutsideEverywhere) {
  LabeledSlice slice = z_slice(0.0);
  slice.regions.push_back({2, circle(Vec2(0, 0), 5.0, 32), {}});
  const Box3 box{Vec3(-30, -30, -10), Vec3(30, 30, 10)};
  const PreparedSlice prepared = prepare_slice(slice, 0, {1, 2}, box);
  const std::vector<double> d = slice_signed_distances(prepared, 2, 4.0, {{0, 0}, {8, 0}});
  // Two values per point: materials 1 and 2.
  EXPECT_NEAR(d[0], -4.0, 1e-12);  // material 1 at the centre of material 2's disc
  EXPECT_NEAR(d[1], 4.0, 1e-12);   // material 2 there: 5 mm inside, clamped at 4
  EXPECT_NEAR(d[2], -4.0, 1e-12);
  EXPECT_NEAR(d[3], -3.0, 0.02);  // material 2: 3 mm outside its disc (a 32-gon)
}

// The online engine rebuilds when a label's truncation_extent changes, and a one-shot
// reconstruction computes it from the same extent: both truncate alike.
TEST(ThinPlateData, TruncationExtentsRoundUpToQuarterOctaves) {
  EXPECT_EQ(truncation_extent(0.0), 0.0);
  EXPECT_EQ(truncation_extent(128.0), 128.0);
  EXPECT_NEAR(truncation_extent(120.0), 128.0, 1e-9);
  EXPECT_EQ(truncation_extent(121.8), truncation_extent(120.0));  // a slice grew it by 1.5 %
  EXPECT_NEAR(truncation_extent(129.0), 128.0 * std::exp2(0.25), 1e-9);
  for (double e = 1.0; e < 1000.0; e *= 1.07) {
    EXPECT_GE(truncation_extent(e), e * (1.0 - 1e-9));
    EXPECT_LT(truncation_extent(e), e * std::exp2(0.25));
  }
}

TEST(ThinPlateField, AGridTooLargeForMemoryIsRefusedWithTheFix) {
  const Box3 box{Vec3::Zero(), Vec3::Constant(100.0)};
  try {
    ThinPlateField field(box, 0.05, 1, ThinPlateOptions{},
                         std::vector<double>{50.0});  // 1000^3 nodes
    FAIL() << "a grid of a billion nodes was allocated";
  } catch (const UnsupportedInput& e) {
    EXPECT_NE(std::string(e.what()).find("--depth"), std::string::npos) << e.what();
  }
}

TEST(ThinPlateField, SolveConvergesInAFewPreconditionedIterations) {
  const SliceSet set = sphere_stack(40.0, {-30, -15, 0, 15, 30});
  ReconstructionStats stats;
  const MeshSet meshes = reconstruct(set, thin_plate_options(), &stats);
  ASSERT_EQ(meshes.meshes.size(), 1u);
  EXPECT_GT(stats.solve_nodes, 10000u);
  // A multigrid-preconditioned solve: tens of iterations, not the thousands plain conjugate
  // gradients need on a bi-Laplacian of this size.
  EXPECT_GT(stats.solve_iterations, 0u);
  EXPECT_LT(stats.solve_iterations, 40u);
}

// The solve's sums are split and joined the same way whatever the threads do: the meshes are the
// same to the bit from one run to the next and at any thread count. (With parallel_reduce's
// automatic partitioning they followed the threads' timing and changed from run to run.)
TEST(ThinPlateField, MeshesAreTheSameToTheBitAtAnyThreadCount) {
  SliceSet set = sphere_stack(40.0, {-30, -15, 0, 15, 30});
  // A second organ beside the sphere: the materials are solved at once, each on its own.
  for (LabeledSlice& slice : set.slices)
    if (slice.origin_mm.z() == 0.0 && slice.u == Vec3::UnitX() && slice.v == Vec3::UnitY())
      slice.regions.push_back({2, circle(Vec2(42, 42), 15.0, 48), {}});
  ReconstructionOptions options = thin_plate_options();
  options.max_depth = 7;
  std::vector<MeshSet> runs;
  for (const int threads : {1, 2, 4}) {
    options.threads = threads;
    ReconstructionStats stats;
    runs.push_back(reconstruct(set, options, &stats));
    // Enough nodes for the sums to be split into many ranges (of 2^14 nodes).
    ASSERT_GT(stats.solve_nodes, 4u << 14);
    ASSERT_EQ(runs.back().meshes.size(), 2u);
    EXPECT_FALSE(runs.back().meshes[1].mesh.triangles.empty());
  }
  for (std::size_t run = 1; run < runs.size(); ++run) {
    SCOPED_TRACE("run " + std::to_string(run));
    ASSERT_EQ(runs[run].meshes.size(), runs[0].meshes.size());
    for (std::size_t m = 0; m < runs[0].meshes.size(); ++m) {
      EXPECT_EQ(runs[run].meshes[m].mesh.vertices, runs[0].meshes[m].mesh.vertices);
      EXPECT_EQ(runs[run].meshes[m].mesh.triangles, runs[0].meshes[m].mesh.triangles);
    }
  }
}

// The solver's kernels compiled for AVX2 (used where the CPU has it) and for the baseline x86-64
// give the same bits: the same element-wise operations in the same order, no fused
// multiply-add. Two organs, solved one-shot and then online, so that every kernel runs on every
// level. Skipped, saying why, on a CPU without AVX2: both fields would take the baseline kernels.
TEST(ThinPlateField, ItsAvx2AndBaselineKernelsGiveTheSameBits) {
#if (defined(__x86_64__) || defined(__i386__)) && defined(__GNUC__) && !defined(__clang__)
  if (!__builtin_cpu_supports("avx2"))
    GTEST_SKIP() << "this CPU has no AVX2: the solve takes the baseline kernels either way";
#else
  GTEST_SKIP() << "the AVX2 kernels are built for x86 with GCC only";
#endif
  SliceSet set = sphere_stack(40.0, {-30, -15, 0, 15, 30});
  for (LabeledSlice& slice : set.slices)
    if (slice.origin_mm.z() == 0.0 && slice.u == Vec3::UnitX() && slice.v == Vec3::UnitY())
      slice.regions.push_back({2, circle(Vec2(42, 42), 15.0, 48), {}});
  const Box3 box = *set.bounds;
  const double finest = box.size().maxCoeff() / 128.0;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1, 2}, box);
  const std::vector<double> extents = box_extents(material_boxes(prepared, 2));
  ThinPlateOptions wide_options, plain_options;
  plain_options.simd = false;
  ThinPlateField wide(box, finest, 2, wide_options, extents);
  ThinPlateField plain(box, finest, 2, plain_options, extents);
  const std::vector<PreparedSlice> first(prepared.begin(), prepared.end() - 2);
  for (ThinPlateField* field : {&wide, &plain}) field->add_slices(first);
  std::vector<int> iterations;
  for (std::size_t k = first.size(); k <= prepared.size(); ++k) {
    if (k > first.size())
      for (ThinPlateField* field : {&wide, &plain}) field->add_slices({prepared[k - 1]});
    const ThinPlateSolveStats a = wide.solve(), b = plain.solve();
    EXPECT_GT(a.iterations, 0);
    EXPECT_EQ(a.iterations, b.iterations);
    EXPECT_EQ(worst_difference(wide, plain, box, 3), 0.0) << "after " << k << " slices";
  }
}

TEST(ThinPlateField, SurfacePassesThroughTheInputContours) {
  const double r = 40.0;
  const SliceSet set = sphere_stack(r, {-30, -15, 0, 15, 30});
  ReconstructionStats stats;
  const MeshSet meshes = reconstruct(set, thin_plate_options(), &stats);
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  ASSERT_FALSE(mesh.empty());
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  EXPECT_EQ(component_count(mesh), 1u);
  // Every contour point has a mesh vertex near it: within a finest cell (120 mm / 2^7 = 0.94
  // mm) and a half, the grid's resolution.
  const double cell = 3.0 * r / 128.0;
  double worst = 0.0;
  for (const LabeledSlice& slice : set.slices)
    for (const Region& region : slice.regions)
      for (const Vec2& p : region.outer) {
        const Vec3 q = slice.to_world(p);
        double best = std::numeric_limits<double>::infinity();
        for (const Vec3& v : mesh.vertices) best = std::min(best, (v - q).norm());
        worst = std::max(worst, best);
      }
  EXPECT_LT(worst, 1.5 * cell);
  const double volume = signed_volume(mesh) / (4.0 / 3.0 * std::numbers::pi * r * r * r);
  EXPECT_NEAR(volume, 1.0, 0.04);
}

// A rod of radius 2.5 mm slanted 15 degrees from z, cut by planes 10 mm apart: four times its
// radius, so the paper's field gives one bead per plane, while the signed distance's extrusion
// overlaps from plane to plane and the thin-plate fill keeps one tube.
SliceSet slanted_rod() {
  SliceSet set;
  set.bounds = Box3{Vec3(-30, -30, -50), Vec3(30, 30, 50)};
  const double slope = std::tan(15.0 * std::numbers::pi / 180.0), radius = 2.5;
  for (int k = -4; k <= 4; ++k) {
    const double z = 10.0 * k;
    LabeledSlice s = z_slice(z);
    Ring2 ellipse;
    for (int i = 0; i < 64; ++i) {
      const double t = 2.0 * std::numbers::pi * i / 64;
      ellipse.emplace_back(
          slope * z + radius / std::cos(15.0 * std::numbers::pi / 180.0) * std::cos(t),
          radius * std::sin(t));
    }
    s.regions.push_back({1, ellipse, {}});
    set.slices.push_back(s);
  }
  return set;
}

TEST(ThinPlateField, ASlantedRodCrossedByFarApartPlanesIsOneTube) {
  const SliceSet set = slanted_rod();
  const MeshSet thin = reconstruct(set, thin_plate_options());
  ASSERT_FALSE(thin.meshes[0].mesh.empty());
  EXPECT_TRUE(check_mesh_health(thin.meshes[0].mesh).closed_manifold_oriented());
  EXPECT_EQ(component_count(thin.meshes[0].mesh), 1u);
  // It spans the planes: from below the first to above the last.
  const Box3 bounds = thin.meshes[0].mesh.bounds();
  EXPECT_LT(bounds.min.z(), -40.0);
  EXPECT_GT(bounds.max.z(), 40.0);
  // The paper's field on the same slices: beads (what issue 38 set out to change).
  const MeshSet beads = reconstruct(set, ReconstructionOptions{});
  EXPECT_GT(component_count(beads.meshes[0].mesh), 1u);
}

// Two slices a millimetre apart across an organ's end: the one through the organ sees a disc
// (its in-plane distance at the centre would be the truncation, 10 mm), the other nothing (-10
// mm). Each value is bounded by the other slice (the surface crosses the millimetre between
// them), so the field goes from about +1 to -1 across the gap, not from +10 to -10: a fill
// through data that jump by twice the truncation within a grid cell rings (the bulge before a
// rib's end in the default scan).
TEST(ThinPlateData, SlicesAcrossAnOrgansEndBoundEachOthersDistances) {
  const Box3 box{Vec3::Constant(-20.0), Vec3::Constant(20.0)};
  LabeledSlice through = z_slice(0.0), beyond = z_slice(1.0);
  through.regions.push_back({1, circle(Vec2(0, 0), 15.0, 96), {}});
  std::vector<PreparedSlice> slices;
  slices.push_back(prepare_slice(through, 0, {1}, box));
  slices.push_back(prepare_slice(beyond, 1, {1}, box));
  // Solve grid spacing 2 mm; truncation 0.1 x 100 mm.
  ThinPlateField field(box, 1.0, 1, ThinPlateOptions{}, std::vector<double>{100.0});
  field.add_slices(std::move(slices));
  field.solve();
  std::vector<double> values(2 * 2);
  field.evaluate({Vec3(0, 0, 0), Vec3(0, 0, 1)}, values.data());
  EXPECT_GT(values[1], 0.0);
  EXPECT_LT(values[1], 2.0);
  EXPECT_LT(values[3], 0.0);
  EXPECT_GT(values[3], -2.0);
}

// Each sample keeps the least of its own distance and the bounds every other slice gives it
// (tighten()), however the planes lie: a brute-force reference over every pair of a sample and a
// plane, on planes through a sphere at assorted tilts. The field visits only the samples near
// each plane and the buckets within reach; the reference visits everything.
TEST(ThinPlateData, EachSampleKeepsTheLeastOfItsBoundsByEveryOtherSlice) {
  const double r = 40.0;
  SliceSet set;
  set.bounds = Box3{Vec3::Constant(-60.0), Vec3::Constant(60.0)};
  const std::vector<std::pair<Vec3, Vec3>> planes = {
      {Vec3(0, 0, -30), Vec3(0, 0, 1)},     {Vec3(0, 0, 12), Vec3(0.1, 0, 1)},
      {Vec3(5, 0, 0), Vec3(1, 0.4, 0.2)},   {Vec3(0, -8, 3), Vec3(0.5, 1, 0.3)},
      {Vec3(0, 0, 33), Vec3(0.3, 0.2, 1)},  {Vec3(-20, 0, 0), Vec3(1, -0.7, 0.5)},
      {Vec3(0, 25, 0), Vec3(-0.2, 1, 0.9)}, {Vec3(0, 0, 37.5), Vec3(0, 0, 1)}};
  for (const auto& [origin, normal] : planes) {
    LabeledSlice s;
    s.origin_mm = origin;
    const Vec3 n = normal.normalized();
    s.u = n.unitOrthogonal();
    s.v = n.cross(s.u);
    const double d = origin.dot(n);  // the sphere's centre is at the origin
    const Vec2 centre(-origin.dot(s.u), -origin.dot(s.v));
    if (std::abs(d) < r) s.regions.push_back({1, circle(centre, std::sqrt(r * r - d * d), 96), {}});
    set.slices.push_back(s);
  }
  const Box3 box = *set.bounds;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1}, box);
  const double finest = box.size().maxCoeff() / 128.0;
  ThinPlateField field(box, finest, 1, ThinPlateOptions{}, std::vector<double>{100.0});
  field.add_slices(prepared);
  const double truncation = 0.1 * truncation_extent(100.0);
  const double least = 0.25 * 2.0 * finest;  // a quarter of the solve grid's spacing
  const std::vector<double> values = field.sample_values();
  const std::vector<std::vector<Vec3>> points = field.sample_points();
  ASSERT_EQ(points.size(), prepared.size());
  std::size_t at = 0, tightened = 0, wrong = 0;
  for (std::size_t a = 0; a < prepared.size(); ++a)
    for (const Vec3& p : points[a]) {
      auto in_plane = [&](const PreparedSlice& s) {
        const Vec3 q = p - s.origin;
        return Vec2(q.dot(s.u), q.dot(s.v));
      };
      const double own =
          slice_signed_distances(prepared[a], 1, truncation, {in_plane(prepared[a])})[0];
      double best = std::abs(own);
      for (std::size_t b = 0; b < prepared.size(); ++b) {
        if (b == a) continue;
        const double h =
            std::max(std::abs((p - prepared[b].origin).dot(prepared[b].unit_normal)), least);
        const double there =
            slice_signed_distances(prepared[b], 1, truncation, {in_plane(prepared[b])})[0];
        if (std::isnan(there)) continue;
        const double bound = (there > 0.0) != (own > 0.0) ? h : std::hypot(h, there);
        best = std::min(best, bound);
      }
      const double expected = own > 0.0 ? best : -best;
      tightened += best < std::abs(own);
      wrong += !(std::abs(values[at++] - expected) <= 1e-12 * truncation);
    }
  EXPECT_EQ(at, values.size());
  EXPECT_EQ(wrong, 0u);
  EXPECT_GT(tightened, values.size() / 20);  // the bounds matter for a good share of samples
}

// Two parallel slices 0.1 mm apart whose discs disagree (a tracking error: the same section
// 6 mm to the side): the first slice's samples inside its disc where the second is outside at
// their foot are bounded by a quarter of the solve grid's spacing, not by the 0.1 mm between
// the slices, which would take them to about zero over the whole disagreement.
TEST(ThinPlateData, NearSlicesBoundEachOtherNoCloserThanAQuarterSpacing) {
  const Box3 box{Vec3::Constant(-20.0), Vec3::Constant(20.0)};
  LabeledSlice first = z_slice(0.0), second = z_slice(0.1);
  first.regions.push_back({1, circle(Vec2(0, 0), 5.0, 96), {}});
  second.regions.push_back({1, circle(Vec2(6, 0), 5.0, 96), {}});
  std::vector<PreparedSlice> slices;
  slices.push_back(prepare_slice(first, 0, {1}, box));
  slices.push_back(prepare_slice(second, 1, {1}, box));
  const double spacing = 2.0;  // the finest cell 1 mm, coarsened once
  ThinPlateField field(box, 1.0, 1, ThinPlateOptions{}, std::vector<double>{100.0});
  field.add_slices(std::move(slices));
  const std::vector<double> values = field.sample_values();
  const std::vector<Vec3> points = field.sample_points()[0];
  std::size_t checked = 0;
  for (std::size_t e = 0; e < points.size(); ++e) {
    const Vec2 q = points[e].head<2>();
    // Inside the first disc by more than the bound, outside the second by a margin.
    if (q.norm() > 5.0 - spacing || (q - Vec2(6, 0)).norm() < 5.0 + 0.1 * spacing) continue;
    EXPECT_NEAR(values[e], 0.25 * spacing, 1e-12) << "at " << q.transpose();
    ++checked;
  }
  EXPECT_GE(checked, 4u);
}

// A rod of 0.6 mm radius along z, crossed by planes 1 mm apart, on a solve grid of 2 mm whose
// sample lines (along z, at even x and y) it falls between: 0.75 mm from the nearest, so no
// sample lies inside any of its sections. Its sections are dilated to the thinnest the data keep
// (0.45 spacings, 0.9 mm) and the field is positive along the rod; the same rod centred on a
// sample line holds a sample in every section, and keeps its data as drawn.
ThinPlateField thin_rod_field(const Vec2& centre) {
  const Box3 box{Vec3::Constant(-20.0), Vec3::Constant(20.0)};
  std::vector<PreparedSlice> slices;
  for (int k = -10; k <= 10; ++k) {
    LabeledSlice s = z_slice(k);
    s.regions.push_back({1, circle(centre, 0.6, 48), {}});
    slices.push_back(prepare_slice(s, static_cast<std::size_t>(k + 10), {1}, box));
  }
  ThinPlateField field(box, 1.0, 1, ThinPlateOptions{}, std::vector<double>{40.0});  // spacing 2 mm
  field.add_slices(std::move(slices));
  field.solve();
  return field;
}

TEST(ThinPlateField, ASectionBetweenTheSampleLinesIsDilatedToReachThem) {
  const ThinPlateField between = thin_rod_field(Vec2(0.75, 0.0));
  std::vector<Vec3> axis;
  for (int k = -8; k <= 8; ++k) axis.emplace_back(0.75, 0.0, k);
  std::vector<double> values(2 * axis.size());
  between.evaluate(axis, values.data());
  for (std::size_t p = 0; p < axis.size(); ++p)
    EXPECT_GT(values[2 * p + 1], 0.0) << "at z = " << axis[p].z();
  // The sample on the line (0, 0) of each section: 0.9 mm dilated radius less 0.75 mm.
  const std::vector<double> samples = between.sample_values();
  EXPECT_NEAR(*std::max_element(samples.begin(), samples.end()), 0.15, 0.01);

  const ThinPlateField on_line = thin_rod_field(Vec2(0.0, 0.0));
  const std::vector<double> drawn = on_line.sample_values();
  EXPECT_NEAR(*std::max_element(drawn.begin(), drawn.end()), 0.6, 0.01);
}

// The slices added one by one to a field set up for the first one's extent, its truncation grown
// with the organ's extent before each (grow_extents) and the field solved after each; `growths`
// counts the steps of the rounded extent.
ThinPlateField grown_slice_by_slice(const Box3& box, double finest,
                                    const std::vector<PreparedSlice>& prepared, int& growths) {
  ThinPlateField grown(box, finest, 1, ThinPlateOptions{},
                       box_extents(material_boxes({prepared[0]}, 1)));
  growths = 0;
  for (std::size_t k = 0; k < prepared.size(); ++k) {
    const std::vector<double> extents = box_extents(material_boxes(
        {prepared.begin(), prepared.begin() + static_cast<std::ptrdiff_t>(k) + 1}, 1));
    growths += truncation_extent(extents[0]) != truncation_extent(grown.extents()[0]);
    EXPECT_TRUE(grown.grow_extents(extents));
    grown.add_slices({prepared[k]});
    grown.solve();
  }
  return grown;
}

// How many sample values of two fields differ (their samples in the same order).
std::size_t differing_samples(const ThinPlateField& a, const ThinPlateField& b) {
  const std::vector<double> va = a.sample_values(), vb = b.sample_values();
  EXPECT_EQ(va.size(), vb.size());
  std::size_t differ = 0;
  for (std::size_t n = 0; n < std::min(va.size(), vb.size()); ++n) differ += va[n] != vb[n];
  return differ;
}

// Discs that end at a field of view's edge (x = 10): their inside values near it lie below the
// truncation although their true boundaries are beyond it (half boundaries), and must follow a
// grown truncation as a field built with it takes them.
TEST(ThinPlateData, AGrowingTruncationKeepsTheBoundsOfEdgesAlongUnknownRegions) {
  SliceSet set = sphere_stack(40.0, {30, 20, 10, 0, -10, -20});
  for (std::size_t k = 0; k < 6; ++k)
    set.slices[k].fov = Ring2{{-60, -60}, {10, -60}, {10, 60}, {-60, 60}};
  const Box3 box = *set.bounds;
  const double finest = box.size().maxCoeff() / 128.0;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1}, box);
  int growths = 0;
  const ThinPlateField grown = grown_slice_by_slice(box, finest, prepared, growths);
  EXPECT_GE(growths, 2);
  ThinPlateField fresh(box, finest, 1, ThinPlateOptions{},
                       box_extents(material_boxes(prepared, 1)));
  fresh.add_slices(prepared);
  fresh.solve();
  EXPECT_EQ(differing_samples(grown, fresh), 0u);
}

// An organ whose extent grows slice by slice: a field whose truncation grows with it
// (grow_extents: the samples the old truncation clamped take their distance and bounds again)
// holds, after each slice, the data a field built with the final truncation from the start
// holds: the same to the bit. A tilted slice crosses the others at an angle.
TEST(ThinPlateData, AGrowingTruncationGivesTheDataOfAFieldBuiltWithIt) {
  SliceSet set = sphere_stack(40.0, {30, 20, 10, 0, -10, -20});
  LabeledSlice tilted;
  tilted.origin_mm = Vec3::Zero();
  tilted.u = Vec3::UnitX();
  tilted.v = Vec3(0.0, std::cos(0.6), std::sin(0.6));
  tilted.regions.push_back({1, circle(Vec2(0, 0), 40.0, 96), {}});
  set.slices.push_back(tilted);
  const Box3 box = *set.bounds;
  const double finest = box.size().maxCoeff() / 128.0;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1}, box);
  const std::vector<double> final_extents = box_extents(material_boxes(prepared, 1));
  int growths = 0;
  const ThinPlateField grown = grown_slice_by_slice(box, finest, prepared, growths);
  EXPECT_GE(growths, 3);
  ThinPlateField fresh(box, finest, 1, ThinPlateOptions{}, final_extents);
  fresh.add_slices(prepared);
  fresh.solve();
  ASSERT_EQ(truncation_extent(grown.extents()[0]), truncation_extent(final_extents[0]));
  EXPECT_EQ(differing_samples(grown, fresh), 0u);
  // A truncation not grown: the data would differ (the guard above compares something).
  ThinPlateField first_only(box, finest, 1, ThinPlateOptions{},
                            box_extents(material_boxes({prepared[0]}, 1)));
  first_only.add_slices(prepared);
  EXPECT_GT(differing_samples(first_only, fresh), fresh.sample_values().size() / 10);
  // Both solves from their own start agree to the online tolerance where the mesh reads them.
  const ThinPlateOptions options;
  const double spacing = 2.0 * finest;
  const double band_mm = options.online_band * 0.1 * truncation_extent(final_extents[0]);
  const FieldComparison compared = compare_near_zero(grown, fresh, box, band_mm);
  EXPECT_GT(compared.near_count, 100u);
  EXPECT_LT(compared.near_zero, online_bound(spacing));
  EXPECT_LT(compared.anywhere, band_mm);
}

// A square rod (8 mm wide) along z, crossed by planes alternately 2.5 and 1.2 mm apart (the
// solve grid's spacing is 2.7 mm): it ends 0.05 mm beyond the plane at z = +-36.4, and the next
// plane, 1.2 mm further, sees nothing. Its ends lie between those planes, and the fill does not
// bulge before them (without the bounds between neighbouring slices' data: 5.8 mm wide).
TEST(ThinPlateField, AnOrgansEndNeitherBulgesNorFallsShortOfItsLastSlice) {
  SliceSet set;
  set.bounds = Box3{Vec3::Constant(-50.0), Vec3::Constant(50.0)};
  double z = -47.5;
  for (int k = 0; z < 47.0; ++k) {
    LabeledSlice s = z_slice(z);
    if (std::abs(z) < 36.45)
      s.regions.push_back({1, Ring2{{-4, -4}, {4, -4}, {4, 4}, {-4, 4}}, {}});
    set.slices.push_back(s);
    z += k % 2 == 0 ? 2.5 : 1.2;
  }
  ASSERT_NEAR(set.slices[6].origin_mm.z(), -36.4, 1e-9);
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  ASSERT_FALSE(mesh.empty());
  EXPECT_EQ(component_count(mesh), 1u);
  const Box3 bounds = mesh.bounds();
  for (const double end : {-bounds.min.z(), bounds.max.z()}) {
    EXPECT_GT(end, 36.4);
    EXPECT_LT(end, 37.6);
  }
  double widest = 0.0;
  for (const Vec3& v : mesh.vertices)
    if (std::abs(v.z()) <= 36.4) widest = std::max({widest, std::abs(v.x()), std::abs(v.y())});
  EXPECT_LT(widest, 4.75);  // 4.4 measured
}

// The area a closed, outward-oriented mesh encloses in the plane z = `z`: each triangle that
// crosses the plane gives a segment of the section's outline, oriented anticlockwise seen from +z
// (along ez x its outward normal).
double section_area(const TriangleMesh& mesh, double z) {
  double twice_area = 0.0;
  for (const auto& t : mesh.triangles) {
    std::vector<Vec3> crossings;
    for (std::size_t e = 0; e < 3; ++e) {
      const Vec3& a = mesh.vertices[t[e]];
      const Vec3& b = mesh.vertices[t[(e + 1) % 3]];
      if ((a.z() < z) != (b.z() < z))
        crossings.push_back(a + (b - a) * (z - a.z()) / (b.z() - a.z()));
    }
    if (crossings.size() != 2) continue;
    const Vec3 normal = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                            .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    Vec3 p = crossings[0], q = crossings[1];
    if ((q - p).dot(Vec3::UnitZ().cross(normal)) < 0.0) std::swap(p, q);
    twice_area += p.x() * q.y() - p.y() * q.x();
  }
  return 0.5 * twice_area;
}

// A rod of radius 4.8 mm (the default scan's rib) along z, crossed by planes 2 mm apart; the
// octree's finest cells are 1.35 mm. Its mesh's sections, between and on the planes, keep the
// drawn circle's area to 0.2 %: the marching-tetrahedra mesh alone, its vertices interpolated
// linearly along cell edges and its triangles chords of the bend, was 0.34 % smaller.
TEST(ThinPlateField, ACurvedSurfacesMeshKeepsItsSectionsArea) {
  SliceSet set;
  set.bounds = Box3{Vec3::Constant(-50.0), Vec3::Constant(50.0)};
  const Ring2 ring = circle(Vec2(0, 0), 4.8, 96);
  for (double z = -40.0; z <= 40.0; z += 2.0) {
    LabeledSlice s = z_slice(z);
    s.regions.push_back({1, ring, {}});
    set.slices.push_back(s);
  }
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  ASSERT_FALSE(mesh.empty());
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  const double drawn = signed_area(ring);
  for (const double z : {-15.0, -10.5, -5.0, 0.0, 0.5, 1.0, 7.3, 12.0}) {
    const double area = section_area(mesh, z);
    EXPECT_NEAR(area, drawn, 0.002 * drawn) << "z = " << z;  // 0.09 % measured
  }
}

// Three slices within 2 mm of z = 0 through a square rod along z, in a box 100 mm deep: the
// slices do not sample z (the box reaches 49 mm beyond them on either side, against their 2 mm
// of spread), so nothing says where the rod ends along z, and the field extrudes their sections
// through the box (as the nearest-slice baseline does) instead of closing the rod just beyond
// them (it ended at z = +-12.1 with the closing on every face).
TEST(ThinPlateField, NearlyCoplanarSlicesAreNotClosedAlongTheirNormal) {
  SliceSet set;
  set.bounds = Box3{Vec3(-50, -50, -50), Vec3(50, 50, 50)};
  for (const double z : {-1.0, 0.0, 1.0}) {
    LabeledSlice s = z_slice(z);
    s.regions.push_back({1, Ring2{{-8, -8}, {8, -8}, {8, 8}, {-8, 8}}, {}});
    set.slices.push_back(s);
  }
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  ASSERT_FALSE(mesh.empty());
  // Cut by the box's faces, and closed there.
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  EXPECT_EQ(component_count(mesh), 1u);
  const Box3 bounds = mesh.bounds();
  EXPECT_LT(bounds.min.z(), -45.0);
  EXPECT_GT(bounds.max.z(), 45.0);
  // Its sections stay the slices' square: no swelling away from them.
  for (const Vec3& v : mesh.vertices) {
    EXPECT_LT(std::abs(v.x()), 9.0);
    EXPECT_LT(std::abs(v.y()), 9.0);
  }
}

// A cylinder of radius 10 mm along z, cut every 2 mm by planes whose circles alternate
// between radii 10.8 and 9.2 mm: outlines with an error, as segmented frames give. The mesh's
// radius at each plane (the mean distance from the axis of the vertices within 0.3 mm of it),
// averaged over the planes of each kind: how much of the planes' alternation the surface keeps.
double kept_alternation(double outline_sd_mm) {
  SliceSet set;
  set.bounds = Box3{Vec3(-30, -30, -25), Vec3(30, 30, 25)};
  for (int k = -10; k <= 10; ++k) {
    LabeledSlice s = z_slice(2.0 * k);
    s.regions.push_back({1, circle(Vec2(0, 0), k % 2 == 0 ? 10.8 : 9.2, 96), {}});
    s.outline_sd_mm = outline_sd_mm;
    set.slices.push_back(s);
  }
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  double radius[2] = {0.0, 0.0}, count[2] = {0.0, 0.0};
  for (int k = -8; k <= 8; ++k)  // away from the ends
    for (const Vec3& v : mesh.vertices)
      if (std::abs(v.z() - 2.0 * k) < 0.3) {
        radius[k % 2 == 0] += std::hypot(v.x(), v.y());
        count[k % 2 == 0] += 1.0;
      }
  EXPECT_GT(count[0], 0.0);
  EXPECT_GT(count[1], 0.0);
  return radius[1] / count[1] - radius[0] / count[0];
}

TEST(ThinPlateField, OutlinesWithAnErrorAreFittedNotInterpolated) {
  // Exact outlines are interpolated: the surface follows the planes' 1.6 mm alternation. With
  // the outlines' error given, the field is a smoothing spline: it averages neighbouring planes
  // and runs near the mean radius.
  const double exact = kept_alternation(0.0), fitted = kept_alternation(0.8);
  EXPECT_GT(exact, 0.8);
  EXPECT_LT(fitted, 0.3 * exact);  // 1.68 and 0.37 mm
}

// A large organ and a small thin one in a 200 mm box: a sphere of radius 50 (material 1) and a
// slab 2 mm thick, 30 mm wide and 30 mm tall (material 2), cut by planes z = const 5 mm apart.
// The box's grid has 3.1 mm cells (2 finest cells of 200 / 2^7 mm), more than the slab's
// thickness.
constexpr double kSlabX = 70.0, kSlabHalfThickness = 1.0;
SliceSet sphere_and_slab() {
  SliceSet set;
  set.bounds = Box3{Vec3::Constant(-100), Vec3::Constant(100)};
  const Vec3 centre(-20, -20, 0);
  for (double z = -47.5; z <= 47.5; z += 5.0) {
    LabeledSlice s = z_slice(z);
    if (Ring2 ring = sphere_section(centre, 50, z); !ring.empty())
      s.regions.push_back({1, ring, {}});
    if (std::abs(z) < 15.0)
      s.regions.push_back(
          {2,
           {Vec2(kSlabX - kSlabHalfThickness, 50), Vec2(kSlabX + kSlabHalfThickness, 50),
            Vec2(kSlabX + kSlabHalfThickness, 80), Vec2(kSlabX - kSlabHalfThickness, 80)},
           {}});
    set.slices.push_back(s);
  }
  return set;
}

// Where material 2's function crosses zero along x at (y, z) = (65, 0), midway between two
// planes: the slab's faces (the first and last crossing within 10 mm of it).
std::pair<double, double> slab_faces(const ThinPlateField& field) {
  std::vector<Vec3> points;
  for (int i = 0; i <= 2000; ++i) points.push_back(Vec3(kSlabX - 10.0 + 0.01 * i, 65.0, 0.0));
  std::vector<double> values(points.size() * 3);
  field.evaluate(points, values.data());
  double first = std::numeric_limits<double>::quiet_NaN(), last = first;
  for (std::size_t i = 0; i + 1 < points.size(); ++i) {
    const double a = values[3 * i + 2], b = values[3 * (i + 1) + 2];
    if ((a > 0.0) == (b > 0.0)) continue;
    const double x = points[i].x() + 0.01 * a / (a - b);
    if (std::isnan(first)) first = x;
    last = x;
  }
  return {first, last};
}

// The slab gets a grid of its own at the finest cell (1.6 mm) over its padded box; the sphere
// stays on the box's grid. The slab's faces between the planes then lie within 0.2 mm of the
// truth, where on the box's grid alone the slab is gone there.
TEST(ThinPlateField, ASmallOrganGetsAGridOfItsOwnThatKeepsItsThinPartsWhole) {
  const SliceSet set = sphere_and_slab();
  const Box3 box = *set.bounds;
  const double finest = box.size().maxCoeff() / 128.0;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1, 2}, box);
  const std::vector<Box3> boxes = material_boxes(prepared, 2);
  ThinPlateField own(box, finest, 2, ThinPlateOptions{}, boxes);
  ThinPlateField shared(box, finest, 2, ThinPlateOptions{}, box_extents(boxes));
  const std::vector<Box3> own_boxes = own.own_boxes();
  ASSERT_EQ(own_boxes.size(), 2u);
  EXPECT_FALSE(own_boxes[0].min.x() <= own_boxes[0].max.x());  // the sphere: the box's grid
  ASSERT_TRUE(own_boxes[1].min.x() <= own_boxes[1].max.x());
  // The slab's contours' box, padded by 10 % of its diagonal and rounded out to 8 finest cells.
  const Box3 padded = boxes[1].padded(0.1 * boxes[1].diagonal());
  for (int a = 0; a < 3; ++a) {
    EXPECT_LE(own_boxes[1].min[a], padded.min[a]);
    EXPECT_GT(own_boxes[1].min[a], padded.min[a] - 8 * finest);
    EXPECT_GE(own_boxes[1].max[a], padded.max[a]);
    EXPECT_LT(own_boxes[1].max[a], padded.max[a] + 8 * finest);
  }
  for (ThinPlateField* field : {&own, &shared}) {
    field->add_slices(prepared);
    field->solve();
  }
  const auto [low, high] = slab_faces(own);
  EXPECT_NEAR(low, kSlabX - kSlabHalfThickness, 0.2);
  EXPECT_NEAR(high, kSlabX + kSlabHalfThickness, 0.2);
  // On the box's grid alone the slab is gone midway between the planes (no crossing).
  EXPECT_TRUE(std::isnan(slab_faces(shared).first));
  // The sphere is solved as it was on the box's grid alone (the same operator and data).
  std::vector<Vec3> points;
  for (int i = 0; i < 500; ++i) points.push_back(Vec3(-80.0 + 0.24 * i, -20.0, 1.0));
  std::vector<double> a(points.size() * 3), b(points.size() * 3);
  own.evaluate(points, a.data());
  shared.evaluate(points, b.data());
  for (std::size_t i = 0; i < points.size(); ++i) EXPECT_EQ(a[3 * i + 1], b[3 * i + 1]);
}

// The engine's option: with own grids (the default) the slab's mesh is one part about its
// volume; on the one grid over the box (`reconstruct --one-grid`) it breaks up or is gone.
TEST(ThinPlateField, ReconstructionsGiveSmallOrgansTheirGridsUnlessAskedForOne) {
  const SliceSet set = sphere_and_slab();
  ReconstructionOptions options = thin_plate_options();
  ReconstructionStats own_stats, one_stats;
  const MeshSet own = reconstruct(set, options, &own_stats);
  options.own_grids = false;
  const MeshSet one = reconstruct(set, options, &one_stats);
  ASSERT_EQ(own.meshes.size(), 2u);
  const TriangleMesh& slab = own.meshes[1].mesh;
  EXPECT_EQ(component_count(slab), 1u);
  // 2 x 30 x 30 mm between its outermost slices, and half a gap beyond them.
  EXPECT_NEAR(signed_volume(slab) / (2.0 * 30.0 * 30.0), 1.0, 0.25);
  const bool one_whole = one.meshes.size() == 2 && component_count(one.meshes[1].mesh) == 1 &&
                         std::abs(signed_volume(one.meshes[1].mesh) / 1800.0 - 1.0) < 0.25;
  EXPECT_FALSE(one_whole);
  EXPECT_GT(own_stats.solve_nodes, one_stats.solve_nodes);
}

TEST(ThinPlateField, AnOrganInsideAnotherStaysInside) {
  // Material 1: a sphere of radius 30 minus a sphere of radius 12 (material 2) at (4, 0, 0).
  SliceSet set;
  set.bounds = Box3{Vec3::Constant(-45), Vec3::Constant(45)};
  const Vec3 inner_centre(4, 0, 0);
  for (double z = -27; z <= 27; z += 6) {
    LabeledSlice s = z_slice(z);
    Region outer{1, sphere_section(Vec3::Zero(), 30, z), {}};
    if (Ring2 hole = sphere_section(inner_centre, 12, z); !hole.empty()) {
      outer.holes.push_back(hole);
      s.regions.push_back({2, hole, {}});
    }
    s.regions.insert(s.regions.begin(), outer);
    set.slices.push_back(s);
  }
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  ASSERT_EQ(meshes.meshes.size(), 2u);
  const TriangleMesh& outer = meshes.meshes[0].mesh;
  const TriangleMesh& inner = meshes.meshes[1].mesh;
  ASSERT_FALSE(inner.empty());
  EXPECT_TRUE(check_mesh_health(outer).closed_manifold_oriented());
  EXPECT_TRUE(check_mesh_health(inner).closed_manifold_oriented());
  EXPECT_EQ(component_count(inner), 1u);
  // Material 1's mesh bounds the shell: the outer sphere and the inner cavity.
  EXPECT_EQ(component_count(outer), 2u);
  for (const Vec3& p : inner.vertices) EXPECT_LT((p - inner_centre).norm(), 14.0);
  const double inner_volume = signed_volume(inner) / (4.0 / 3.0 * std::numbers::pi * 12 * 12 * 12);
  EXPECT_NEAR(inner_volume, 1.0, 0.15);
}

TEST(ThinPlateField, UnknownPatchesCarryNoDataAndCompleteFromTheNeighbours) {
  const double r = 40.0;
  SliceSet set = sphere_stack(r, {-30, -15, 0, 15, 30});
  // An unknown hole in the middle of the z = 0 disc: no cavity may grow there.
  Region& disc = set.slices[2].regions[0];
  const Ring2 patch = circle(Vec2(0, 0), 0.5 * r, 24);
  disc.holes.push_back(patch);
  set.slices[2].regions.push_back({kUnknownLabel, patch, {}});
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  EXPECT_EQ(component_count(mesh), 1u);
  for (const Vec3& p : mesh.vertices) EXPECT_GT(p.norm(), 0.8 * r);
}

// A rod of radius 5 mm along z whose far half borders its acoustic shadow in every slice (an
// unknown region from its far surface down to y = -40, as the simulator's rib casts); with
// `caster`, the rod's label is declared to cast that shadow. The box of its thin-plate mesh.
Box3 rod_with_its_shadow(bool caster) {
  const double r = 5.0;
  const Ring2 disc = circle(Vec2(0, 0), r, 96);
  Ring2 shadow{{-r, 0}, {-r, -40}, {r, -40}, {r, 0}};
  for (int i = 95; i >= 48; --i) shadow.push_back(disc[static_cast<std::size_t>(i)]);
  shadow.pop_back();  // disc[48] is (-r, 0), the first point
  SliceSet set;
  set.bounds = Box3{Vec3(-30, -50, -30), Vec3(30, 30, 30)};
  if (caster) set.labels.push_back({1, "rod", true});
  for (const double z : {-20.0, -10.0, 0.0, 10.0, 20.0}) {
    LabeledSlice s = z_slice(z);
    s.regions.push_back({1, disc, {}});
    s.regions.push_back({kUnknownLabel, shadow, {}});
    set.slices.push_back(s);
  }
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  EXPECT_EQ(component_count(mesh), 1u);
  return mesh.bounds();
}

TEST(ThinPlateField, AnOrganDoesNotGoOnFarIntoItsOwnShadow) {
  // The rod and its shadow: the surface may lie along the shadow or beyond, and the field must
  // not carry the rod's inside values far into it: with the edge along the shadow as no
  // boundary at all, the rod went 2.1 mm deeper than its 5 mm; with that edge's distance as a
  // lower bound, 1.1 mm.
  const double r = 5.0;
  const Box3 bounds = rod_with_its_shadow(false);
  EXPECT_GT(bounds.min.y(), -r - 1.6);
  EXPECT_LT(bounds.max.y(), r + 1.0);
}

TEST(ThinPlateField, AShadowCasterEndsAtItsDrawnEdgeAlongItsShadow) {
  // The rod and shadow above, the rod declared a shadow caster (a bone: its drawn section ends
  // at its surface, also along its shadow): the field ends it there, not deeper.
  const double r = 5.0;
  const Box3 bounds = rod_with_its_shadow(true);
  EXPECT_GT(bounds.min.y(), -r - 0.3);
  EXPECT_LT(bounds.max.y(), r + 0.3);
}

TEST(ThinPlateField, AFieldOfViewsEdgeIsNoSurface) {
  // Horizontal sections of a sphere seen through a field of view that stops at x = 10 mm (the
  // sphere reaches x = 40): the fov's edge cuts the discs, and must neither end the organ there
  // nor make "inside" blobs beside it. Two vertical slices see the whole sphere.
  const double r = 40.0;
  SliceSet set = sphere_stack(r, {-30, -15, 0, 15, 30});
  for (std::size_t k = 0; k < 5; ++k)
    set.slices[k].fov = Ring2{{-60, -60}, {10, -60}, {10, 60}, {-60, 60}};
  const MeshSet meshes = reconstruct(set, thin_plate_options());
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  EXPECT_EQ(component_count(mesh), 1u);
  double worst = 0.0;
  for (const Vec3& p : mesh.vertices) worst = std::max(worst, std::abs(p.norm() - r));
  EXPECT_LT(worst, 0.15 * r);
  const Box3 bounds = mesh.bounds();
  EXPECT_GT(bounds.max.x(), 0.85 * r);  // the organ goes on beyond the fov's edge
}

ReconstructorOptions thin_plate_setup(const SliceSet& set) {
  ReconstructorOptions setup;
  setup.engine = thin_plate_options();
  setup.bounds = set.bounds;
  return setup;
}

using SampledField = std::vector<std::pair<Vec3, std::vector<double>>>;

// Two sampled fields where both sampled: how many vertices, and the largest difference of a
// value. Both lists are sorted by grid key, i.e. lexicographically by position on one grid, so
// they are walked together.
struct SampledComparison {
  std::size_t compared = 0;
  double worst = 0.0;
};
SampledComparison compare_sampled(const SampledField& a, const SampledField& b) {
  auto less = [](const Vec3& p, const Vec3& q) {
    return std::lexicographical_compare(p.data(), p.data() + 3, q.data(), q.data() + 3);
  };
  SampledComparison out;
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (less(a[i].first, b[j].first)) {
      ++i;
    } else if (less(b[j].first, a[i].first)) {
      ++j;
    } else {
      for (std::size_t f = 0; f < a[i].second.size(); ++f) {
        out.worst = std::max(out.worst, std::abs(a[i].second[f] - b[j].second[f]));
      }
      ++out.compared;
      ++i;
      ++j;
    }
  }
  return out;
}

// The one-shot field of `set` as the online engine samples it.
SampledField reconstructed_field(const SliceSet& set) {
  Reconstructor once(thin_plate_setup(set));
  for (const LabeledSlice& slice : set.slices) once.add_slice(slice);
  once.update();
  return once.sampled_field();
}

// The online engine adds each slice's data and solves from the last solution to the online
// tolerance; the one-shot solve starts from the closing value. They agree to that tolerance,
// not to the bit.
// `set`'s slices given to an online engine one by one (an update after each) and to another at
// once: the online engine's sampled field against the other's, the solve iterations of its
// updates, and both engines' meshes.
struct OnlineAgainstOnce {
  std::size_t sampled = 0;
  SampledComparison field;
  std::vector<std::size_t> iterations;
  MeshSet online, once;
};
OnlineAgainstOnce online_against_once(const SliceSet& set) {
  OnlineAgainstOnce out;
  Reconstructor online(thin_plate_setup(set));
  for (const LabeledSlice& slice : set.slices) {
    online.add_slice(slice);
    out.iterations.push_back(online.update().step.solve_iterations);
  }
  Reconstructor once(thin_plate_setup(set));
  for (const LabeledSlice& slice : set.slices) once.add_slice(slice);
  once.update();
  const SampledField a = online.sampled_field();
  out.sampled = a.size();
  out.field = compare_sampled(a, once.sampled_field());
  out.online = online.mesh();
  out.once = once.mesh();
  return out;
}

TEST(ThinPlateOnline, UpdatesAgreeWithTheOneShotReconstruction) {
  const OnlineAgainstOnce r = online_against_once(sphere_stack(40.0, {-30, -15, 0, 15, 30}));
  for (const std::size_t n : r.iterations) EXPECT_GT(n, 0u);
  ASSERT_GT(r.sampled, 1000u);
  EXPECT_GT(r.field.compared, r.sampled * 9 / 10);
  // An update's solve stops when an iteration moves no value near the zero set by more than
  // the online tolerance (of the grid spacing, 2 finest cells of 120 / 2^7 mm).
  const double spacing = 2.0 * 120.0 / 128.0;
  EXPECT_LT(r.field.worst, online_bound(spacing));
  const double va = signed_volume(r.online.meshes[0].mesh),
               vb = signed_volume(r.once.meshes[0].mesh);
  EXPECT_NEAR(va / vb, 1.0, 1e-3);
}

// An organ with a grid of its own that grows as slices come (the slab above, its box rounded
// out to 8 finest cells) has that grid built again when it outgrows it (the engine rebuilds the
// field, each other grid going on from its last solution): online and one-shot still agree to
// the online tolerance.
TEST(ThinPlateOnline, AnOrganThatOutgrowsItsOwnGridAgreesWithTheOneShotReconstruction) {
  const OnlineAgainstOnce r = online_against_once(sphere_and_slab());
  ASSERT_GT(r.sampled, 1000u);
  EXPECT_GT(r.field.compared, r.sampled * 9 / 10);
  EXPECT_LT(r.field.worst, online_bound(2.0 * 200.0 / 128.0));
  ASSERT_EQ(r.once.meshes.size(), 2u);
  ASSERT_EQ(r.online.meshes.size(), 2u);
  for (std::size_t m = 0; m < 2; ++m) {
    const double va = signed_volume(r.online.meshes[m].mesh),
                 vb = signed_volume(r.once.meshes[m].mesh);
    EXPECT_NEAR(va / vb, 1.0, 1e-2);
  }
  EXPECT_EQ(component_count(r.once.meshes[1].mesh), 1u);
}

// Two fields given the same slices and solves: one samples its solution again per block only
// where it moved by more than the resample tolerance, the other (tolerance 0) everywhere. Their
// solutions are the same; their values differ by at most 1.25^3 x the tolerance (the
// Catmull-Rom weights' absolute sum), and a point whose nodes no solve changed since keeps its
// value to the bit.
TEST(ThinPlateOnline, PartialResamplingStaysWithinItsToleranceOfTheSolution) {
  const SliceSet set = sphere_stack(40.0, {-30, -15, 0, 15, 30});
  const Box3 box = *set.bounds;
  const double finest = box.size().maxCoeff() / 128.0;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1}, box);
  const std::vector<double> extents = box_extents(material_boxes(prepared, 1));
  ThinPlateOptions partial_options;
  ThinPlateOptions full_options;
  full_options.resample_tolerance = 0.0;
  ThinPlateField partial(box, finest, 1, partial_options, extents);
  ThinPlateField full(box, finest, 1, full_options, extents);
  // Points scattered over the box, off the grid's nodes.
  std::vector<Vec3> points;
  for (int i = 0; i < 4000; ++i) {
    const Vec3 t(std::fmod(0.618034 * i, 1.0), std::fmod(0.414214 * i + 0.1, 1.0),
                 std::fmod(0.732051 * i + 0.2, 1.0));
    points.push_back(box.min + t.cwiseProduct(box.size()));
  }
  const double spacing = 2.0 * finest;
  const double bound = 1.25 * 1.25 * 1.25 * partial_options.resample_tolerance * spacing;
  std::vector<double> before(points.size() * 2), a(points.size() * 2), b(points.size() * 2);
  std::size_t kept = 0, kept_equal = 0;
  double worst = 0.0, largest = 0.0;
  for (std::size_t k = 0; k < prepared.size(); ++k) {
    SCOPED_TRACE("slice " + std::to_string(k));
    partial.add_slices({prepared[k]});
    full.add_slices({prepared[k]});
    const std::uint32_t previous = partial.generation();
    partial.solve();
    full.solve();
    ASSERT_EQ(partial.generation(), previous + 1);
    partial.evaluate(points, a.data());
    full.evaluate(points, b.data());
    for (std::size_t p = 0; p < points.size(); ++p) {
      for (std::size_t f = 0; f < 2; ++f) {
        worst = std::max(worst, std::abs(a[2 * p + f] - b[2 * p + f]));
        largest = std::max(largest, std::abs(b[2 * p + f] - before[2 * p + f]));
      }
      if (k == 0 || partial.changed_at(points[p]) > previous) continue;
      ++kept;
      kept_equal += a[2 * p] == before[2 * p] && a[2 * p + 1] == before[2 * p + 1];
    }
    before = a;
  }
  EXPECT_LE(worst, bound);
  EXPECT_GT(worst, 0.0);  // some values were kept...
  EXPECT_GT(kept, 0u);
  EXPECT_EQ(kept_equal, kept);      // ...to the bit where changed_at says so
  EXPECT_GT(largest, 100 * bound);  // while the solution moved far more than the tolerance
}

// A material whose added data the field already fits to the online tolerance is not solved
// again (here: a slice given twice), one whose data are new is; either way the field stays
// within about that tolerance of a one-shot solve of the same data near the zero set. A coarse
// tolerance (a quarter of a grid spacing, online and one-shot) makes the repeated slice's fit
// residual fall below it.
TEST(ThinPlateOnline, AMaterialWhoseNewDataTheFieldFitsIsNotSolvedAgain) {
  const SliceSet set = sphere_stack(40.0, {-30, -15, 0, 15, 30});
  const Box3 box = *set.bounds;
  const double finest = box.size().maxCoeff() / 128.0, spacing = 2.0 * finest;
  std::vector<PreparedSlice> prepared = prepare_slices(set, {1}, box);
  LabeledSlice low = z_slice(-36.0);
  low.regions.push_back({1, sphere_section(Vec3::Zero(), 40.0, -36.0), {}});
  const PreparedSlice added = prepare_slice(low, prepared.size(), {1}, box);
  const std::vector<double> extents = box_extents(material_boxes(prepared, 1));
  ThinPlateOptions options;
  options.tolerance = options.online_tolerance = 0.25;
  ThinPlateField online(box, finest, 1, options, extents);
  online.add_slices(prepared);
  EXPECT_EQ(online.solve().unchanged_materials, 0);  // a field's first solve always solves
  online.add_slices({prepared[2]});
  const ThinPlateSolveStats repeated = online.solve();
  EXPECT_EQ(repeated.unchanged_materials, 1);
  EXPECT_EQ(repeated.iterations, 0);
  online.add_slices({added});
  const ThinPlateSolveStats fresh = online.solve();
  EXPECT_EQ(fresh.unchanged_materials, 0);
  EXPECT_GT(fresh.iterations, 0);

  ThinPlateField once(box, finest, 1, options, extents);
  std::vector<PreparedSlice> all = prepared;
  all.push_back(prepared[2]);
  all.push_back(added);
  once.add_slices(all);
  once.solve();
  const double band_mm = options.online_band * 0.1 * truncation_extent(extents[0]);
  const FieldComparison compared = compare_near_zero(online, once, box, band_mm);
  EXPECT_LT(compared.near_zero, 2.0 * options.tolerance * spacing);
  EXPECT_LT(compared.anywhere, band_mm);
}

// Slices added one by one, each update solved from the last solution to the online tolerance,
// its stopping test on the nodes near the zero set; a one-shot solve of them all to the
// solver's tolerance at every node. Near the zero set (what the mesh reads) they agree to the
// online tolerance (plus the sampled solution's; 0.060 mm against 0.103), and everywhere to
// less than the band, so that beyond it the signs agree. Updates that stop at ten times the
// online tolerance drift beyond that (0.157 mm): the comparison sees the tolerance.
TEST(ThinPlateOnline, UpdatesAgreeWithTheOneShotFieldToTheOnlineTolerance) {
  const SliceSet set = sphere_stack(40.0, {-30, 30, -20, 20, -10, 10, 0});
  const Box3 box = *set.bounds;
  const double finest = box.size().maxCoeff() / 128.0, spacing = 2.0 * finest;
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {1}, box);
  const std::vector<double> extents = box_extents(material_boxes(prepared, 1));
  auto online_field = [&](const ThinPlateOptions& options) {
    ThinPlateField online(box, finest, 1, options, extents);
    for (const PreparedSlice& slice : prepared) {
      online.add_slices({slice});
      online.solve();
    }
    return online;
  };
  const ThinPlateOptions options;
  ThinPlateField once(box, finest, 1, options, extents);
  once.add_slices(prepared);
  once.solve();
  const double band_mm = options.online_band * 0.1 * truncation_extent(extents[0]);
  const double bound = online_bound(spacing);
  const FieldComparison compared = compare_near_zero(online_field(options), once, box, band_mm);
  EXPECT_GT(compared.near_count, 200u);
  EXPECT_LT(compared.near_zero, bound);
  EXPECT_LT(compared.anywhere, band_mm);
  ThinPlateOptions loose = options;
  loose.online_tolerance = 10.0 * options.online_tolerance;
  EXPECT_GT(compare_near_zero(online_field(loose), once, box, band_mm).near_zero, bound);
}

// The online engine keeps the octree's rows whose interpolation reads no block that a solve
// changed, through added slices, an organ's growing extent (a rebuild from the last field) and
// the removal of a stray slice (another rebuild, which moves the field near that slice only and
// keeps most rows): the result still agrees with the one-shot field.
TEST(ThinPlateOnline, KeptRowsStayCurrentThroughAdditionsRebuildsAndRemovals) {
  // The equator first: the vertical slices then grow the organ's extent, which rebuilds.
  const SliceSet stack = sphere_stack(40.0, {-30, -20, -10, 0, 10, 20, 30});
  SliceSet set = stack;
  std::rotate(set.slices.begin(), set.slices.begin() + 3, set.slices.end() - 2);
  // A stray disc inside the organ's box (so its extent does not change), added and removed.
  LabeledSlice stray = z_slice(-38.0);
  stray.regions.push_back({1, circle(Vec2(25, 25), 5.0, 32), {}});
  Reconstructor online(thin_plate_setup(set));
  std::size_t rebuilds = 0;
  for (const LabeledSlice& slice : set.slices) {
    online.add_slice(slice);
    rebuilds += online.update().full_rebuild;
  }
  EXPECT_EQ(rebuilds, 1u);  // the first update: the extent's growth is applied in place
  const int stray_id = online.add_slice(stray);
  EXPECT_FALSE(online.update().full_rebuild);
  ASSERT_TRUE(online.remove_slice(stray_id));
  const UpdateStats removal = online.update();
  EXPECT_TRUE(removal.full_rebuild);
  EXPECT_LT(removal.step.field_evaluations, online.sampled_field().size());  // rows were kept
  const auto a = online.sampled_field();
  const auto [compared, worst] = compare_sampled(a, reconstructed_field(set));
  EXPECT_GT(compared, a.size() * 9 / 10);
  // The online tolerance (of a grid spacing) and the sampled solution's (2.5e-3, times 1.25^3)
  // of the one-shot field.
  const double spacing = 2.0 * 120.0 / 128.0;
  EXPECT_LT(worst, online_bound(spacing));
}

// What an online update keeps (rows, unsolved materials, moved plateaus) depends on the values
// alone: the meshes after every update are the same to the bit at any thread count.
TEST(ThinPlateOnline, UpdatesAreTheSameToTheBitAtAnyThreadCount) {
  const SliceSet set = sphere_stack(40.0, {0, 30, -30, 15, -15});
  std::vector<std::vector<MeshSet>> runs;
  for (const int threads : {1, 3}) {
    ReconstructorOptions setup = thin_plate_setup(set);
    setup.engine.threads = threads;
    Reconstructor online(setup);
    runs.emplace_back();
    for (const LabeledSlice& slice : set.slices) {
      online.add_slice(slice);
      online.update();
      runs.back().push_back(online.mesh());
    }
  }
  for (std::size_t u = 0; u < runs[0].size(); ++u) {
    SCOPED_TRACE("update " + std::to_string(u));
    ASSERT_EQ(runs[1][u].meshes.size(), runs[0][u].meshes.size());
    for (std::size_t m = 0; m < runs[0][u].meshes.size(); ++m) {
      EXPECT_EQ(runs[1][u].meshes[m].mesh.vertices, runs[0][u].meshes[m].mesh.vertices);
      EXPECT_EQ(runs[1][u].meshes[m].mesh.triangles, runs[0][u].meshes[m].mesh.triangles);
    }
  }
}

// A wrong slice (a stray disc below the sphere) removed again: its data must go with it, or the
// stray blob stays in the mesh as a second part.
TEST(ThinPlateOnline, RemovingASliceTakesItsDataAway) {
  const SliceSet set = sphere_stack(40.0, {-30, -15, 0, 15, 30});
  Reconstructor online(thin_plate_setup(set));
  for (const LabeledSlice& slice : set.slices) online.add_slice(slice);
  LabeledSlice stray = z_slice(-52.0);
  stray.regions.push_back({1, circle(Vec2(0, 0), 6.0, 32), {}});
  const int stray_id = online.add_slice(stray);
  online.update();
  // The stray disc is there (in 4 pieces: the two vertical slices cross it and say outside).
  ASSERT_GT(component_count(online.mesh().meshes[0].mesh), 1u);
  ASSERT_TRUE(online.remove_slice(stray_id));
  const UpdateStats update = online.update();
  EXPECT_TRUE(update.full_rebuild);
  EXPECT_EQ(component_count(online.mesh().meshes[0].mesh), 1u);
  const MeshSet expected = reconstruct(set, thin_plate_options());
  // The rebuild starts its solve from the last field: equal to the solver's tolerance.
  EXPECT_NEAR(signed_volume(online.mesh().meshes[0].mesh) / signed_volume(expected.meshes[0].mesh),
              1.0, 1e-3);
}

}  // namespace
}  // namespace sonoshape::recon::thin_plate_test
