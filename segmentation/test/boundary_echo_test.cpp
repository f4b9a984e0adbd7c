// A boundary's specular echo (a line brighter than the tissues on both sides) is filled from both
// sides, so that the boundary lies at its middle; a boundary without one is left as it is.
#include "boundary_echo.hpp"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

namespace sonoshape::segmentation::detail::boundary_echo_test {
namespace {

constexpr double kPxMm = 0.63;  // the default scan's pixels: lines are read 2 px above and below
constexpr double kContrast = 25.0;

// Rows above `boundary` are grey `above`, the others `below`; row `line` (when in the image)
// is `line_grey`.
cv::Mat column_image(int boundary, int line, int line_grey) {
  cv::Mat grey(40, 32, CV_8U);
  for (int j = 0; j < grey.rows; ++j) grey.row(j).setTo(j < boundary ? 90 : 40);
  if (line >= 0) grey.row(line).setTo(line_grey);
  return grey;
}

TEST(BoundaryEcho, FillsALineBetweenTwoTissuesFromBothSides) {
  const cv::Mat sector(40, 32, CV_8U, cv::Scalar(255));
  const cv::Mat grey = column_image(20, 20, 170);
  const cv::Mat filled = fill_boundary_echoes(grey, sector, kPxMm, kContrast);
  // The line's pixel takes the middle of the tissues above (90) and below (40).
  EXPECT_EQ(filled.at<std::uint8_t>(20, 16), 65);
  cv::Mat changed = filled != grey;
  EXPECT_EQ(cv::countNonZero(changed.row(20)), grey.cols);
  changed.row(20).setTo(0);
  EXPECT_EQ(cv::countNonZero(changed), 0);
  // A line that stands out by less than the contrast stays.
  const cv::Mat faint = column_image(20, 20, 110);
  EXPECT_EQ(cv::countNonZero(fill_boundary_echoes(faint, sector, kPxMm, kContrast) != faint), 0);
  // Outside the sector nothing changes.
  const cv::Mat none(40, 32, CV_8U, cv::Scalar(0));
  EXPECT_EQ(cv::countNonZero(fill_boundary_echoes(grey, none, kPxMm, kContrast) != grey), 0);
}

TEST(BoundaryEcho, LeavesABoundaryWithoutAnEchoAndWideBands) {
  const cv::Mat sector(40, 32, CV_8U, cv::Scalar(255));
  const cv::Mat step = column_image(20, -1, 0);
  EXPECT_EQ(cv::countNonZero(fill_boundary_echoes(step, sector, kPxMm, kContrast) != step), 0);
  // A bright band wider than a line (8 px, 5 mm) is tissue, not an echo.
  cv::Mat band = column_image(20, -1, 0);
  band.rowRange(10, 18).setTo(170);
  EXPECT_EQ(cv::countNonZero(fill_boundary_echoes(band, sector, kPxMm, kContrast) != band), 0);
}

}  // namespace
}  // namespace sonoshape::segmentation::detail::boundary_echo_test
