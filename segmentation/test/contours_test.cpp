// The polygons of label maps are valid by construction: one-pixel necks, diagonal corner
// contacts, holes pinched against their outer ring and random maps all give slices that pass
// validate_slice_set, with nothing dropped.
#include "sonoshape/segmentation/contours.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <set>
#include <utility>

#include "sonoshape/core/slice_io.hpp"

namespace sonoshape::seg {
namespace {

ImagePlane scaled_plane(double mm_per_px) {
  ImagePlane plane;
  plane.pixel_to_plane << mm_per_px, 0.0, 1.0, 0.0, mm_per_px, -2.0;
  return plane;
}

Ring2 image_box(int w, int h) {
  return {{-0.5, -0.5}, {w - 0.5, -0.5}, {w - 0.5, h - 0.5}, {-0.5, h - 0.5}};
}

Status validate(const LabeledSlice& slice) {
  SliceSet set;
  set.slices.push_back(slice);
  return validate_slice_set(set, "test slice");
}

// No point is shared by two rings or twice by one ring: rings neither touch each other nor
// themselves at a vertex (the pinches the old outlines had).
void expect_no_shared_points(const LabeledSlice& slice) {
  std::set<std::pair<double, double>> seen;
  std::size_t points = 0;
  auto add = [&](const Ring2& ring) {
    for (const Vec2& p : ring) {
      seen.insert({p.x(), p.y()});
      ++points;
    }
  };
  for (const Region& r : slice.regions) {
    add(r.outer);
    for (const Ring2& hole : r.holes) add(hole);
  }
  EXPECT_EQ(seen.size(), points);
}

double label_area(const LabeledSlice& slice, int label) {
  double area = 0.0;
  for (const Region& r : slice.regions) {
    if (r.label != label) continue;
    area += std::abs(signed_area(r.outer));
    for (const Ring2& hole : r.holes) area -= std::abs(signed_area(hole));
  }
  return area;
}

TEST(Contours, OnePixelNecksAndDiagonalCornersGiveValidPolygons) {
  LabelImage map(40, 30, 0);
  auto fill = [&](int i0, int j0, int i1, int j1, std::uint8_t v) {
    for (int j = j0; j < j1; ++j)
      for (int i = i0; i < i1; ++i) map.at(i, j) = v;
  };
  // Two blocks of label 1 joined by a one-pixel neck (a line of pixels).
  fill(2, 2, 8, 8, 1);
  fill(8, 4, 14, 5, 1);
  fill(14, 2, 20, 8, 1);
  // A block of label 1 meeting another only at a corner (diagonal contact), and a block of
  // label 2 on the other diagonal (so the two labels' outlines would cross there).
  fill(22, 2, 27, 7, 1);
  fill(27, 7, 32, 12, 1);
  fill(27, 2, 32, 7, 2);
  fill(22, 7, 27, 12, 2);
  // A ring of label 1 whose hole touches the outer boundary at a corner, with two holes that
  // touch each other diagonally, and an isolated pixel and a one-pixel line of unknown.
  fill(2, 14, 20, 28, 1);
  fill(5, 17, 9, 21, 0);
  fill(9, 21, 13, 25, 0);
  fill(14, 17, 18, 25, 0);
  map.at(2, 14) = 0;  // the ring's corner pixel goes: the outside now touches ...
  map.at(3, 15) = 0;  // ... this one-pixel hole at a corner
  map.at(2, 13) = 1;  // and a pixel above meets the ring only at a corner
  map.at(25, 20) = kLabelPixelUnknown;
  fill(23, 24, 38, 25, kLabelPixelUnknown);
  const ImageU8 sector(40, 30, 255);
  const ImagePlane plane = scaled_plane(0.5);
  std::size_t pixels_1 = 0;
  for (const std::uint8_t v : map.pixels) pixels_1 += v == 1;
  for (const double tolerance_mm : {0.0, 0.3, 2.0}) {
    std::vector<Repair> repairs;
    const auto slice = make_slice(map, sector, image_box(40, 30), plane, tolerance_mm, &repairs);
    ASSERT_TRUE(slice) << "tolerance " << tolerance_mm << ": " << slice.message();
    EXPECT_TRUE(repairs.empty()) << repairs.front().detail;
    expect_no_shared_points(*slice);
    bool unknown = false;
    for (const Region& r : slice->regions) unknown |= r.label == kUnknownLabel;
    EXPECT_TRUE(unknown);
    if (tolerance_mm == 0.0) {
      // The outlines run a quarter pixel inside the pixel edges: the area is the pixels' less
      // a quarter-pixel band along the boundary (and the few pixels that broke a pinch).
      const double px = 0.25;  // mm² per pixel
      EXPECT_LT(label_area(*slice, 1), pixels_1 * px);
      EXPECT_GT(label_area(*slice, 1), 0.8 * pixels_1 * px);
    }
  }
}

TEST(Contours, RandomLabelMapsGiveValidSlices) {
  // Speckle-like maps (every pixel a random label) are the worst case for necks and pinches.
  std::mt19937 rng(7);
  for (int trial = 0; trial < 12; ++trial) {
    const int w = 24 + trial, h = 20 + 2 * trial;
    LabelImage map(w, h, 0);
    std::uniform_int_distribution<int> pick(0, 3);
    const bool blocky = trial % 2 == 0;
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        const int v = blocky ? pick(rng) * (((i / 3) + (j / 2)) % 2) : pick(rng);
        map.at(i, j) = v == 3 ? kLabelPixelUnknown : static_cast<std::uint8_t>(v);
      }
    ImageU8 sector(w, h, 0);
    Ring2 fov;  // a triangle-ish sector, not the whole image
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) sector.at(i, j) = std::abs(i - w / 2) <= j + 2 ? 255 : 0;
    fov = {{w / 2.0 - 2.5, -0.5}, {w / 2.0 + 2.5, -0.5}, {w + 0.5, h - 0.5}, {-0.5, h - 0.5}};
    for (const double tolerance_mm : {0.0, 0.7}) {
      std::vector<Repair> repairs;
      const auto slice = make_slice(map, sector, fov, scaled_plane(0.3), tolerance_mm, &repairs);
      ASSERT_TRUE(slice) << "trial " << trial << ": " << slice.message();
      EXPECT_TRUE(repairs.empty()) << "trial " << trial << ": " << repairs.front().detail;
      expect_no_shared_points(*slice);
    }
  }
}

TEST(Contours, SimplificationKeepsNeighboursApartAndCutsPoints) {
  // A wavy boundary between two labels: simplified ring by ring, the two outlines would cross;
  // simplified together they stay apart, with far fewer points than the exact outlines.
  const int w = 120, h = 60;
  LabelImage map(w, h, 1);
  for (int i = 0; i < w; ++i) {
    const int edge = 30 + static_cast<int>(std::lround(6.0 * std::sin(i * 0.3)));
    for (int j = edge; j < h; ++j) map.at(i, j) = 2;
  }
  const ImageU8 sector(w, h, 255);
  const ImagePlane plane = scaled_plane(0.2);
  std::size_t exact_points = 0, simplified_points = 0;
  for (const double tolerance_mm : {0.0, 0.4}) {
    std::vector<Repair> repairs;
    const auto slice = make_slice(map, sector, image_box(w, h), plane, tolerance_mm, &repairs);
    ASSERT_TRUE(slice) << slice.message();
    EXPECT_TRUE(repairs.empty());
    EXPECT_TRUE(validate(*slice));
    std::size_t& points = tolerance_mm == 0.0 ? exact_points : simplified_points;
    for (const Region& r : slice->regions) points += r.outer.size();
  }
  EXPECT_LT(simplified_points * 3, exact_points);
}

TEST(Contours, SimplificationIsReproducible) {
  // Ties in the simplification's cost must not be broken by memory addresses: the same map,
  // simplified with the heap in different states, gives the same polygons.
  std::mt19937 rng(11);
  LabelImage map(60, 50, 0);
  std::uniform_int_distribution<int> pick(0, 2);
  for (int j = 0; j < 50; ++j)
    for (int i = 0; i < 60; ++i) map.at(i, j) = static_cast<std::uint8_t>(pick(rng) ? 1 : 2);
  const ImageU8 sector(60, 50, 255);
  std::vector<std::vector<Region>> runs;
  std::vector<std::unique_ptr<int[]>> clutter;
  for (int run = 0; run < 4; ++run) {
    for (int k = 0; k < 100 * (run + 1); ++k) clutter.emplace_back(new int[1 + (k * 7) % 50]);
    runs.push_back(label_map_regions(map, sector, scaled_plane(0.2), 0.5));
  }
  for (int run = 1; run < 4; ++run) {
    ASSERT_EQ(runs[run].size(), runs[0].size());
    for (std::size_t r = 0; r < runs[0].size(); ++r) {
      EXPECT_EQ(runs[run][r].outer, runs[0][r].outer) << "run " << run << " region " << r;
      EXPECT_EQ(runs[run][r].holes, runs[0][r].holes) << "run " << run << " region " << r;
    }
  }
}

TEST(Contours, InvalidRegionsAreDroppedAndRecorded) {
  // The safety net behind make_slice: what no construction mends is dropped, with a record.
  LabeledSlice slice;
  slice.regions.push_back(Region{1, {{0, 0}, {4, 0}, {4, 4}, {0, 4}}, {}});
  slice.regions.push_back(Region{2, {{10, 0}, {14, 4}, {14, 0}, {10, 4}}, {}});  // a bow tie
  slice.regions.push_back(Region{kUnknownLabel,
                                 {{20, 0}, {30, 0}, {30, 10}, {20, 10}},
                                 {{{21, 1}, {23, 1}, {23, 3}}, {{40, 40}, {41, 40}, {41, 41}}}});
  std::vector<Repair> repairs;
  drop_invalid_regions(slice, &repairs);
  ASSERT_EQ(slice.regions.size(), 1u);
  EXPECT_EQ(slice.regions[0].label, 1);
  ASSERT_EQ(repairs.size(), 2u);
  EXPECT_EQ(repairs[0].kind, "invalid_region");
  EXPECT_EQ(repairs[0].where, "label 2");
  EXPECT_NE(repairs[0].detail.find("self-intersects"), std::string::npos) << repairs[0].detail;
  EXPECT_EQ(repairs[1].where, "unknown");
  EXPECT_NE(repairs[1].detail.find("hole"), std::string::npos) << repairs[1].detail;
  EXPECT_NEAR(repairs[1].area_changed_mm2, 100.0 - 2.0 - 0.5, 1e-9);
  EXPECT_TRUE(validate(slice));
}

TEST(Contours, InvalidFovIsAnError) {
  const LabelImage map(10, 10, 1);
  const ImageU8 sector(10, 10, 255);
  const Ring2 bow_tie{{0, 0}, {9, 9}, {9, 0}, {0, 9}};
  const auto slice = make_slice(map, sector, bow_tie, scaled_plane(1.0), 0.0);
  ASSERT_FALSE(slice);
  EXPECT_NE(slice.message().find("fov"), std::string::npos) << slice.message();
}

}  // namespace
}  // namespace sonoshape::seg
