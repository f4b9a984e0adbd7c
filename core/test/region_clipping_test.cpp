// clip_region: the parts of a region inside and outside a polygon partition it, keep its label and
// its hole, and come out whole where the polygon misses or covers the region.
#include "sonoshape/core/region_clipping.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::region_clipping_test {
namespace {

Ring2 square(double x0, double y0, double side) {
  return {{x0, y0}, {x0 + side, y0}, {x0 + side, y0 + side}, {x0, y0 + side}};
}

double area(const std::vector<Region>& regions) {
  double sum = 0.0;
  for (const Region& r : regions) {
    sum += std::abs(signed_area(r.outer));
    for (const Ring2& h : r.holes) sum -= std::abs(signed_area(h));
  }
  return sum;
}

TEST(RegionClipping, InsideAndOutsidePartsPartitionTheRegionAndKeepItsLabel) {
  Region region{3, square(0, 0, 10), {square(4, 4, 2)}};      // 100 mm², a 4 mm² hole
  const Ring2 left = {{-1, -1}, {5, -1}, {5, 11}, {-1, 11}};  // x < 5, clockwise or not
  const std::vector<Region> inside = clip_region(region, left, true);
  const std::vector<Region> outside = clip_region(region, left, false);
  EXPECT_NEAR(area(inside), 50.0 - 2.0, 1e-12);
  EXPECT_NEAR(area(outside), 50.0 - 2.0, 1e-12);
  for (const auto* parts : {&inside, &outside}) {
    ASSERT_FALSE(parts->empty());
    for (const Region& r : *parts) EXPECT_EQ(r.label, 3);
  }
  // The reversed polygon cuts the same way.
  const Ring2 reversed(left.rbegin(), left.rend());
  EXPECT_NEAR(area(clip_region(region, reversed, true)), 48.0, 1e-12);
}

TEST(RegionClipping, APolygonThatMissesOrCoversTheRegionLeavesItWholeOrNothing) {
  const Region region{1, square(0, 0, 2), {}};
  EXPECT_TRUE(clip_region(region, square(5, 5, 1), true).empty());
  const std::vector<Region> untouched = clip_region(region, square(5, 5, 1), false);
  ASSERT_EQ(untouched.size(), 1u);
  EXPECT_NEAR(area(untouched), 4.0, 1e-12);
  const std::vector<Region> covered = clip_region(region, square(-1, -1, 4), true);
  ASSERT_EQ(covered.size(), 1u);
  EXPECT_NEAR(area(covered), 4.0, 1e-12);
  EXPECT_TRUE(clip_region(region, square(-1, -1, 4), false).empty());
}

}  // namespace
}  // namespace sonoshape::region_clipping_test
