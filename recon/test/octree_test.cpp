// The octree's bookkeeping: the grid-vertex index (direct table and hash) and the contour keys an
// online engine merges slice by slice.
#include <gtest/gtest.h>

#include <random>

#include "grid_index.hpp"
#include "octree_field.hpp"

namespace sonoshape::recon {
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
        ASSERT_EQ(direct.find(grid_key(i, j, k)), hashed.find(grid_key(i, j, k))) << i << " " << j << " " << k;
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

}  // namespace
}  // namespace sonoshape::recon
