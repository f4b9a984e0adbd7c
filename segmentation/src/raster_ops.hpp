#pragma once
// Faster equivalents of the OpenCV calls on whole frames that dominate the segmenter's time
// (docs/benchmarks.md, "Segmentation speed"); raster_ops_test.cpp compares them with OpenCV.
// Internal to the segmentation module.
#include <opencv2/core.hpp>

#include "sonoshape/core/image.hpp"

namespace sonoshape::segmentation::detail {

/// The frame as a CV_8U matrix over its own pixels (no copy): for reading only.
inline cv::Mat wrap(const ImageU8& image) {
  return cv::Mat(image.height, image.width, CV_8U, const_cast<std::uint8_t*>(image.pixels.data()));
}

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

/// The Gaussian blur of cv::GaussianBlur(src, dst, Size(0, 0), sigma): OpenCV's kernel (size
/// round(8 sigma + 1) | 1) and border (BORDER_REFLECT_101), rows then columns, but summed
/// symmetric taps first and 32 pixels at a time (AVX2 where the processor has it: about twice
/// OpenCV's speed), so it differs from OpenCV by float rounding (below 1e-4 of the values'
/// range). The AVX2 and the plain path (`simd` false) give the same bits: no fused
/// multiply-add, the same order of operations. Computed only inside `region` (zero outside it;
/// the whole image when empty), the rows spread over OpenCV's threads. `src` is CV_32F with one
/// channel.
cv::Mat gaussian_blur_rows(const cv::Mat& src, double sigma, cv::Rect region = {},
                           bool simd = true);

}  // namespace sonoshape::segmentation::detail
