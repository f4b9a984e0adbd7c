// Cells built on demand (issue 24) against the whole arrangement: every cell a point reaches is
// the whole arrangement's cell there (same planes, same exact vertices, closed), and the engine's
// field and meshes are those of the whole arrangement on random, sweep and unknown-region sets.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_scheduler_observer.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "arrangement.hpp"
#include "sonoshape/recon/reconstruct.hpp"
#include "sonoshape/recon/reconstructor.hpp"
#include "test_shapes.hpp"

namespace sonoshape::recon::on_demand_test {
namespace {

// ---------------------------------------------------------------------------------------------
// The arrangement

const Box3 kUnitBox{Vec3(-1.0, -2.0, -1.5), Vec3(2.0, 1.0, 1.5)};

// A cell as (plane, side of the plane the cell is on) -> the face's vertices, sorted. Vertices
// are the doubles rounded from exact points: the same exact point gives the same double.
using CellShape = std::map<std::pair<int, int>, std::vector<std::array<double, 3>>>;

CellShape shape_of(const Arrangement& arr, int cell) {
  CellShape shape;
  for (const int f : arr.cell(cell).faces) {
    const ArrangementFace& face = arr.face(f);
    std::vector<std::array<double, 3>> vertices;
    for (const int v : face.vertices)
      vertices.push_back({arr.vertex(v).x(), arr.vertex(v).y(), arr.vertex(v).z()});
    std::sort(vertices.begin(), vertices.end());
    const auto [it, inserted] =
        shape.emplace(std::make_pair(face.plane, face.cell_positive == cell ? 1 : -1), vertices);
    EXPECT_TRUE(inserted) << "two faces of cell " << cell << " on plane " << face.plane;
  }
  return shape;
}

// A built cell is a closed polyhedron: oriented outwards, its faces use each edge once in each
// direction, and its vertices lie exactly on their planes. Regions do not share vertices, so a
// face shared with a neighbour may name a point by another id: edges are compared by the first
// id of the cell with the same exact point.
void expect_closed(const Arrangement& arr, int cell) {
  std::vector<int> ids;
  auto representative = [&](int v) {
    for (const int w : ids)
      if (arr.exact_vertex(w) == arr.exact_vertex(v)) return w;
    ids.push_back(v);
    return v;
  };
  std::map<std::pair<int, int>, int> edges;
  for (const int f : arr.cell(cell).faces) {
    const ArrangementFace& face = arr.face(f);
    ASSERT_TRUE(face.cell_positive == cell || face.cell_negative == cell);
    const std::size_t n = face.vertices.size();
    ASSERT_GE(n, 3u);
    for (std::size_t i = 0; i < n; ++i) {
      int a = face.vertices[i], b = face.vertices[(i + 1) % n];
      EXPECT_EQ(arr.side(face.plane, a), 0);
      EXPECT_EQ(arr.side(face.edge_planes[i], a), 0);
      EXPECT_EQ(arr.side(face.edge_planes[i], b), 0);
      a = representative(a);
      b = representative(b);
      if (face.cell_positive == cell) std::swap(a, b);
      ++edges[{a, b}];
    }
  }
  for (const auto& [edge, count] : edges) {
    EXPECT_EQ(count, 1) << "cell " << cell;
    EXPECT_TRUE(edges.count({edge.second, edge.first})) << "cell " << cell << " is not closed";
  }
}

struct Plane {
  Vec3 normal;
  double offset;
};

// Inserts `planes` into a whole and an on-demand arrangement, then compares the cells of
// `points`: a point clear of every plane must get the same cell; a point on planes a cell whose
// closure holds it. With `built_after` > 0 the on-demand arrangement first builds the cells of
// every point after that many planes (as the online engine does before its next plane): the
// later planes reopen the built cells they cross, and only those.
void expect_same_cells(const std::vector<Plane>& planes, const std::vector<Vec3>& points,
                       std::size_t built_after = 0) {
  Arrangement whole(kUnitBox);
  Arrangement lazy(kUnitBox, true);
  ASSERT_TRUE(lazy.on_demand());
  std::size_t reopened = 0;
  for (std::size_t i = 0; i < planes.size(); ++i) {
    if (i == built_after && built_after > 0)
      for (const Vec3& p : points) lazy.construct_cell(p);
    const std::size_t built = lazy.built_cell_count();
    std::vector<bool> was_reopened(lazy.cell_count());
    for (std::size_t c = 0; c < lazy.cell_count(); ++c)
      was_reopened[c] = lazy.reopened(static_cast<int>(c));
    whole.insert_plane(planes[i].normal, planes[i].offset, static_cast<int>(i));
    const std::vector<int> cells =
        lazy.insert_plane(planes[i].normal, planes[i].offset, static_cast<int>(i));
    if (i < built_after || built_after == 0) {
      EXPECT_TRUE(cells.empty());
    }
    // Exactly the built cells with vertices strictly on both sides of the plane are reopened.
    EXPECT_EQ(lazy.built_cell_count(), built - cells.size());
    for (const int c : cells) {
      EXPECT_FALSE(was_reopened[static_cast<std::size_t>(c)]);
      EXPECT_TRUE(lazy.reopened(c));
    }
    reopened += cells.size();
  }
  if (built_after > 0) {
    EXPECT_GT(reopened, 0u);
  } else {
    EXPECT_EQ(lazy.cell_count(), 0u);
  }
  int compared = 0;
  for (const Vec3& p : points) {
    const int c = lazy.construct_cell(p);
    ASSERT_FALSE(lazy.reopened(c));
    EXPECT_EQ(lazy.construct_cell(p), c) << "a second query must find the built cell";
    // In a batch, a point takes the cell of the one before when it lies inside it clear of its
    // faces' planes (points on planes take the walk): the same cell either way.
    EXPECT_EQ(lazy.construct_cells({p, p, p}, {1, 1, 1}), std::vector<int>(3, c));
    expect_closed(lazy, c);
    bool clear = true;
    for (std::size_t i = 0; i < planes.size(); ++i)
      clear &=
          std::abs(planes[i].normal.dot(p) + planes[i].offset) > 1e-9 * planes[i].normal.norm();
    if (clear) {
      EXPECT_EQ(shape_of(lazy, c), shape_of(whole, whole.locate(p))) << "at " << p.transpose();
      ++compared;
    } else {
      for (const int f : lazy.cell(c).faces) {
        const ArrangementFace& face = lazy.face(f);
        const double s = lazy.plane(face.plane).signed_distance(p);
        EXPECT_GE(face.cell_positive == c ? s : -s, -1e-12) << "at " << p.transpose();
      }
    }
  }
  EXPECT_GT(compared, 0);
  EXPECT_LE(lazy.built_cell_count(), whole.cell_count());
}

std::vector<Vec3> random_points(std::mt19937_64& rng, int count) {
  std::uniform_real_distribution<double> inside(0.0, 1.0);
  std::vector<Vec3> points;
  for (int k = 0; k < count; ++k)
    points.push_back(
        kUnitBox.min +
        (kUnitBox.max - kUnitBox.min).cwiseProduct(Vec3(inside(rng), inside(rng), inside(rng))));
  return points;
}

// `count` planes of random normals through random points of the inner 80 % of the unit box.
std::vector<Plane> random_planes(std::mt19937_64& rng, int count) {
  std::normal_distribution<double> gauss;
  std::uniform_real_distribution<double> uniform(-0.8, 0.8);
  std::vector<Plane> planes;
  for (int i = 0; i < count; ++i) {
    const Vec3 n(gauss(rng), gauss(rng), gauss(rng));
    const Vec3 p(uniform(rng), uniform(rng), uniform(rng));
    planes.push_back({n, -n.dot(p)});
  }
  return planes;
}

TEST(OnDemandArrangement, RandomPlanesGiveTheWholeArrangementsCells) {
  std::mt19937_64 rng(7);
  const std::vector<Plane> planes = random_planes(rng, 14);
  expect_same_cells(planes, random_points(rng, 400));
}

// construct_cells refines the regions a batch of points reaches in parallel: the cells, faces
// and vertices, ids included, are the same for any number of threads, and each point's cell is
// the one construct_cell builds for it alone (and so the whole arrangement's).
TEST(OnDemandArrangement, BatchesGiveTheSameCellsForAnyThreadCount) {
  // TBB allows as many workers as cores by default: let 16 threads run on a smaller machine.
  const tbb::global_control workers(tbb::global_control::max_allowed_parallelism, 16);
  std::mt19937_64 rng(11);
  const std::vector<Plane> planes = random_planes(rng, 24);
  // Three batches, the later ones partly in cells built before; every seventh point not wanted.
  std::vector<std::vector<Vec3>> batches;
  for (int b = 0; b < 3; ++b) batches.push_back(random_points(rng, 500));
  batches[2].insert(batches[2].end(), batches[0].begin(), batches[0].begin() + 100);
  auto wanted = [](const std::vector<Vec3>& batch) {
    std::vector<char> w(batch.size(), 1);
    for (std::size_t n = 0; n < w.size(); n += 7) w[n] = 0;
    return w;
  };
  // Passes of 5 jobs (one-thread only) must give the ids of one pass.
  const std::vector<int> thread_counts{1, 2, 4, 16, 1};
  std::vector<std::unique_ptr<Arrangement>> arrangements;
  std::vector<std::vector<std::vector<int>>> cells(thread_counts.size());
  for (std::size_t t = 0; t < thread_counts.size(); ++t) {
    arrangements.push_back(std::make_unique<Arrangement>(kUnitBox, true));
    Arrangement& arr = *arrangements.back();
    for (std::size_t i = 0; i < planes.size(); ++i)
      arr.insert_plane(planes[i].normal, planes[i].offset, static_cast<int>(i));
    tbb::task_arena arena(thread_counts[t]);
    for (const std::vector<Vec3>& batch : batches)
      arena.execute([&] {
        const std::size_t passes = t + 1 == thread_counts.size() ? 5 : Arrangement::kJobsPerPass;
        cells[t].push_back(arr.construct_cells(batch, wanted(batch), passes));
      });
  }
  const Arrangement& one = *arrangements.front();
  for (std::size_t t = 1; t < thread_counts.size(); ++t) {
    SCOPED_TRACE(std::to_string(thread_counts[t]) + " threads" +
                 (t + 1 == thread_counts.size() ? ", passes of 5 jobs" : ""));
    const Arrangement& arr = *arrangements[t];
    EXPECT_EQ(cells[t], cells[0]);
    ASSERT_EQ(arr.cell_count(), one.cell_count());
    ASSERT_EQ(arr.face_count(), one.face_count());
    ASSERT_EQ(arr.vertex_count(), one.vertex_count());
    ASSERT_EQ(arr.region_count(), one.region_count());
    for (std::size_t c = 0; c < one.cell_count(); ++c)
      EXPECT_EQ(arr.cell(static_cast<int>(c)).faces, one.cell(static_cast<int>(c)).faces);
    for (std::size_t f = 0; f < one.face_count(); ++f) {
      const ArrangementFace& a = arr.face(static_cast<int>(f));
      const ArrangementFace& b = one.face(static_cast<int>(f));
      EXPECT_EQ(a.plane, b.plane);
      EXPECT_EQ(a.vertices, b.vertices);
      EXPECT_EQ(a.edge_planes, b.edge_planes);
      EXPECT_EQ(a.cell_positive, b.cell_positive);
      EXPECT_EQ(a.cell_negative, b.cell_negative);
    }
    for (std::size_t v = 0; v < one.vertex_count(); ++v)
      EXPECT_EQ(arr.vertex(static_cast<int>(v)), one.vertex(static_cast<int>(v)));
  }
  // One point at a time: the same cell for each point.
  Arrangement single(kUnitBox, true);
  for (std::size_t i = 0; i < planes.size(); ++i)
    single.insert_plane(planes[i].normal, planes[i].offset, static_cast<int>(i));
  for (std::size_t b = 0; b < batches.size(); ++b) {
    const std::vector<char> w = wanted(batches[b]);
    for (std::size_t n = 0; n < batches[b].size(); ++n) {
      if (!w[n]) {
        EXPECT_EQ(cells[0][b][n], -1);
        continue;
      }
      const int c = cells[0][b][n];
      ASSERT_GE(c, 0);
      EXPECT_FALSE(one.reopened(c));
      expect_closed(one, c);
      EXPECT_EQ(shape_of(one, c), shape_of(single, single.construct_cell(batches[b][n])))
          << "at " << batches[b][n].transpose();
    }
  }
  EXPECT_EQ(one.built_cell_count(), single.built_cell_count());
}

TEST(OnDemandArrangement, PlanesAfterBuiltCellsReopenOnlyTheCellsTheyCross) {
  // The online engine: cells built after some planes, then more planes (which reopen the built
  // cells they cross), then the cells of the points again: those of the whole arrangement.
  std::mt19937_64 rng(8);
  std::normal_distribution<double> gauss;
  std::uniform_real_distribution<double> uniform(-0.8, 0.8);
  std::vector<Plane> planes;
  for (int i = 0; i < 16; ++i) {
    const Vec3 n(gauss(rng), gauss(rng), gauss(rng));
    const Vec3 p(uniform(rng), uniform(rng), uniform(rng));
    planes.push_back({n, -n.dot(p)});
  }
  const std::vector<Vec3> points = random_points(rng, 400);
  for (const std::size_t after : {1u, 5u, 11u}) {
    SCOPED_TRACE("cells built after " + std::to_string(after) + " planes");
    expect_same_cells(planes, points, after);
  }
}

TEST(OnDemandArrangement, DegeneratePlanesGiveTheWholeArrangementsCells) {
  // Three planes through a line, more through a point, planes through vertices and edges of the
  // box and of each other, nearly parallel planes, and a sweep (a deep tree); then points on
  // planes, on their lines and at their crossings as well as random ones.
  std::vector<Plane> planes{{Vec3(1, 0, 0), 0.0},
                            {Vec3(0, 1, 0), 0.0},
                            {Vec3(1, 1, 0), 0.0},
                            {Vec3(0, 0, 1), 0.0},
                            {Vec3(1, -1, 1), 0.0},
                            {Vec3(1, -1, 0), 0.0},
                            {Vec3(1, -2, 0), 0.0},
                            {Vec3(0, 0, 1), -0.1},
                            {Vec3(1e-9, 1e-9, 1), -0.1 + 1e-12},
                            {Vec3(0, 1e-15, 1), -0.1 - 1e-15}};
  for (const double x : {-0.5, 0.5}) planes.push_back({Vec3(1, 0, 0), -x});
  for (int i = 0; i < 8; ++i) planes.push_back({Vec3(0.01 * i, 0.02, 1), -(-1.2 + 0.3 * i)});
  std::mt19937_64 rng(11);
  std::vector<Vec3> points = random_points(rng, 400);
  for (const double x : {-0.5, 0.0, 0.5, 0.25})
    for (const double y : {-1.0, 0.0, -0.5})
      for (const double z : {-1.2, -0.1, 0.0, 0.3, 0.7}) points.emplace_back(x, y, z);
  expect_same_cells(planes, points);
  // The same planes inserted after cells were built: vertices of four planes, planes through
  // built vertices and edges, and faces shared by cells built from different regions.
  for (const std::size_t after : {3u, 9u, 14u}) {
    SCOPED_TRACE("cells built after " + std::to_string(after) + " planes");
    expect_same_cells(planes, points, after);
  }
}

TEST(OnDemandArrangement, BuildsOnlyTheCellsItIsAskedFor) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> gauss;
  std::uniform_real_distribution<double> uniform(-0.8, 0.8);
  Arrangement whole(kUnitBox), lazy(kUnitBox, true);
  for (int i = 0; i < 30; ++i) {
    const Vec3 n(gauss(rng), gauss(rng), gauss(rng));
    const Vec3 p(uniform(rng), uniform(rng), uniform(rng));
    whole.insert_plane(n, -n.dot(p), i);
    lazy.insert_plane(n, -n.dot(p), i);
  }
  // Points along a short segment reach a few cells of the thousands.
  for (int k = 0; k <= 50; ++k) lazy.construct_cell(Vec3(0.1 + 0.004 * k, -0.3, 0.2));
  EXPECT_GT(whole.cell_count(), 2000u);
  EXPECT_LT(lazy.cell_count(), 40u);
  EXPECT_LT(lazy.region_count(), 40u * 30u);
  // A later plane reopens only the built cells it crosses: the plane x = 0.2 crosses those in the
  // middle of the segment (x from 0.1 to 0.3), the plane x = 0.9 none.
  const std::size_t built = lazy.built_cell_count();
  EXPECT_TRUE(lazy.insert_plane(Vec3(1, 0, 0), -0.9, 30).empty());
  const std::vector<int> reopened = lazy.insert_plane(Vec3(1, 0, 0), -0.2, 31);
  EXPECT_GT(reopened.size(), 0u);
  EXPECT_LT(reopened.size(), built);
  EXPECT_EQ(lazy.built_cell_count(), built - reopened.size());
}

// ---------------------------------------------------------------------------------------------
// The engine

constexpr double kRadius = 30.0;
const Box3 kBox{Vec3::Constant(-45.0), Vec3::Constant(45.0)};

using test::circle;

// The sections of a sphere (label 1) and a smaller one (label 2) by the plane (origin, u, v),
// circles of `segments` edges.
LabeledSlice spheres_slice(const Vec3& origin, const Vec3& u, const Vec3& v, int segments = 48) {
  LabeledSlice s;
  s.u = u;
  s.v = v;
  s.origin_mm = origin;
  const Vec3 n = u.cross(v);
  auto add_sphere = [&](const Vec3& centre, double radius, int label) {
    const double d = n.dot(centre - s.origin_mm);
    if (std::abs(d) >= 0.95 * radius) return;
    s.regions.push_back(
        {label,
         circle(s.to_plane(centre - d * n), std::sqrt(radius * radius - d * d), segments),
         {}});
  };
  add_sphere(Vec3(-10, 0, 0), 0.5 * kRadius, 1);
  add_sphere(Vec3(16, 4, 2), 0.3 * kRadius, 2);
  return s;
}

SliceSet random_set(unsigned seed, int count, int segments = 48) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-0.8, 0.8);
  SliceSet set;
  while (static_cast<int>(set.slices.size()) < count) {
    const Vec3 n = Vec3(normal(rng), normal(rng), normal(rng)).normalized();
    const Vec3 u = n.unitOrthogonal();
    LabeledSlice s = spheres_slice(n * (uniform(rng) * kRadius), u, n.cross(u), segments);
    if (!s.regions.empty()) set.slices.push_back(std::move(s));
  }
  return set;
}

// A freehand-like sweep: planes z = h, h rising, tilted about x by a growing angle and rocked
// about y, so that neighbours meet inside the box as a hand-held probe's do.
SliceSet sweep_set(int count) {
  SliceSet set;
  for (int k = 0; k < count; ++k) {
    const double tilt = -0.4 + 0.8 * k / (count - 1), rock = 0.3 * std::sin(1.3 * k);
    const Vec3 u = Vec3(std::cos(rock), 0, std::sin(rock));
    const Vec3 v = (Vec3(0, std::cos(tilt), std::sin(tilt)) - std::sin(rock) * std::sin(tilt) * u)
                       .normalized();
    set.slices.push_back(spheres_slice(Vec3(0, 0, -10.0 + 20.0 * k / (count - 1)), u, v));
  }
  return set;
}

std::unique_ptr<Reconstructor> reconstruct_with(const SliceSet& set, bool on_demand,
                                                ReconstructionStats* stats, int threads = 2) {
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 5;
  options.engine.threads = threads;
  options.labels = {{1, "big"}, {2, "small"}};
  options.engine.cells_on_demand = on_demand;
  auto r = std::make_unique<Reconstructor>(options);
  for (const LabeledSlice& s : set.slices) r->add_slice(s);
  const UpdateStats update = r->update();
  if (stats) *stats = update.step;
  return r;
}

// The field at every sampled vertex within 1e-9 and the same meshes (triangles and vertices).
// `fewer`: the on-demand engine builds fewer cells than the whole arrangement has.
void expect_same_reconstruction(const SliceSet& set, bool fewer) {
  ReconstructionStats whole_stats, lazy_stats;
  const auto whole = reconstruct_with(set, false, &whole_stats);
  const auto lazy = reconstruct_with(set, true, &lazy_stats);
  const auto a = whole->sampled_field();
  const auto b = lazy->sampled_field();
  ASSERT_EQ(a.size(), b.size());
  double worst = 0.0;
  for (std::size_t n = 0; n < a.size(); ++n) {
    ASSERT_EQ(a[n].first, b[n].first) << "sampled vertices differ at row " << n;
    for (std::size_t l = 0; l < a[n].second.size(); ++l)
      worst = std::max(worst, std::abs(a[n].second[l] - b[n].second[l]));
  }
  EXPECT_LE(worst, 1e-9);
  const MeshSet& ma = whole->mesh();
  const MeshSet& mb = lazy->mesh();
  ASSERT_EQ(ma.meshes.size(), mb.meshes.size());
  std::size_t triangles = 0;
  for (std::size_t m = 0; m < ma.meshes.size(); ++m) {
    ASSERT_EQ(ma.meshes[m].mesh.vertices.size(), mb.meshes[m].mesh.vertices.size());
    ASSERT_EQ(ma.meshes[m].mesh.triangles, mb.meshes[m].mesh.triangles);
    for (std::size_t v = 0; v < ma.meshes[m].mesh.vertices.size(); ++v)
      EXPECT_LE((ma.meshes[m].mesh.vertices[v] - mb.meshes[m].mesh.vertices[v]).norm(), 1e-9);
    triangles += ma.meshes[m].mesh.triangles.size();
  }
  EXPECT_GT(triangles, 100u);
  EXPECT_EQ(whole_stats.field_evaluations, lazy_stats.field_evaluations);
  if (fewer) {
    EXPECT_LT(lazy_stats.cells, whole_stats.cells);
  } else {
    EXPECT_EQ(lazy_stats.cells, whole_stats.cells);
  }
}

void expect_identical(const Reconstructor& a, const Reconstructor& b);
int add_unknown_discs(SliceSet& set, std::size_t first, std::size_t every);

TEST(OnDemandEngine, RandomSetsGiveTheWholeArrangementsFieldAndMeshes) {
  for (const unsigned seed : {21u, 22u}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    expect_same_reconstruction(random_set(seed, 24), true);
  }
}

TEST(OnDemandEngine, LongContoursGiveTheWholeArrangementsFieldAndMeshes) {
  // Sections of 400 edges: their parts in a face have far-field trees, whose approximations
  // depend on where a clipped ring starts, and so on the order of the face's edges.
  SliceSet set = random_set(27, 16, 400);
  ASSERT_GE(add_unknown_discs(set, 2, 3), 3);
  expect_same_reconstruction(set, true);
}

TEST(OnDemandEngine, SweepSetsGiveTheWholeArrangementsFieldAndMeshes) {
  expect_same_reconstruction(sweep_set(20), true);
}

// Adds an unknown disc of radius 8 to every `every`-th slice from `first`, clear of its
// sections (circles: centroid and radius); returns how many slices took one.
int add_unknown_discs(SliceSet& set, std::size_t first, std::size_t every) {
  int added = 0;
  for (std::size_t k = first; k < set.slices.size(); k += every) {
    LabeledSlice& slice = set.slices[k];
    for (int t = 0; t < 12; ++t) {
      const Vec2 c = 28.0 * Vec2(std::cos(0.5 * t), std::sin(0.5 * t));
      bool clear = true;
      for (const Region& r : slice.regions) {
        Vec2 centre = Vec2::Zero();
        for (const Vec2& q : r.outer) centre += q;
        centre /= static_cast<double>(r.outer.size());
        clear &= (c - centre).norm() > (r.outer[0] - centre).norm() + 9.0;
      }
      if (!clear) continue;
      slice.regions.push_back({kUnknownLabel, circle(c, 8.0, 24), {}});
      ++added;
      break;
    }
  }
  return added;
}

// A hexagonal field of view of radius 40 about the slice's origin.
Ring2 hexagon_fov() {
  Ring2 fov;
  for (int k = 0; k < 6; ++k) {
    const double t = 2.0 * std::numbers::pi * k / 6;
    fov.emplace_back(40.0 * std::cos(t), 40.0 * std::sin(t));
  }
  return fov;
}

TEST(OnDemandEngine, UnknownRegionSetsGiveTheWholeArrangementsFieldAndMeshes) {
  // Unknown discs on some slices, and a field of view on another: the cells around them are
  // built before the completion (which reads the faces around the unknown sets), the others on
  // demand, and still fewer than the whole arrangement's.
  SliceSet set = random_set(23, 10);
  ASSERT_GE(add_unknown_discs(set, 0, 3), 3);
  expect_same_reconstruction(set, true);
  set.slices[1].fov = hexagon_fov();
  expect_same_reconstruction(set, true);
}

TEST(OnDemandEngine, UnknownRegionSetsGiveTheSameResultsForAnyThreadCount) {
  const tbb::global_control workers(tbb::global_control::max_allowed_parallelism, 16);
  SliceSet set = random_set(26, 16);
  ASSERT_GE(add_unknown_discs(set, 1, 2), 5);
  set.slices[4].fov = hexagon_fov();
  ReconstructionStats one_stats;
  const auto one = reconstruct_with(set, true, &one_stats, 1);
  EXPECT_GT(one_stats.unknown_triangles, 0u);
  for (const int threads : {2, 4, 16}) {
    SCOPED_TRACE(std::to_string(threads) + " threads");
    ReconstructionStats stats;
    const auto other = reconstruct_with(set, true, &stats, threads);
    EXPECT_EQ(one_stats.cells, stats.cells);
    EXPECT_EQ(one_stats.faces, stats.faces);
    EXPECT_EQ(one_stats.unknown_triangles, stats.unknown_triangles);
    expect_identical(*one, *other);
  }
}

// `threads` bounds every stage of the on-demand engine too, and the result does not depend on
// it: the cells are built on one thread, the face images in fixed chunks merged in order, and
// the polygon of a face shared by two cells is the same whichever was built first.
TEST(OnDemandEngine, OneThreadGivesTheFieldAndMeshesOfTwo) {
  const SliceSet set = random_set(25, 30);
  ReconstructionStats one_stats, two_stats;
  const auto one = reconstruct_with(set, true, &one_stats, 1);
  const auto two = reconstruct_with(set, true, &two_stats, 2);
  EXPECT_EQ(one_stats.cells, two_stats.cells);
  EXPECT_EQ(one_stats.faces, two_stats.faces);
  const auto a = one->sampled_field();
  const auto b = two->sampled_field();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t n = 0; n < a.size(); ++n) {
    ASSERT_EQ(a[n].first, b[n].first);
    ASSERT_EQ(a[n].second, b[n].second) << "row " << n;
  }
  ASSERT_EQ(one->mesh().meshes.size(), two->mesh().meshes.size());
  for (std::size_t m = 0; m < one->mesh().meshes.size(); ++m) {
    EXPECT_EQ(one->mesh().meshes[m].mesh.vertices, two->mesh().meshes[m].mesh.vertices);
    EXPECT_EQ(one->mesh().meshes[m].mesh.triangles, two->mesh().meshes[m].mesh.triangles);
  }
}

// ---------------------------------------------------------------------------------------------
// The online engine on demand

ReconstructorOptions engine_options(bool on_demand, int threads) {
  ReconstructorOptions options;
  options.bounds = kBox;
  options.engine.max_depth = 5;
  options.engine.threads = threads;
  options.labels = {{1, "big"}, {2, "small"}};
  options.engine.cells_on_demand = on_demand;
  return options;
}

// The field and meshes of `a` and `b` identical to the bit.
void expect_identical(const Reconstructor& a, const Reconstructor& b) {
  const auto fa = a.sampled_field();
  const auto fb = b.sampled_field();
  ASSERT_EQ(fa.size(), fb.size());
  for (std::size_t n = 0; n < fa.size(); ++n) {
    ASSERT_EQ(fa[n].first, fb[n].first);
    ASSERT_EQ(fa[n].second, fb[n].second) << "row " << n;
  }
  ASSERT_EQ(a.mesh().meshes.size(), b.mesh().meshes.size());
  for (std::size_t m = 0; m < a.mesh().meshes.size(); ++m) {
    EXPECT_EQ(a.mesh().meshes[m].mesh.vertices, b.mesh().meshes[m].mesh.vertices);
    EXPECT_EQ(a.mesh().meshes[m].mesh.triangles, b.mesh().meshes[m].mesh.triangles);
  }
}

// Feeds `set` to an on-demand online engine: `first` slices in the first update, then one per
// update. After every `check_every`-th update (and the last) its field is within 1e-9 of the
// whole arrangement's one-shot field and its meshes are the same. Updates after the first are
// incremental (no rebuild), slices with unknown regions too; cells reopened by a new plane are
// fewer than those built. `online` is the engine.
void expect_online_matches_whole(const SliceSet& set, std::size_t first, std::size_t check_every,
                                 std::unique_ptr<Reconstructor>& online, int threads = 2) {
  online = std::make_unique<Reconstructor>(engine_options(true, threads));
  std::size_t incremental = 0;
  for (std::size_t k = 0; k < set.slices.size(); ++k) {
    online->add_slice(set.slices[k]);
    if (k + 1 < first) continue;
    const UpdateStats update = online->update();
    const bool last = k + 1 == set.slices.size();
    if (k + 1 > first) {
      EXPECT_FALSE(update.full_rebuild) << "update of slice " << k;
      if (!update.full_rebuild) {
        ++incremental;
        EXPECT_LT(update.cells_changed, update.step.cells) << "update of slice " << k;
      }
    }
    if ((k + 1 - first) % check_every != 0 && !last) continue;
    SCOPED_TRACE("after slice " + std::to_string(k));
    SliceSet so_far = online->slice_set();
    auto whole = std::make_unique<Reconstructor>(engine_options(false, threads));
    for (const LabeledSlice& s : so_far.slices) whole->add_slice(s);
    const UpdateStats whole_update = whole->update();
    const auto a = whole->sampled_field();
    const auto b = online->sampled_field();
    ASSERT_EQ(a.size(), b.size());
    double worst = 0.0;
    for (std::size_t n = 0; n < a.size(); ++n) {
      ASSERT_EQ(a[n].first, b[n].first) << "sampled vertices differ at row " << n;
      for (std::size_t l = 0; l < a[n].second.size(); ++l)
        worst = std::max(worst, std::abs(a[n].second[l] - b[n].second[l]));
    }
    EXPECT_LE(worst, 1e-9);
    const MeshSet& ma = whole->mesh();
    const MeshSet& mb = online->mesh();
    EXPECT_EQ(ma.meshes.size(), mb.meshes.size());
    for (std::size_t m = 0; m < std::min(ma.meshes.size(), mb.meshes.size()); ++m) {
      ASSERT_EQ(ma.meshes[m].mesh.vertices.size(), mb.meshes[m].mesh.vertices.size());
      ASSERT_EQ(ma.meshes[m].mesh.triangles, mb.meshes[m].mesh.triangles);
      for (std::size_t v = 0; v < ma.meshes[m].mesh.vertices.size(); ++v)
        EXPECT_LE((ma.meshes[m].mesh.vertices[v] - mb.meshes[m].mesh.vertices[v]).norm(), 1e-9);
    }
    EXPECT_LE(online->totals().cells, whole_update.step.cells);
  }
  EXPECT_GT(incremental, 0u);
}

TEST(OnDemandOnline, RandomSetsGiveTheWholeArrangementsFieldAndMeshes) {
  for (const unsigned seed : {31u, 32u}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    std::unique_ptr<Reconstructor> online;
    expect_online_matches_whole(random_set(seed, 22), 3, 4, online);
  }
}

TEST(OnDemandOnline, SweepSetsGiveTheWholeArrangementsFieldAndMeshes) {
  std::unique_ptr<Reconstructor> online;
  expect_online_matches_whole(sweep_set(20), 2, 4, online);
}

TEST(OnDemandOnline, UnknownRegionsArrivingKeepTheUpdatesIncremental) {
  // Slices without unknown regions, then some with a field of view or an unknown disc: each
  // update builds the cells around the new unknown sets and those a new plane reopened next
  // to the old ones, stays incremental, and equals the whole arrangement's reconstruction.
  SliceSet set = random_set(33, 14);
  for (std::size_t k = 9; k < set.slices.size(); k += 4) set.slices[k].fov = hexagon_fov();
  ASSERT_GE(add_unknown_discs(set, 6, 4), 1);
  std::unique_ptr<Reconstructor> online;
  expect_online_matches_whole(set, 4, 3, online);
  ASSERT_TRUE(online);
  EXPECT_GT(online->totals().unknown_triangles, 0u);
}

// `threads` bounds every stage of the online engine on demand, and its results do not depend
// on it: the same field and meshes, to the bit, for 1, 2, 4 and 16 threads after each update.
TEST(OnDemandOnline, ResultsAreIdenticalForAnyThreadCount) {
  // TBB allows as many workers as cores by default: let 16 threads run on a smaller machine.
  const tbb::global_control workers(tbb::global_control::max_allowed_parallelism, 16);
  const SliceSet set = random_set(34, 16);
  std::vector<std::unique_ptr<Reconstructor>> engines;
  for (const int threads : {1, 2, 4, 16})
    engines.push_back(std::make_unique<Reconstructor>(engine_options(true, threads)));
  for (std::size_t k = 0; k < set.slices.size(); ++k) {
    for (auto& engine : engines) {
      engine->add_slice(set.slices[k]);
      if (k >= 3) engine->update();
    }
    if (k < 3 || k % 4 != 3) continue;
    SCOPED_TRACE("after slice " + std::to_string(k));
    for (std::size_t e = 1; e < engines.size(); ++e) expect_identical(*engines[0], *engines[e]);
  }
  for (std::size_t e = 1; e < engines.size(); ++e) {
    EXPECT_EQ(engines[0]->totals().cells, engines[e]->totals().cells);
    expect_identical(*engines[0], *engines[e]);
  }
}

// Counts the worker threads that join the calling thread's default arena: the engine's stages
// run in its own arena of `threads` threads, so none should.
class DefaultArenaWorkers : public tbb::task_scheduler_observer {
 public:
  DefaultArenaWorkers() { observe(true); }
  ~DefaultArenaWorkers() override { observe(false); }
  void on_scheduler_entry(bool worker) override {
    if (worker) ++workers;
  }
  std::atomic<int> workers{0};
};

TEST(OnDemandOnline, EveryStageRunsInTheEnginesArena) {
  const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, 4);
  const SliceSet set = random_set(35, 10);
  {
    DefaultArenaWorkers observer;
    Reconstructor engine(engine_options(true, 1));
    for (std::size_t k = 0; k < set.slices.size(); ++k) {
      engine.add_slice(set.slices[k]);
      if (k >= 3) engine.update();
    }
    EXPECT_EQ(observer.workers.load(), 0) << "a stage ran parallel work outside the engine's arena";
  }
  // The observer does see workers that join the default arena (else the check above is void).
  DefaultArenaWorkers observer;
  std::atomic<double> sink{0.0};
  tbb::parallel_for(0, 256, [&](int i) {
    double x = i;
    for (int k = 0; k < 200000; ++k) x = std::sqrt(x + k);
    sink = sink + x;
  });
  if (observer.workers.load() == 0) GTEST_SKIP() << "no worker joined a parallel loop here";
}

TEST(OnDemandEngine, TheOneShotReconstructionBuildsCellsOnDemand) {
  SliceSet set = random_set(24, 24);
  set.bounds = kBox;
  set.labels = {{1, "big"}, {2, "small"}};
  ReconstructionOptions options;
  options.max_depth = 5;
  ReconstructionStats stats, whole;
  const MeshSet meshes = reconstruct(set, options, &stats);
  reconstruct_with(set, false, &whole);
  EXPECT_LT(stats.cells, whole.cells);
  EXPECT_GT(stats.cells, 0u);
  EXPECT_EQ(meshes.meshes.size(), 2u);
}

}  // namespace
}  // namespace sonoshape::recon::on_demand_test
