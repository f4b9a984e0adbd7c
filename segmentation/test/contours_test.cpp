// The polygons of label maps are valid by construction: one-pixel necks, diagonal corner
// contacts, holes pinched against their outer ring and random maps all give slices that pass
// validate_slice_set, with nothing dropped.
#include "sonoshape/segmentation/contours.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <utility>

#include "sonoshape/core/slice_io.hpp"

namespace sonoshape::segmentation::contours_test {
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

// No ring passes a point twice (the pinches the old outlines had); rings of neighbouring labels
// may share points, as they share edges.
void expect_no_pinches(const LabeledSlice& slice) {
  auto check = [&](const Ring2& ring) {
    std::set<std::pair<double, double>> seen;
    for (const Vec2& p : ring) seen.insert({p.x(), p.y()});
    EXPECT_EQ(seen.size(), ring.size());
  };
  for (const Region& r : slice.regions) {
    check(r.outer);
    for (const Ring2& hole : r.holes) check(hole);
  }
}

// Every edge of every ring runs along the pixel grid: axis-parallel, its ends on pixel corners
// (half-integer pixel coordinates) of a plane that maps pixel (i, j) to (s i + 1, s j - 2) mm.
void expect_on_pixel_edges(const LabeledSlice& slice, double mm_per_px) {
  auto check = [&](const Ring2& ring) {
    for (std::size_t k = 0; k < ring.size(); ++k) {
      const Vec2& a = ring[k];
      const Vec2& b = ring[(k + 1) % ring.size()];
      EXPECT_TRUE(a.x() == b.x() || a.y() == b.y()) << a.transpose() << " - " << b.transpose();
      const double i = (a.x() - 1.0) / mm_per_px, j = (a.y() + 2.0) / mm_per_px;
      EXPECT_NEAR(i - std::floor(i), 0.5, 1e-9) << a.transpose();
      EXPECT_NEAR(j - std::floor(j), 0.5, 1e-9) << a.transpose();
    }
  };
  for (const Region& r : slice.regions) {
    check(r.outer);
    for (const Ring2& hole : r.holes) check(hole);
  }
}

std::size_t slanted_edges(const LabeledSlice& slice) {
  std::size_t count = 0;
  auto add = [&](const Ring2& ring) {
    for (std::size_t k = 0; k < ring.size(); ++k) {
      const Vec2& a = ring[k];
      const Vec2& b = ring[(k + 1) % ring.size()];
      count += a.x() != b.x() && a.y() != b.y();
    }
  };
  for (const Region& r : slice.regions) {
    add(r.outer);
    for (const Ring2& hole : r.holes) add(hole);
  }
  return count;
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
  for (const OutlineForm form : {OutlineForm::kPixelEdges, OutlineForm::kSmooth})
    for (const double tolerance_mm : {0.0, 0.3, 2.0}) {
      std::vector<Repair> repairs;
      const auto slice =
          make_slice(map, sector, image_box(40, 30), plane, tolerance_mm, &repairs, form);
      ASSERT_TRUE(slice) << "tolerance " << tolerance_mm << ": " << slice.message();
      EXPECT_TRUE(repairs.empty()) << repairs.front().detail;
      expect_no_pinches(*slice);
      bool unknown = false;
      for (const Region& r : slice->regions) unknown |= r.label == kUnknownLabel;
      EXPECT_TRUE(unknown);
      if (tolerance_mm == 0.0 && form == OutlineForm::kPixelEdges) {
        // The outlines run on the pixel edges: the area is a whole number of pixels, the label's
        // but for the few that broke a pinch (one per diagonal contact).
        const double px = 0.25;  // mm² per pixel
        const double pixels = label_area(*slice, 1) / px;
        EXPECT_NEAR(pixels, std::round(pixels), 1e-9);
        EXPECT_LE(pixels, pixels_1 + 1e-9);
        EXPECT_GE(pixels, pixels_1 - 4.0);
        expect_on_pixel_edges(*slice, 0.5);
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
    for (const OutlineForm form : {OutlineForm::kPixelEdges, OutlineForm::kSmooth})
      for (const double tolerance_mm : {0.0, 0.7}) {
        std::vector<Repair> repairs;
        const auto slice =
            make_slice(map, sector, fov, scaled_plane(0.3), tolerance_mm, &repairs, form);
        ASSERT_TRUE(slice) << "trial " << trial << ": " << slice.message();
        EXPECT_TRUE(repairs.empty()) << "trial " << trial << ": " << repairs.front().detail;
        // Valid by construction: make_slice did not fall back to the exact (axis-parallel)
        // outlines.
        if (form == OutlineForm::kSmooth) {
          EXPECT_GT(slanted_edges(*slice), 0u);
        }
        expect_no_pinches(*slice);
        if (tolerance_mm == 0.0 && form == OutlineForm::kPixelEdges)
          expect_on_pixel_edges(*slice, 0.3);
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

// The area and centroid of a label's regions (outer rings less holes), in mm.
std::pair<double, Vec2> area_and_centroid(const LabeledSlice& slice, int label) {
  double area = 0.0;
  Vec2 moment = Vec2::Zero();
  auto add = [&](const Ring2& ring, double sign) {
    const double a = signed_area(ring);
    Vec2 m = Vec2::Zero();  // first moment of the ring's signed area
    for (std::size_t k = 0; k < ring.size(); ++k) {
      const Vec2& p = ring[k];
      const Vec2& q = ring[(k + 1) % ring.size()];
      const double cross = p.x() * q.y() - q.x() * p.y();
      m += (p + q) * cross / 6.0;
    }
    const double s = a < 0.0 ? -sign : sign;  // whatever the ring's orientation
    area += s * a;
    moment += s * m;
  };
  for (const Region& r : slice.regions) {
    if (r.label != label) continue;
    add(r.outer, 1.0);
    for (const Ring2& hole : r.holes) add(hole, -1.0);
  }
  return {area, moment / area};
}

TEST(Contours, OutlinesLieOnThePixelEdges) {
  // A rectangle of pixels, a disc with a hole, and two labels side by side: each outline runs on
  // the edges of its label's pixels, so its area is the pixel count and its centroid the mean of
  // the pixel centres; neighbours share the edge between them. A tracer whose outlines are
  // inset, grown or moved by a fraction of a pixel (a sub-pixel offset of the wrong sign moves
  // every outline half a pixel towards +column/+row) fails here.
  const int w = 64, h = 48;
  LabelImage map(w, h, 0);
  std::map<int, std::pair<double, Vec2>> pixels;  // label -> (count, sum of centres)
  auto set = [&](int i, int j, int label) {
    map.at(i, j) = static_cast<std::uint8_t>(label);
    // try_emplace with an explicit zero: a value-initialised Eigen vector is not zeroed.
    auto& [count, sum] = pixels.try_emplace(label, 0.0, Vec2::Zero()).first->second;
    count += 1.0;
    sum += Vec2(i, j);
  };
  for (int j = 7; j < 19; ++j)
    for (int i = 10; i < 25; ++i) set(i, j, 1);  // rectangle: columns 10..24, rows 7..18
  for (int j = 20; j < 46; ++j)
    for (int i = 30; i < 62; ++i) {
      const double r = std::hypot(i - 45.3, j - 32.8);
      if (r <= 11.7 && r > 3.2) set(i, j, 2);  // disc with a hole
    }
  for (int j = 24; j < 40; ++j)
    for (int i = 2; i < 20; ++i) set(i, j, i < 9 ? 3 : 4);  // two labels sharing an edge
  const ImageU8 sector(w, h, 255);
  const double mm_per_px = 0.5;
  const ImagePlane plane = scaled_plane(mm_per_px);
  for (const double tolerance_mm : {0.0, 0.2}) {
    std::vector<Repair> repairs;
    const auto slice = make_slice(map, sector, image_box(w, h), plane, tolerance_mm, &repairs,
                                  OutlineForm::kPixelEdges);
    ASSERT_TRUE(slice) << slice.message();
    EXPECT_TRUE(repairs.empty());
    EXPECT_TRUE(validate(*slice));
    for (const auto& [label, count_and_sum] : pixels) {
      const auto [area, centroid] = area_and_centroid(*slice, label);
      const Vec2 centre_px = count_and_sum.second / count_and_sum.first;
      const Vec2 expected = plane.to_plane(centre_px.x(), centre_px.y());
      const double pixel_mm2 = mm_per_px * mm_per_px;
      if (tolerance_mm == 0.0) {  // exact: to rounding
        EXPECT_NEAR(area, count_and_sum.first * pixel_mm2, 1e-9) << "label " << label;
        EXPECT_NEAR((centroid - expected).norm(), 0.0, 1e-9) << "label " << label;
      } else {  // simplified: within a small part of a pixel on average
        EXPECT_NEAR(area / (count_and_sum.first * pixel_mm2), 1.0, 0.03) << "label " << label;
        EXPECT_LT((centroid - expected).norm(), 0.05 * mm_per_px) << "label " << label;
      }
    }
    if (tolerance_mm == 0.0) {
      expect_on_pixel_edges(*slice, mm_per_px);
      // The rectangle's outline is its four corners on the pixel edges.
      const Region* rectangle = nullptr;
      for (const Region& r : slice->regions)
        if (r.label == 1) rectangle = &r;
      ASSERT_NE(rectangle, nullptr);
      const std::set<std::pair<double, double>> corners(
          {{1.0 + 9.5 * mm_per_px, -2.0 + 6.5 * mm_per_px},
           {1.0 + 24.5 * mm_per_px, -2.0 + 6.5 * mm_per_px},
           {1.0 + 24.5 * mm_per_px, -2.0 + 18.5 * mm_per_px},
           {1.0 + 9.5 * mm_per_px, -2.0 + 18.5 * mm_per_px}});
      std::set<std::pair<double, double>> outline;
      for (const Vec2& p : rectangle->outer) outline.insert({p.x(), p.y()});
      EXPECT_EQ(outline, corners);
    }
    // The two labels side by side share their edge at column 8.5: every corner of label 3's
    // outline on that line is a corner of label 4's.
    std::set<std::pair<double, double>> on_line_3, on_line_4;
    const double line_mm = 1.0 + 8.5 * mm_per_px;
    for (const Region& r : slice->regions)
      for (const Vec2& p : r.outer)
        if (std::abs(p.x() - line_mm) < 1e-9)
          (r.label == 3 ? on_line_3 : on_line_4).insert({p.x(), p.y()});
    EXPECT_FALSE(on_line_3.empty());
    EXPECT_EQ(on_line_3, on_line_4);
  }
  // Smoothed, the outlines keep the pixels' area and centroid: no inset, no shift.
  std::vector<Repair> repairs;
  const auto smooth = make_slice(map, sector, image_box(w, h), plane, 0.0, &repairs);
  ASSERT_TRUE(smooth) << smooth.message();
  EXPECT_TRUE(repairs.empty());
  EXPECT_GT(slanted_edges(*smooth), 0u);
  for (const auto& [label, count_and_sum] : pixels) {
    const auto [area, centroid] = area_and_centroid(*smooth, label);
    const Vec2 centre_px = count_and_sum.second / count_and_sum.first;
    const Vec2 expected = plane.to_plane(centre_px.x(), centre_px.y());
    EXPECT_NEAR(area / (count_and_sum.first * mm_per_px * mm_per_px), 1.0, 0.005)
        << "label " << label;
    EXPECT_LT((centroid - expected).norm(), 0.02 * mm_per_px) << "label " << label;
  }
}

// Where the ring's edges cross the vertical line at x (mm), strictly between rows y0 and y1.
std::vector<double> crossings_at(const Region& region, double x, double y0, double y1) {
  std::vector<double> ys;
  const Ring2& ring = region.outer;
  for (std::size_t k = 0; k < ring.size(); ++k) {
    const Vec2& a = ring[k];
    const Vec2& b = ring[(k + 1) % ring.size()];
    if ((a.x() < x) == (b.x() < x)) continue;
    const double y = a.y() + (x - a.x()) / (b.x() - a.x()) * (b.y() - a.y());
    if (y > y0 && y < y1) ys.push_back(y);
  }
  return ys;
}

TEST(Contours, SmoothOutlinesFollowASlantedBoundary) {
  // Two labels split by a line of slope 0.37 (a pixel is label 2 when its centre lies below
  // it). Along the pixels' edges their shared outline is a staircase that swings a quarter of
  // a pixel about the line on average; smoothed, it runs far closer to the line, and both
  // labels still share it exactly.
  const int w = 60, h = 40;
  const double slope = 0.37, offset = 8.3;  // row = slope * column + offset, in pixels
  LabelImage map(w, h, 1);
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i)
      if (j > slope * i + offset) map.at(i, j) = 2;
  const ImageU8 sector(w, h, 255);
  const double mm_per_px = 0.5;
  const ImagePlane plane = scaled_plane(mm_per_px);
  double mean_deviation_px[2] = {0.0, 0.0};
  for (const OutlineForm form : {OutlineForm::kPixelEdges, OutlineForm::kSmooth}) {
    std::vector<Repair> repairs;
    const auto slice = make_slice(map, sector, image_box(w, h), plane, 0.0, &repairs, form);
    ASSERT_TRUE(slice) << slice.message();
    EXPECT_TRUE(repairs.empty());
    ASSERT_EQ(slice->regions.size(), 2u);
    const Region& above = slice->regions[0].label == 1 ? slice->regions[0] : slice->regions[1];
    const Region& below = slice->regions[0].label == 1 ? slice->regions[1] : slice->regions[0];
    // Columns 2..w-3 (away from the image's sides), sampled every 0.01 px.
    // Rows 1..h-2: the outlines along the image's top and bottom are smoothed too.
    const double top_mm = plane.to_plane(0.0, 1.0).y(),
                 bottom_mm = plane.to_plane(0.0, h - 2.0).y();
    double sum = 0.0;
    int samples = 0;
    for (double i = 2.0; i <= w - 3.0; i += 0.01, ++samples) {
      const double x_mm = plane.to_plane(i, 0.0).x();
      const std::vector<double> ya = crossings_at(above, x_mm, top_mm, bottom_mm);
      const std::vector<double> yb = crossings_at(below, x_mm, top_mm, bottom_mm);
      // One shared outline (which may wind back a little where a step was smoothed).
      ASSERT_FALSE(ya.empty()) << "column " << i;
      ASSERT_EQ(ya.size(), yb.size()) << "column " << i;
      double mean_mm = 0.0;
      for (std::size_t k = 0; k < ya.size(); ++k) {
        EXPECT_NEAR(ya[k], yb[ya.size() - 1 - k], 1e-9) << "column " << i;
        mean_mm += ya[k] / static_cast<double>(ya.size());
      }
      const double row = (mean_mm + 2.0) / mm_per_px;  // back to pixel rows
      sum += std::abs(row - (slope * i + offset));
    }
    mean_deviation_px[form == OutlineForm::kSmooth] = sum / samples;
  }
  EXPECT_GT(mean_deviation_px[0], 0.2);                         // the staircase
  EXPECT_LT(mean_deviation_px[1], 0.5 * mean_deviation_px[0]);  // 0.10 against 0.26 px
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
}  // namespace sonoshape::segmentation::contours_test
