// The blooming correction moves a boundary by the shift of the grey midpoint into the darker
// tissue to a fraction of a pixel: at 0.63 mm a pixel (the default scan) the shift is about half
// a pixel, which a rule of whole pixels rounded to nothing.
#include "blooming.hpp"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

namespace sonoshape::segmentation::detail::blooming_test {
namespace {

constexpr std::uint8_t kDark = 0, kBright = 2;
constexpr double kDarkGrey = 89.0, kBrightGrey = 133.0, kPsfMm = 0.46, kRangeDb = 50.0;

// A vertical boundary: the grey rises linearly across it, the midpoint of the two classes at
// column `midpoint_px` (a fraction of a pixel); every pixel right of the midpoint is bright.
struct Edge {
  cv::Mat map, grey, sector;
};
Edge edge(double midpoint_px, double slope_grey_per_px) {
  Edge e;
  const int w = 24, h = 8;
  e.grey.create(h, w, CV_32F);
  e.map.create(h, w, CV_8U);
  e.sector = cv::Mat(h, w, CV_8U, cv::Scalar(255));
  const double midpoint = 0.5 * (kDarkGrey + kBrightGrey);
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      e.grey.at<float>(j, i) = static_cast<float>(midpoint + slope_grey_per_px * (i - midpoint_px));
      e.map.at<std::uint8_t>(j, i) = i > midpoint_px ? kBright : kDark;
    }
  return e;
}

// The first bright column of the middle row.
int first_bright(const cv::Mat& map) {
  for (int i = 0; i < map.cols; ++i)
    if (map.at<std::uint8_t>(map.rows / 2, i) == kBright) return i;
  return map.cols;
}

TEST(Blooming, MovesTheBoundaryByAFractionOfAPixel) {
  const double px_mm = 0.63;
  const double shift_px = blooming_shift_mm(kDarkGrey, kBrightGrey, kPsfMm, kRangeDb) / px_mm;
  ASSERT_GT(shift_px, 0.3);
  ASSERT_LT(shift_px, 0.7);
  const std::vector<GreyClass> classes{{kDark, kDarkGrey}, {kBright, kBrightGrey}};
  // Midpoint 0.2 px left of column 10: column 10's centre lies within the shift, so it goes
  // back to the dark tissue; column 11's does not.
  Edge near = edge(9.8, 10.0);
  undo_blooming(near.map, near.sector, near.grey, classes, kPsfMm, kRangeDb, px_mm, -1);
  EXPECT_EQ(first_bright(near.map), 11);
  // Midpoint 0.9 px left of column 10: column 10's centre lies beyond the shift and stays.
  Edge far = edge(9.1, 10.0);
  undo_blooming(far.map, far.sector, far.grey, classes, kPsfMm, kRangeDb, px_mm, -1);
  EXPECT_EQ(first_bright(far.map), 10);
  // No blur given: nothing moves.
  Edge off = edge(9.8, 10.0);
  undo_blooming(off.map, off.sector, off.grey, classes, 0.0, kRangeDb, px_mm, -1);
  EXPECT_EQ(first_bright(off.map), 10);
  // The excluded class (a bone's section) keeps its pixels.
  Edge bone = edge(9.8, 10.0);
  undo_blooming(bone.map, bone.sector, bone.grey, classes, kPsfMm, kRangeDb, px_mm, kBright);
  EXPECT_EQ(first_bright(bone.map), 10);
}

}  // namespace
}  // namespace sonoshape::segmentation::detail::blooming_test
