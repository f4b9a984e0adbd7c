// The octree's bookkeeping: the grid-vertex index (direct table and hash), the sorted key sets of
// the smoothing and the mesher, the contour keys an
// online engine merges slice by slice, and the field it keeps from one update to the next.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include "grid_index.hpp"
#include "key_masks.hpp"
#include "octree_field.hpp"
#include "sorted_keys.hpp"

namespace sonoshape::recon::octree_test {
namespace {

TEST(Octree, DirectGridIndexAgreesWithTheHashInsideAndOutsideTheGrid) {
  constexpr int kResolution = 16;
  GridIndex direct(kResolution);
  GridIndex hashed;
  std::mt19937 rng(3);
  // Indices from well outside the grid (hash part of the direct index) to well inside.
  std::uniform_int_distribution<int> index(-6, kResolution + 6);
  std::vector<std::uint64_t> keys;
  for (int n = 0; n < 3000; ++n) keys.push_back(grid_key(index(rng), index(rng), index(rng)));
  for (std::size_t n = 0; n < keys.size(); ++n) {
    const auto row = static_cast<std::uint32_t>(n);
    EXPECT_EQ(direct.insert(keys[n], row), hashed.insert(keys[n], row));
  }
  EXPECT_EQ(direct.size(), hashed.size());
  for (int i = -7; i <= kResolution + 7; ++i)
    for (int j = -7; j <= kResolution + 7; ++j)
      for (int k = -7; k <= kResolution + 7; ++k)
        ASSERT_EQ(direct.find(grid_key(i, j, k)), hashed.find(grid_key(i, j, k)))
            << i << " " << j << " " << k;
  direct.clear();
  EXPECT_EQ(direct.size(), 0u);
  for (const std::uint64_t key : keys) EXPECT_EQ(direct.find(key), GridIndex::kNone);
  EXPECT_TRUE(direct.insert(keys.front(), 7));
  EXPECT_EQ(direct.at(keys.front()), 7u);
}

TEST(Octree, ContourKeysMergedSliceBySliceEqualThoseOfAllContours) {
  Grid grid;
  grid.origin = Vec3(-10, -10, -10);
  grid.depth = 5;
  grid.cell_size = 20.0 / 32;
  OctreeOptions options;
  options.max_depth = grid.depth;
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> coordinate(-10.0, 10.0);
  std::vector<std::vector<std::pair<Vec3, Vec3>>> parts(3);
  std::vector<std::pair<Vec3, Vec3>> all;
  for (auto& part : parts)
    for (int n = 0; n < 40; ++n) {
      const Vec3 a(coordinate(rng), coordinate(rng), coordinate(rng));
      const Vec3 b = a + Vec3(coordinate(rng), coordinate(rng), coordinate(rng)) * 0.1;
      part.emplace_back(a, b);
      all.emplace_back(a, b);
    }
  ContourKeys merged = contour_keys(grid, options, {});
  for (const auto& part : parts) merge_contour_keys(merged, contour_keys(grid, options, part));
  const ContourKeys at_once = contour_keys(grid, options, all);
  EXPECT_EQ(merged.cells_by_level, at_once.cells_by_level);
  EXPECT_EQ(merged.fixed_vertices, at_once.fixed_vertices);
  EXPECT_FALSE(at_once.fixed_vertices.empty());
  EXPECT_EQ(at_once.cells_by_level.size(), static_cast<std::size_t>(grid.depth + 1));
}

// A sphere (function 1), a sheet 0.4 mm thick (function 2) between grid planes, so that only
// snapping gives the sheet grid vertices, and a speck of function 2 at one finest vertex that the
// refinement does not reach, next to a snapped vertex: the band must come out closed after the
// snapping's closure, which expands from the snapped cells only (here: onto the speck's cells).
TEST(Octree, BandStaysClosedAfterSnappingThinRegions) {
  const Box3 box{Vec3::Constant(-10.0), Vec3::Constant(10.0)};
  OctreeOptions options;
  options.max_depth = 5;  // cells of 0.625 mm; the sheet's mid-plane z = 5.3 is 0.3 from a vertex
  const BatchEvaluator evaluate = [](const std::vector<Vec3>& points, double* values,
                                     std::uint64_t*) {
    for (std::size_t n = 0; n < points.size(); ++n) {
      const Vec3& p = points[n];
      values[3 * n] = 0.0;
      values[3 * n + 1] = 6.0 - (p - Vec3(0, 0, -2)).norm();
      const double sheet =
          std::abs(p.x()) < 6 && std::abs(p.y()) < 6 ? 0.2 - std::abs(p.z() - 5.3) : -1.0;
      values[3 * n + 2] =
          std::max(sheet, 0.3 - (p - Vec3(-6.875, 6.875, -3.75)).norm());  // vertex (5, 27, 10)
    }
  };
  std::vector<RegionSample> samples;
  for (double x = -5.5; x <= 5.5; x += 0.3)
    for (double y = -5.5; y <= 5.5; y += 0.3) samples.push_back({Vec3(x, y, 5.3), 2});
  samples.push_back({Vec3(-6.25, 6.875, -3.75), 2});  // vertex (6, 27, 10), beside the speck
  const SampledField field = sample_field(box, 3, evaluate, ContourKeys{}, samples, options);
  ASSERT_GT(field.snapped_vertices, 0u);
  const int resolution = 1 << options.max_depth;
  auto label = [&](int i, int j, int k) { return field.label(grid_key(i, j, k)); };
  std::size_t sheet_cells = 0;
  for (const std::uint64_t cell : field.surface_cells) {
    int i, j, k;
    grid_unkey(cell, i, j, k);
    std::vector<int> corners;
    for (int c = 0; c < 8; ++c)
      corners.push_back(label(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)));
    EXPECT_NE(std::count(corners.begin(), corners.end(), corners[0]), 8) << "band cell not mixed";
    sheet_cells += std::count(corners.begin(), corners.end(), 2) > 0;
    // Every face with mixed corners leads to a band cell.
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        std::array<int, 3> base{i, j, k}, neighbour{i, j, k};
        base[static_cast<std::size_t>(axis)] += side;
        neighbour[static_cast<std::size_t>(axis)] += side ? 1 : -1;
        if (neighbour[static_cast<std::size_t>(axis)] < 0 ||
            neighbour[static_cast<std::size_t>(axis)] >= resolution)
          continue;
        std::vector<int> face;
        for (int c = 0; c < 4; ++c) {
          std::array<int, 3> p = base;
          p[static_cast<std::size_t>((axis + 1) % 3)] += c & 1;
          p[static_cast<std::size_t>((axis + 2) % 3)] += (c >> 1) & 1;
          face.push_back(label(p[0], p[1], p[2]));
        }
        if (std::count(face.begin(), face.end(), face[0]) == 4) continue;
        EXPECT_TRUE(std::binary_search(field.surface_cells.begin(), field.surface_cells.end(),
                                       grid_key(neighbour[0], neighbour[1], neighbour[2])))
            << "open band at cell " << i << " " << j << " " << k;
      }
  }
  EXPECT_GT(sheet_cells, 0u);
  // The speck's cells on the far side from the snapped vertex come only from the expansion.
  EXPECT_TRUE(std::binary_search(field.surface_cells.begin(), field.surface_cells.end(),
                                 grid_key(4, 26, 9)));
}

// The online engine keeps the last field and marks the rows whose cells changed: sampling again
// from it must give exactly the field sampled afresh (the same vertices, values, band and snaps),
// with fewer evaluations. The change moves the sphere where x > 2; the sheet is snapped in both.
TEST(Octree, AKeptFieldSampledAgainEqualsAFreshField) {
  const Box3 box{Vec3::Constant(-10.0), Vec3::Constant(10.0)};
  OctreeOptions options;
  options.max_depth = 5;
  const auto evaluator = [](double shift) {
    return BatchEvaluator([shift](const std::vector<Vec3>& points, double* values, std::uint64_t*) {
      for (std::size_t n = 0; n < points.size(); ++n) {
        const Vec3& p = points[n];
        const Vec3 centre(0.0, p.x() > 2.0 ? shift : 0.0, -2.0);
        values[3 * n] = 0.0;
        values[3 * n + 1] = 6.0 - (p - centre).norm();
        values[3 * n + 2] =
            std::abs(p.x()) < 6 && std::abs(p.y()) < 6 ? 0.2 - std::abs(p.z() - 5.3) : -1.0;
      }
    });
  };
  std::vector<RegionSample> samples;
  for (double x = -5.5; x <= 5.5; x += 0.3)
    for (double y = -5.5; y <= 5.5; y += 0.3) samples.push_back({Vec3(x, y, 5.3), 2});
  OctreeWorkspace workspace;
  SampledField kept =
      sample_field(box, 3, evaluator(0.0), ContourKeys{}, samples, options, workspace);
  std::vector<char> valid(kept.keys.size());
  for (std::size_t r = 0; r < valid.size(); ++r) {
    int i, j, k;
    grid_unkey(kept.keys[r], i, j, k);
    valid[r] = !(kept.grid.position(i, j, k).x() > 2.0);
  }
  workspace.previous = std::move(kept);
  workspace.previous_valid = std::move(valid);
  const SampledField again =
      sample_field(box, 3, evaluator(1.5), ContourKeys{}, samples, options, workspace);
  const SampledField fresh = sample_field(box, 3, evaluator(1.5), ContourKeys{}, samples, options);
  EXPECT_LT(again.evaluations, fresh.evaluations / 2);
  EXPECT_EQ(again.surface_cells, fresh.surface_cells);
  EXPECT_EQ(again.snapped_vertices, fresh.snapped_vertices);
  ASSERT_GT(fresh.snapped_vertices, 0u);
  // The rows this pass read, against all rows of the fresh field.
  std::size_t read = 0;
  for (std::size_t r = 0; r < again.keys.size(); ++r) {
    if (again.row_pass[r] != again.pass) continue;
    ++read;
    ASSERT_NE(fresh.index.find(again.keys[r]), GridIndex::kNone)
        << "a row the fresh field does not have";
    const double* a = again.values.data() + r * 3;
    const double* b = fresh.at(again.keys[r]);
    for (int l = 0; l < 3; ++l) ASSERT_EQ(a[l], b[l]) << "row " << r << " function " << l;
  }
  EXPECT_EQ(read, fresh.keys.size());
}

// The neighbour sets of the smoothing and the mesher: the merged shifted copies must be the sorted
// set of all shifted keys, and each key's recorded positions must hold its shifted keys.
TEST(Octree, UnionOfShiftsListsEveryShiftedKeyAndWhereItLies) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> index(0, 60);
  std::vector<std::uint64_t> keys;  // enough that the merge runs in several parts
  for (int n = 0; n < 80000; ++n) keys.push_back(grid_key(index(rng), index(rng), index(rng)));
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  for (const auto& shifts :
       {std::vector<std::int64_t>(kStencilShifts.begin(), kStencilShifts.end()),
        std::vector<std::int64_t>(kCubeCornerShifts.begin(), kCubeCornerShifts.end())}) {
    std::vector<std::uint32_t> positions;
    const std::vector<std::uint64_t> merged = union_of_shifts(keys, shifts, &positions);
    std::vector<std::uint64_t> expected;
    for (const std::uint64_t key : keys)
      for (const std::int64_t shift : shifts)
        expected.push_back(key + static_cast<std::uint64_t>(shift));
    std::sort(expected.begin(), expected.end());
    expected.erase(std::unique(expected.begin(), expected.end()), expected.end());
    EXPECT_EQ(merged, expected);
    ASSERT_GT(keys.size(), 3u * 16384u);
    ASSERT_EQ(positions.size(), keys.size() * shifts.size());
    for (std::size_t n = 0; n < keys.size(); ++n)
      for (std::size_t c = 0; c < shifts.size(); ++c)
        ASSERT_EQ(merged[positions[n * shifts.size() + c]],
                  keys[n] + static_cast<std::uint64_t>(shifts[c]))
            << "key " << n << " shift " << c;
  }
  // An empty band has no neighbours.
  std::vector<std::uint32_t> positions(3, 0);
  EXPECT_TRUE(union_of_shifts({}, kStencilShifts, &positions).empty());
  EXPECT_TRUE(positions.empty());
}

// The same sets on bit masks (key_masks.hpp): identical keys and positions to the merges, for
// rows along k of one and of three words, negative indices, a thin shell like a band, and a box too
// large for masks (the merges then answer).
TEST(Octree, MaskedUnionsEqualTheMerges) {
  std::mt19937 rng(9);
  std::vector<std::vector<std::uint64_t>> sets;
  std::uniform_int_distribution<int> wide(-3, 140), narrow(5, 40);
  std::vector<std::uint64_t> scattered, small, shell;
  for (int n = 0; n < 30000; ++n) scattered.push_back(grid_key(wide(rng), wide(rng), wide(rng)));
  for (int n = 0; n < 3000; ++n) small.push_back(grid_key(narrow(rng), narrow(rng), narrow(rng)));
  for (int i = 0; i < 128; ++i)
    for (int j = 0; j < 128; ++j)
      for (int k = 0; k < 128; ++k) {
        const double r =
            std::sqrt((i - 64.0) * (i - 64.0) + (j - 60.0) * (j - 60.0) + (k - 70.0) * (k - 70.0));
        if (std::abs(r - 50.0) < 1.0) shell.push_back(grid_key(i, j, k));
      }
  const std::vector<std::uint64_t> huge = {grid_key(0, 0, 0), grid_key(3, 5, 7),
                                           grid_key(400000, 2, 2)};
  for (auto* set : {&scattered, &small, &shell}) {
    std::sort(set->begin(), set->end());
    set->erase(std::unique(set->begin(), set->end()), set->end());
  }
  for (const std::vector<std::uint64_t>* set :
       std::initializer_list<const std::vector<std::uint64_t>*>{&scattered, &small, &shell,
                                                                &huge}) {
    std::vector<std::uint32_t> merged_positions, masked_positions;
    EXPECT_EQ(cube_corner_union(*set, &masked_positions),
              union_of_shifts(*set, kCubeCornerShifts, &merged_positions));
    EXPECT_EQ(masked_positions, merged_positions);
    EXPECT_EQ(cube_corner_union(*set), union_of_shifts(*set, kCubeCornerShifts));
    EXPECT_EQ(stencil_union(*set, &masked_positions),
              union_of_shifts(*set, kStencilShifts, &merged_positions));
    EXPECT_EQ(masked_positions, merged_positions);
  }
  ASSERT_GT(shell.size(), 10000u);
  std::vector<std::uint32_t> positions(3, 0);
  EXPECT_TRUE(stencil_union({}, &positions).empty());
  EXPECT_TRUE(positions.empty());
}

}  // namespace
}  // namespace sonoshape::recon::octree_test
