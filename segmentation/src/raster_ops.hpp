#pragma once
// Faster equivalents of the OpenCV calls on whole frames that dominate the segmenter's time
// (docs/benchmarks.md, "Segmentation speed"). Each gives exactly what the OpenCV call it
// replaces gives (raster_ops_test.cpp compares them); internal to the segmentation module.
#include <opencv2/core.hpp>

namespace sonoshape::seg::detail {

/// cv::dilate(mask, kernel) with OpenCV's default anchor and border (outside the image adds
/// nothing), for a 0/255 CV_8U mask and a kernel whose rows are runs centred on the anchor
/// column (cv::getStructuringElement's ellipses, rectangles and crosses of odd size). Runs in
/// time proportional to pixels x kernel rows instead of pixels x kernel points; any other
/// kernel falls back to cv::dilate. Returns a 0/255 CV_8U mask.
cv::Mat dilate_runs(const cv::Mat& mask, const cv::Mat& kernel);

/// cv::erode(mask, kernel) under the same conditions (outside the image erodes nothing).
cv::Mat erode_runs(const cv::Mat& mask, const cv::Mat& kernel);

/// cv::morphologyEx(mask, MORPH_OPEN, kernel): erode_runs, then dilate_runs.
cv::Mat open_runs(const cv::Mat& mask, const cv::Mat& kernel);

/// cv::GaussianBlur(src, dst, Size(0, 0), sigma) with OpenCV's default border, computed in
/// horizontal stripes on OpenCV's thread pool (cv::parallel_for_; one stripe per thread).
/// Each stripe reads the rows around it from the whole image, so the result is the same,
/// bit for bit, as one call. `src` is CV_32F with one channel.
cv::Mat gaussian_blur_rows(const cv::Mat& src, double sigma);

}  // namespace sonoshape::seg::detail
