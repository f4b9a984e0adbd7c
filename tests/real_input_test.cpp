// Real-world conventions and faults of public cross-section datasets, each reproduced on a small
// file of tests/data/real_input (written by make_corpus.py there) and checked on the SURFACE that
// reconstruction makes of it: its topology (components, genus) and its volume against the shape
// the file means.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <numeric>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/mesh_components.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/recon/reconstruct.hpp"

namespace sonoshape::real_input_test {
namespace {

const std::filesystem::path kCorpus =
    std::filesystem::path(SONOSHAPE_SOURCE_DIR) / "tests" / "data" / "real_input";
constexpr double kPi = std::numbers::pi;
constexpr int kDepth = 6;

// The stacks of make_corpus.py: planes z = 0, 4, ..., 20 closed by empty planes at -2 and 22.
const std::vector<double> kZs = {0, 4, 8, 12, 16, 20};
const std::vector<double> kCaps = {-2, 22};

SliceSet read(const std::string& name, std::vector<Repair>* repairs = nullptr) {
  ::testing::internal::CaptureStderr();
  Result<SliceSet> set = read_slice_set(kCorpus / name);
  ::testing::internal::GetCapturedStderr();
  EXPECT_TRUE(set.is_ok()) << set.message();
  if (!set.is_ok()) return {};
  if (repairs) *repairs = set->repairs;
  return *set;
}

MeshSet reconstruct(const SliceSet& set) {
  recon::ReconstructionOptions options;
  options.max_depth = kDepth;
  return recon::reconstruct(set, options);
}

const TriangleMesh& mesh_of(const MeshSet& meshes, int label) {
  static const TriangleMesh empty;
  for (const MeshSet::Entry& e : meshes.meshes)
    if (e.label == label) return e.mesh;
  ADD_FAILURE() << "no mesh for label " << label;
  return empty;
}

// Connected components of a closed mesh and the genus of each (from its Euler characteristic).
struct Topology {
  std::vector<int> genus;  // one per component, sorted
};

Topology topology(const TriangleMesh& mesh) {
  const MeshParts parts = mesh_parts(mesh);
  struct Counts {
    std::set<std::uint32_t> vertices;
    std::set<std::pair<std::uint32_t, std::uint32_t>> edges;
    long faces = 0;
  };
  std::vector<Counts> components(parts.count);
  for (std::size_t n = 0; n < mesh.triangles.size(); ++n) {
    const auto& t = mesh.triangles[n];
    Counts& c = components[parts.part_of_triangle[n]];
    ++c.faces;
    for (int k = 0; k < 3; ++k) {
      c.vertices.insert(t[k]);
      const std::uint32_t a = t[k], b = t[(k + 1) % 3];
      c.edges.insert({std::min(a, b), std::max(a, b)});
    }
  }
  Topology out;
  for (const Counts& c : components) {
    const long euler =
        static_cast<long>(c.vertices.size()) - static_cast<long>(c.edges.size()) + c.faces;
    out.genus.push_back(static_cast<int>((2 - euler) / 2));
  }
  std::sort(out.genus.begin(), out.genus.end());
  return out;
}

// A closed, manifold, oriented mesh with the given genus per component.
void expect_surface(const TriangleMesh& mesh, const std::vector<int>& genus) {
  ASSERT_FALSE(mesh.empty());
  const MeshHealth health = check_mesh_health(mesh);
  EXPECT_TRUE(health.closed_manifold_oriented())
      << health.boundary_edges << " boundary, " << health.non_manifold_edges
      << " non-manifold edges, " << health.misoriented_edges << " misoriented";
  EXPECT_EQ(topology(mesh).genus, genus);
}

// A disc of radius r on every plane of the stacks, as a clean set built in code: its
// reconstruction measures how far the surface reaches past the first and last planes, so that
// the volume of a shape of cross-section area A is A times this length.
double effective_length() {
  static const double length = [] {
    SliceSet set;
    const double r = 10.0;
    Ring2 disc;
    for (int k = 0; k < 64; ++k)
      disc.emplace_back(r * std::cos(2 * kPi * k / 64), r * std::sin(2 * kPi * k / 64));
    for (double z : kCaps) {
      LabeledSlice s;
      s.origin_mm = Vec3(0, 0, z);
      set.slices.push_back(s);
    }
    for (double z : kZs) {
      LabeledSlice s;
      s.origin_mm = Vec3(0, 0, z);
      s.regions.push_back({1, disc, {}});
      set.slices.push_back(s);
    }
    return signed_volume(mesh_of(reconstruct(set), 1)) / std::abs(signed_area(disc));
  }();
  return length;
}

void expect_volume(const TriangleMesh& mesh, double cross_section_area, double tolerance) {
  const double expected = cross_section_area * effective_length();
  EXPECT_NEAR(signed_volume(mesh) / expected, 1.0, tolerance)
      << "volume " << signed_volume(mesh) << ", expected " << expected;
}

std::size_t count_kind(const std::vector<Repair>& repairs, const std::string& kind) {
  return static_cast<std::size_t>(std::count_if(repairs.begin(), repairs.end(),
                                                [&](const Repair& r) { return r.kind == kind; }));
}

TEST(RealInput, EffectiveLengthOfTheStacksIsBetweenTheirPlanesAndCaps) {
  EXPECT_GT(effective_length(), 20.0);
  EXPECT_LT(effective_length(), 24.0);
}

TEST(RealInput, HoleLabelsOfTheThreeConventionsMakeTheSameTube) {
  // A hole labelled with its parent's label (Vertebrae), 0, or nLabels (hand, Elephant): all
  // the outside, so each file is a tube of radii 10 and 4: one component of genus 1.
  double first_volume = 0.0;
  for (const char* name :
       {"hole_label_parent.csl", "hole_label_zero.csl", "hole_label_nlabels.csl"}) {
    SCOPED_TRACE(name);
    std::vector<Repair> repairs;
    const SliceSet set = read(name, &repairs);
    EXPECT_TRUE(repairs.empty());
    const MeshSet meshes = reconstruct(set);
    ASSERT_EQ(meshes.meshes.size(), 1u);
    expect_surface(meshes.meshes[0].mesh, {1});
    expect_volume(meshes.meshes[0].mesh, kPi * (100 - 16), 0.05);
    const double volume = signed_volume(meshes.meshes[0].mesh);
    if (first_volume == 0.0) first_volume = volume;
    EXPECT_NEAR(volume, first_volume, 1e-9 * first_volume);
  }
}

TEST(RealInput, HoleFilledByAnotherMaterialMakesATubeAroundACylinder) {
  const SliceSet set = read("hole_filled_by_material.csl");
  EXPECT_EQ(set.material_ids(), (std::vector<int>{1, 2}));
  const MeshSet meshes = reconstruct(set);
  ASSERT_EQ(meshes.meshes.size(), 2u);
  expect_surface(mesh_of(meshes, 1), {1});
  expect_surface(mesh_of(meshes, 2), {0});
  expect_volume(mesh_of(meshes, 1), kPi * (100 - 16), 0.05);
  expect_volume(mesh_of(meshes, 2), kPi * 16, 0.08);
}

TEST(RealInput, NestedMaterialsWithUnusedDeclaredLabelsMakeOneMeshPerMaterialThatOccurs) {
  // nLabels = 20 with materials 1-3: a tube of 1, in its hole a tube of 2, in that a rod of 3.
  const SliceSet set = read("nested_materials.csl");
  EXPECT_EQ(set.material_ids(), (std::vector<int>{1, 2, 3}));
  const MeshSet meshes = reconstruct(set);
  ASSERT_EQ(meshes.meshes.size(), 3u);
  expect_surface(mesh_of(meshes, 1), {1});
  expect_surface(mesh_of(meshes, 2), {1});
  expect_surface(mesh_of(meshes, 3), {0});
  expect_volume(mesh_of(meshes, 1), kPi * (100 - 36), 0.05);
  expect_volume(mesh_of(meshes, 2), kPi * (25 - 6.25), 0.15);  // 2.5 mm thick: 5 cells
  expect_volume(mesh_of(meshes, 3), kPi * 1.8 * 1.8, 0.2);
}

// make_corpus.py's figure-8 (Bernoulli's lemniscate of half-width 10, 64 points) written
// cleanly: its two lobes as two contours that meet at the crossing, the origin.
SliceSet two_lobes() {
  const int n = 64;
  Ring2 right{Vec2(0, 0)};
  Ring2 left{Vec2(0, 0)};
  for (int j = 0; j < n; ++j) {
    const int k = (3 * n / 4 + j) % n;  // from just after t = 3 pi / 2: the right lobe first
    const double t = 2 * kPi * (k + 0.5) / n;
    const double d = 1 + std::sin(t) * std::sin(t);
    const Vec2 p(10 * std::cos(t) / d, 10 * std::sin(t) * std::cos(t) / d);
    (p.x() > 0 ? right : left).push_back(p);
  }
  SliceSet set;
  for (double z : kCaps) {
    LabeledSlice s;
    s.origin_mm = Vec3(0, 0, z);
    set.slices.push_back(s);
  }
  for (double z : kZs) {
    LabeledSlice s;
    s.origin_mm = Vec3(0, 0, z);
    s.regions = {{1, right, {}}, {1, left, {}}};
    set.slices.push_back(s);
  }
  return set;
}

TEST(RealInput, FigureEightMakesTheSurfaceOfItsTwoLobes) {
  // The lemniscate crosses itself at the origin; its lobes enclose 100 mm² together and have
  // opposite orientations, so even-odd and non-zero agree on it. Its surface is the one the two
  // lobes written as separate contours make (the lobes touch along the z axis, which the
  // reconstruction resolves the same way for both).
  const MeshSet clean = reconstruct(two_lobes());
  ASSERT_EQ(clean.meshes.size(), 1u);
  const TriangleMesh& clean_mesh = clean.meshes[0].mesh;
  for (const char* name : {"figure_eight.csl", "figure_eight.slices.json"}) {
    SCOPED_TRACE(name);
    std::vector<Repair> repairs;
    const SliceSet set = read(name, &repairs);
    EXPECT_EQ(count_kind(repairs, "self_intersection"), kZs.size());
    for (const Repair& r : repairs) EXPECT_NEAR(r.area_changed_mm2, 0.0, 1e-9);
    for (const LabeledSlice& s : set.slices)
      EXPECT_TRUE(s.regions.empty() || s.regions.size() == 2u);
    const MeshSet meshes = reconstruct(set);
    ASSERT_EQ(meshes.meshes.size(), 1u);
    const TriangleMesh& mesh = meshes.meshes[0].mesh;
    ASSERT_FALSE(mesh.empty());
    EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
    EXPECT_EQ(topology(mesh).genus, topology(clean_mesh).genus);
    EXPECT_NEAR(signed_volume(mesh) / signed_volume(clean_mesh), 1.0, 0.01);
    expect_volume(mesh, 100.0, 0.15);  // thin near the crossing, where the sampling loses some
  }
}

TEST(RealInput, PinchedRingBecomesTwoDiscs) {
  // Two circles of radius 5 traced as one contour through their common point.
  std::vector<Repair> repairs;
  const SliceSet set = read("pinched_ring.csl", &repairs);
  EXPECT_EQ(count_kind(repairs, "self_intersection"), kZs.size());
  const MeshSet meshes = reconstruct(set);
  ASSERT_EQ(meshes.meshes.size(), 1u);
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  ASSERT_FALSE(mesh.empty());
  EXPECT_TRUE(check_mesh_health(mesh).closed_manifold_oriented());
  for (int genus : topology(mesh).genus) EXPECT_EQ(genus, 0);
  const double polygon_area = 2 * 32 * 0.5 * 25 * std::sin(2 * kPi / 32);  // two 32-gons
  expect_volume(mesh, polygon_area, 0.08);
}

TEST(RealInput, SmallLoopIsFilledNotPunchedOut) {
  // The contour curls once around a 2 x 2.6 patch inside the disc. Non-zero fills it; even-odd
  // would have made a hole in every plane, a tunnel through the cylinder (genus 1).
  std::vector<Repair> repairs;
  const SliceSet set = read("small_loop.csl", &repairs);
  ASSERT_EQ(count_kind(repairs, "self_intersection"), kZs.size());
  for (const Repair& r : repairs) EXPECT_NEAR(r.area_changed_mm2, 2.0 * 2.6, 1e-6);
  const MeshSet meshes = reconstruct(set);
  ASSERT_EQ(meshes.meshes.size(), 1u);
  expect_surface(meshes.meshes[0].mesh, {0});
  expect_volume(meshes.meshes[0].mesh, 32 * 0.5 * 100 * std::sin(2 * kPi / 32), 0.05);
}

TEST(RealInput, SpikeIsCutOff) {
  std::vector<Repair> repairs;
  const SliceSet set = read("spike.csl", &repairs);
  EXPECT_EQ(count_kind(repairs, "self_intersection"), kZs.size());
  const MeshSet meshes = reconstruct(set);
  ASSERT_EQ(meshes.meshes.size(), 1u);
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  expect_surface(mesh, {0});
  expect_volume(mesh, 32 * 0.5 * 100 * std::sin(2 * kPi / 32), 0.05);
  for (const Vec3& p : mesh.vertices) EXPECT_LT(std::hypot(p.x(), p.y()), 11.0);
}

TEST(RealInput, FlippedPlaneEquationsAreFittedToTheirVertices) {
  std::vector<Repair> repairs;
  const SliceSet set = read("flipped_d.csl", &repairs);
  ASSERT_EQ(repairs.size(), 1u);
  EXPECT_EQ(repairs[0].kind, "plane_refit");
  const MeshSet meshes = reconstruct(set);
  ASSERT_EQ(meshes.meshes.size(), 1u);
  const TriangleMesh& mesh = meshes.meshes[0].mesh;
  expect_surface(mesh, {0});
  expect_volume(mesh, 32 * 0.5 * 100 * std::sin(2 * kPi / 32), 0.05);
  const Box3 box = mesh.bounds();
  EXPECT_GT(box.min.z(), -2.0);  // between the caps, where the vertices are
  EXPECT_LT(box.max.z(), 22.0);
  EXPECT_LT(box.min.z(), 0.0);
  EXPECT_GT(box.max.z(), 20.0);
}

TEST(RealInput, OffPlaneNoiseIsProjected) {
  std::vector<Repair> repairs;
  const SliceSet set = read("off_plane_noise.csl", &repairs);
  EXPECT_EQ(count_kind(repairs, "off_plane_vertices"), kZs.size());
  EXPECT_EQ(count_kind(repairs, "plane_refit"), 0u);
  const MeshSet meshes = reconstruct(set);
  ASSERT_EQ(meshes.meshes.size(), 1u);
  expect_surface(meshes.meshes[0].mesh, {0});
  expect_volume(meshes.meshes[0].mesh, 32 * 0.5 * 100 * std::sin(2 * kPi / 32), 0.05);
}

}  // namespace
}  // namespace sonoshape::real_input_test
