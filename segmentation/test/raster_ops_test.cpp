// The segmenter's fast morphology gives exactly what OpenCV's gives, on masks with blobs, specks,
// one-pixel lines and set pixels on the image border; its Gaussian differs from OpenCV's by float
// rounding only, and its AVX2 and plain paths agree bit for bit.
#include "raster_ops.hpp"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

namespace sonoshape::segmentation::detail::raster_ops_test {
namespace {

// Blobs of several sizes (a thresholded blur of noise), specks, a line and the border rows.
cv::Mat test_mask(int w, int h, unsigned seed) {
  cv::RNG rng(seed);
  cv::Mat noise(h, w, CV_32F);
  rng.fill(noise, cv::RNG::UNIFORM, 0.0, 1.0);
  cv::Mat blobs;
  cv::GaussianBlur(noise, blobs, cv::Size(0, 0), 3.0);
  cv::Mat mask = blobs > 0.52;
  mask.setTo(255, noise > 0.995);  // specks
  cv::line(mask, {2, h / 3}, {w - 3, h / 2}, cv::Scalar(255), 1);
  mask.row(0).setTo(255);
  mask.col(w - 1).setTo(0);
  mask(cv::Rect(0, h - 5, w / 2, 5)).setTo(255);
  return mask;
}

std::vector<std::pair<std::string, cv::Mat>> kernels() {
  std::vector<std::pair<std::string, cv::Mat>> out;
  for (const int r : {0, 1, 2, 3, 7, 19})
    out.emplace_back("disk " + std::to_string(r),
                     cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
  out.emplace_back("ellipse 9x5", cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(9, 5)));
  out.emplace_back("rect 5x3", cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 3)));
  out.emplace_back("cross 5", cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(5, 5)));
  cv::Mat skew = cv::Mat::zeros(3, 3, CV_8U);  // not centred runs: OpenCV's own code
  skew.at<std::uint8_t>(0, 0) = skew.at<std::uint8_t>(1, 1) = skew.at<std::uint8_t>(2, 1) = 1;
  out.emplace_back("skewed", skew);
  return out;
}

int differing(const cv::Mat& a, const cv::Mat& b) { return cv::countNonZero(a != b); }

TEST(RasterOps, MorphologyByRunsEqualsOpenCv) {
  for (const unsigned seed : {1u, 2u, 3u}) {
    const cv::Mat mask = test_mask(97 + 40 * static_cast<int>(seed), 61, seed);
    for (const auto& [name, kernel] : kernels()) {
      SCOPED_TRACE(name + ", seed " + std::to_string(seed));
      cv::Mat dilated, eroded, opened;
      cv::dilate(mask, dilated, kernel);
      cv::erode(mask, eroded, kernel);
      cv::morphologyEx(mask, opened, cv::MORPH_OPEN, kernel);
      EXPECT_EQ(differing(dilate_runs(mask, kernel), dilated), 0);
      EXPECT_EQ(differing(erode_runs(mask, kernel), eroded), 0);
      EXPECT_EQ(differing(open_runs(mask, kernel), opened), 0);
    }
  }
}

TEST(RasterOps, EmptyAndFullMasksStaySo) {
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(7, 7));
  const cv::Mat empty = cv::Mat::zeros(20, 30, CV_8U), full(20, 30, CV_8U, cv::Scalar(255));
  EXPECT_EQ(cv::countNonZero(dilate_runs(empty, kernel)), 0);
  EXPECT_EQ(cv::countNonZero(erode_runs(full, kernel)), 600);  // the border erodes nothing
  EXPECT_EQ(cv::countNonZero(open_runs(full, kernel)), 600);
}

TEST(RasterOps, GaussianMatchesOpenCvAndItsPlainPathBitForBit) {
  const int threads = cv::getNumThreads();
  cv::RNG rng(7);
  cv::Mat image(301, 173, CV_32F);
  rng.fill(image, cv::RNG::UNIFORM, 0.0, 255.0);
  image(cv::Rect(0, 0, 60, 301)).setTo(0.0);  // a black side, as outside a sector
  for (const int pool : {1, 2}) {
    cv::setNumThreads(pool);
    // Kernels from a few pixels to wider than the image (241 taps for 173 columns).
    for (const double sigma : {0.8, 3.0, 10.0, 12.5, 30.0}) {
      SCOPED_TRACE("threads " + std::to_string(pool) + ", sigma " + std::to_string(sigma));
      cv::Mat expected;
      cv::GaussianBlur(image, expected, cv::Size(0, 0), sigma);
      const cv::Mat fast = gaussian_blur_rows(image, sigma);
      EXPECT_LE(cv::norm(fast, expected, cv::NORM_INF), 255.0 * 1e-6);
      EXPECT_EQ(cv::norm(fast, gaussian_blur_rows(image, sigma, {}, false), cv::NORM_INF), 0.0);
      // Only a region, at odd offsets and sizes (SIMD blocks fall elsewhere), zero elsewhere.
      const cv::Rect region(37, 21, 101, 203);
      const cv::Mat part = gaussian_blur_rows(image, sigma, region);
      EXPECT_EQ(cv::norm(part(region), fast(region), cv::NORM_INF), 0.0);
      EXPECT_EQ(cv::countNonZero(part) - cv::countNonZero(part(region)), 0);
    }
  }
  cv::setNumThreads(threads);
}

}  // namespace
}  // namespace sonoshape::segmentation::detail::raster_ops_test
