// The online engine against the one-shot reconstruction: after any sequence of additions and
// removals, the sampled field and the meshes equal those of reconstructing the same slices at once.
#include "sonoshape/recon/reconstructor.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/recon/reconstruct.hpp"
#include "test_shapes.hpp"

namespace sonoshape::recon::reconstructor_test {
namespace {

constexpr double kRadius = 30.0;
const Box3 kBox{Vec3::Constant(-45.0), Vec3::Constant(45.0)};

using test::circle;

// A 70 degree, 85 mm fan with its apex 45 mm from the centre of the plane's disc.
Ring2 sector_fan() {
  Ring2 fan{Vec2(0, 45)};
  for (int k = 0; k <= 8; ++k) {
    const double t = (-35.0 + 70.0 * k / 8.0) * std::numbers::pi / 180.0;
    fan.emplace_back(85.0 * std::sin(t), 45.0 - 85.0 * std::cos(t));
  }
  std::reverse(fan.begin(), fan.end());
  return fan;
}

// A random plane through the ball of radius 0.8 r cutting a sphere (label 1) and, when
// `two_labels`, a smaller sphere (label 2) beside it; optionally an ultrasound-like sector fov.
LabeledSlice random_slice(std::mt19937& rng, bool two_labels, bool fov) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-0.8, 0.8);
  Vec3 n(normal(rng), normal(rng), normal(rng));
  n.normalize();
  const Vec3 u = n.unitOrthogonal();
  LabeledSlice s;
  s.u = u;
  s.v = n.cross(u);
  s.origin_mm = n * (uniform(rng) * kRadius);
  auto add_sphere = [&](const Vec3& centre, double radius, int label) {
    const double d = n.dot(centre - s.origin_mm);
    if (std::abs(d) >= 0.95 * radius) return;
    s.regions.push_back(
        {label, circle(s.to_plane(centre - d * n), std::sqrt(radius * radius - d * d), 48), {}});
  };
  add_sphere(Vec3(-10, 0, 0), 0.5 * kRadius, 1);
  if (two_labels) add_sphere(Vec3(16, 4, 2), 0.3 * kRadius, 2);
  if (fov) s.fov = sector_fan();
  return s;
}

// Reconstructs `set` in one update of a fresh engine with the same box.
std::unique_ptr<Reconstructor> one_shot(const SliceSet& set, const ReconstructorOptions& options) {
  auto r = std::make_unique<Reconstructor>(options);
  for (const LabeledSlice& s : set.slices) r->add_slice(s);
  r->update();
  return r;
}

void expect_same_field(const Reconstructor& online, const Reconstructor& offline) {
  const auto a = online.sampled_field();
  const auto b = offline.sampled_field();
  ASSERT_EQ(a.size(), b.size());
  double worst = 0.0;
  for (std::size_t n = 0; n < a.size(); ++n) {
    ASSERT_EQ(a[n].first, b[n].first) << "sampled vertices differ at row " << n;
    ASSERT_EQ(a[n].second.size(), b[n].second.size());
    for (std::size_t l = 0; l < a[n].second.size(); ++l)
      worst = std::max(worst, std::abs(a[n].second[l] - b[n].second[l]));
  }
  EXPECT_LE(worst, 1e-9);
  const MeshSet& ma = online.mesh();
  const MeshSet& mb = offline.mesh();
  ASSERT_EQ(ma.meshes.size(), mb.meshes.size());
  for (std::size_t m = 0; m < ma.meshes.size(); ++m) {
    EXPECT_EQ(ma.meshes[m].label, mb.meshes[m].label);
    ASSERT_EQ(ma.meshes[m].mesh.vertices.size(), mb.meshes[m].mesh.vertices.size());
    ASSERT_EQ(ma.meshes[m].mesh.triangles, mb.meshes[m].mesh.triangles);
    for (std::size_t v = 0; v < ma.meshes[m].mesh.vertices.size(); ++v)
      EXPECT_LE((ma.meshes[m].mesh.vertices[v] - mb.meshes[m].mesh.vertices[v]).norm(), 1e-9);
  }
}

struct Scenario {
  const char* name;
  bool two_labels;
  bool fov;
  int seed;
};

class RandomSequences : public ::testing::TestWithParam<Scenario> {};

TEST_P(RandomSequences, EqualTheOneShotReconstructionAfterEveryUpdate) {
  const Scenario scenario = GetParam();
  std::mt19937 rng(static_cast<unsigned>(scenario.seed));
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 5;
  options.engine.threads = 2;
  options.labels = {{1, "big"}, {2, "small"}};
  Reconstructor online(options);
  std::vector<int> ids;
  std::uniform_real_distribution<double> coin(0.0, 1.0);
  const int steps = scenario.fov ? 7 : 10;
  for (int step = 0; step < steps; ++step) {
    // Mostly one addition per update, sometimes two, sometimes a removal (undo).
    if (step > 2 && coin(rng) < 0.25 && !ids.empty()) {
      const std::size_t k =
          static_cast<std::size_t>(coin(rng) * static_cast<double>(ids.size())) % ids.size();
      EXPECT_TRUE(online.remove_slice(ids[k]));
      ids.erase(ids.begin() + static_cast<std::ptrdiff_t>(k));
    }
    const int additions = coin(rng) < 0.2 ? 2 : 1;
    for (int a = 0; a < additions; ++a)
      ids.push_back(online.add_slice(random_slice(rng, scenario.two_labels, scenario.fov)));
    const UpdateStats stats = online.update();
    EXPECT_EQ(online.slice_ids(), ids);
    if (step > 0 && stats.slices_removed == 0) {
      EXPECT_FALSE(stats.full_rebuild) << "step " << step;
    }
    // The evaluations' seconds are part of the field and smoothing stages, and there are some
    // whenever vertices were evaluated.
    EXPECT_EQ(stats.step.evaluation_s > 0.0, stats.step.field_evaluations > 0) << "step " << step;
    EXPECT_LE(stats.step.evaluation_s, stats.step.field_s + stats.step.smoothing_s)
        << "step " << step;
    const auto offline = one_shot(online.slice_set(), options);
    SCOPED_TRACE("step " + std::to_string(step));
    expect_same_field(online, *offline);
  }
}

INSTANTIATE_TEST_SUITE_P(Reconstructor, RandomSequences,
                         ::testing::Values(Scenario{"one_label", false, false, 11},
                                           Scenario{"two_labels", true, false, 12},
                                           Scenario{"sector_fov", true, true, 13}),
                         [](const auto& info) { return std::string(info.param.name); });

// `threads` bounds every stage (one arena), and the result does not depend on it: the parallel
// loops (the completion's rounds among them) write disjoint entries and sum in a fixed order.
TEST(Reconstructor, OneThreadGivesTheMeshesOfAllThreads) {
  std::mt19937 rng(31);
  SliceSet set;
  for (int n = 0; n < 6; ++n) set.slices.push_back(random_slice(rng, true, true));
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 5;
  options.labels = {{1, "big"}, {2, "small"}};
  options.engine.threads = 1;
  const auto one = one_shot(set, options);
  options.engine.threads = 0;
  const auto all = one_shot(set, options);
  ASSERT_EQ(one->mesh().meshes.size(), all->mesh().meshes.size());
  std::size_t triangles = 0;
  for (std::size_t m = 0; m < one->mesh().meshes.size(); ++m) {
    const TriangleMesh& a = one->mesh().meshes[m].mesh;
    const TriangleMesh& b = all->mesh().meshes[m].mesh;
    EXPECT_EQ(a.vertices, b.vertices) << "label " << one->mesh().meshes[m].label;
    EXPECT_EQ(a.triangles, b.triangles) << "label " << one->mesh().meshes[m].label;
    triangles += a.triangles.size();
  }
  EXPECT_GT(triangles, 100u);
}

// Regions thinner than the finest cells are snapped to grid vertices after the smoothing and the
// band is closed again from the snapped cells only; online and one-shot must still agree.
TEST(Reconstructor, ThinRegionsSnapAlikeOnlineAndOneShot) {
  std::mt19937 rng(21);
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 5;  // cells of 2.8 mm
  options.engine.threads = 2;
  options.labels = {{1, "big"}, {2, "strip"}};
  Reconstructor online(options);
  std::size_t snapped = 0;
  for (int step = 0; step < 6; ++step) {
    LabeledSlice slice = random_slice(rng, false, false);
    // A 1 mm wide strip, thinner than the cells, beside the sphere's disc (within 25 mm of the
    // plane's origin) and inside the box (the origin is within 24 mm of the centre).
    slice.regions.push_back({2, Ring2{Vec2(-8, 27), Vec2(8, 27), Vec2(8, 28), Vec2(-8, 28)}, {}});
    online.add_slice(slice);
    const UpdateStats stats = online.update();
    snapped = stats.step.snapped_vertices;
    SCOPED_TRACE("step " + std::to_string(step));
    expect_same_field(online, *one_shot(online.slice_set(), options));
  }
  EXPECT_GT(snapped, 0u);
}

TEST(Reconstructor, UpdatesOnlyTheZoneOfTheNewPlane) {
  std::mt19937 rng(5);
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 5;
  Reconstructor online(options);
  for (int k = 0; k < 12; ++k) online.add_slice(random_slice(rng, false, false));
  const UpdateStats first = online.update();
  EXPECT_TRUE(first.full_rebuild);
  online.add_slice(random_slice(rng, false, false));
  const UpdateStats next = online.update();
  EXPECT_FALSE(next.full_rebuild);
  EXPECT_EQ(next.slices_added, 1u);
  EXPECT_GT(next.cells_changed, 0u);
  EXPECT_LT(next.cells_changed, next.step.cells);
  EXPECT_LT(next.step.field_evaluations, first.step.field_evaluations / 2);
}

// A slice of a sweep: the plane z = height tilted a little about x, with the sector fov.
LabeledSlice sweep_slice(double height) {
  const double tilt = 0.05;
  LabeledSlice s;
  s.u = Vec3(1, 0, 0);
  s.v = Vec3(0, std::cos(tilt), std::sin(tilt));
  s.origin_mm = Vec3(0, 0, height);
  const double d = s.normal().normalized().dot(Vec3(-10, 0, 0) - s.origin_mm);
  s.regions.push_back({1,
                       circle(s.to_plane(Vec3(-10, 0, 0) - d * s.normal().normalized()),
                              std::sqrt(225.0 - d * d), 48),
                       {}});
  s.fov = sector_fan();
  return s;
}

TEST(Reconstructor, RecompletesOnlyTheSlicesNearTheNewPlane) {
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 5;
  Reconstructor online(options);
  for (int k = 0; k < 9; ++k) online.add_slice(sweep_slice(-12.0 + 3.0 * k));
  const UpdateStats first = online.update();
  EXPECT_EQ(first.step.completed_slices, 9u);
  // The next slice of the sweep splits the top slab: the slab's faces on the box are cut (their
  // images are rebuilt) and the new slice's face is added; slice 8's face is not cut and keeps
  // its image. Completion reads the faces of the cells within one group step of a face, so
  // slices 7 and 8 read the top slab's faces: they and the new slice complete again, the other
  // six do not.
  online.add_slice(sweep_slice(15.0));
  const UpdateStats next = online.update();
  EXPECT_FALSE(next.full_rebuild);
  EXPECT_EQ(next.step.completed_slices, 3u);
  SliceSet all = online.slice_set();
  expect_same_field(online, *one_shot(all, options));
}

TEST(Reconstructor, QueriesAndUndo) {
  std::mt19937 rng(8);
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 4;
  Reconstructor online(options);
  EXPECT_TRUE(online.mesh().meshes.empty());
  const int a = online.add_slice(random_slice(rng, false, false));
  const int b = online.add_slice(random_slice(rng, false, false));
  EXPECT_EQ(a, 0);
  EXPECT_EQ(b, 1);
  EXPECT_TRUE(online.remove_slice(b));  // a queued addition is simply dropped
  EXPECT_FALSE(online.remove_slice(b));
  EXPECT_FALSE(online.remove_slice(42));
  online.update();
  EXPECT_EQ(online.slice_ids(), std::vector<int>{a});
  EXPECT_EQ(online.slice_count(), 1u);
  const UpdateStats idle = online.update();  // nothing queued: nothing done
  EXPECT_EQ(idle.slices_added, 0u);
  EXPECT_EQ(idle.step.field_evaluations, 0u);
}

TEST(Reconstructor, CoincidentSlicesAreRefusedOrIgnored) {
  std::mt19937 rng(9);
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 4;
  Reconstructor online(options);
  const LabeledSlice slice = random_slice(rng, false, false);
  online.add_slice(slice);
  online.update();
  const auto before = online.sampled_field();
  online.add_slice(slice);  // identical: accepted, ignored by the reconstruction
  online.update();
  EXPECT_EQ(online.slice_count(), 2u);
  EXPECT_EQ(online.sampled_field().size(), before.size());
  LabeledSlice other = slice;
  other.regions.clear();
  EXPECT_THROW(online.add_slice(other), std::invalid_argument);
  LabeledSlice broken = slice;
  broken.origin_mm.x() += 5.0;
  broken.regions.push_back({1, Ring2{Vec2(0, 0), Vec2(1, 0)}, {}});  // a ring of two points
  EXPECT_THROW(online.add_slice(broken), std::invalid_argument);
  EXPECT_EQ(online.slice_count(), 2u);
}

TEST(Reconstructor, AMaterialSeenLaterRebuildsAndStillAgrees) {
  std::mt19937 rng(10);
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 4;
  Reconstructor online(options);  // no labels declared: they come with the slices
  LabeledSlice first = random_slice(rng, true, false);
  std::erase_if(first.regions, [](const Region& r) { return r.label == 2; });
  online.add_slice(first);
  online.update();
  EXPECT_EQ(online.mesh().meshes.size(), 1u);
  online.add_slice(random_slice(rng, true, false));
  online.add_slice(random_slice(rng, true, false));
  const UpdateStats stats = online.update();
  EXPECT_TRUE(stats.full_rebuild);
  EXPECT_EQ(online.mesh().meshes.size(), 2u);
  expect_same_field(online, *one_shot(online.slice_set(), options));
}

TEST(Reconstructor, AGrowingBoxRebuildsWhenNoneIsGiven) {
  std::mt19937 rng(12);
  ReconstructorOptions options;
  options.engine.max_depth = 4;
  Reconstructor online(options);
  online.add_slice(random_slice(rng, false, false));
  online.update();
  const Box3 first = *online.slice_set().bounds;
  bool grew = false;
  for (int k = 0; k < 10 && !grew; ++k) {
    online.add_slice(random_slice(rng, false, false));
    const UpdateStats stats = online.update();
    const Box3 now = *online.slice_set().bounds;
    grew = now.min != first.min || now.max != first.max;
    EXPECT_EQ(stats.full_rebuild, grew);
  }
  EXPECT_TRUE(grew);
  const SliceSet set = online.slice_set();
  ReconstructorOptions fixed = options;
  fixed.bounds = set.bounds;
  expect_same_field(online, *one_shot(set, fixed));
}

}  // namespace
}  // namespace sonoshape::recon::reconstructor_test
