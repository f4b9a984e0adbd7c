#include "blooming.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace sonoshape::segmentation::detail {
namespace {

// Inverse of the standard normal distribution function by bisection (|z| < 8 is plenty).
double inverse_normal(double p) {
  double lo = -8.0, hi = 8.0;
  for (int k = 0; k < 60; ++k) {
    const double mid = 0.5 * (lo + hi);
    (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// The pixels whose cv::distanceTransform distance (DIST_L2, DIST_MASK_5) to the nearest set
// pixel of `mask` (CV_8U) is at most `limit_px`, without the transform of the whole frame: the
// mask dilated by that distance's own ball of radius limit_px. The 5x5 chamfer distance is a
// minimum over the set pixels of a function of the offset alone (integer weights, scaled), so
// the two agree exactly; the ball is taken from distanceTransform itself, on an image holding
// its centre alone. The chamfer distance is at least the larger of |dx| and |dy|, so the ball
// fits in a square of half-width floor(limit_px).
cv::Mat within_distance(const cv::Mat& mask, double limit_px) {
  const int r = static_cast<int>(std::floor(std::max(0.0, limit_px))) + 1;
  cv::Mat centre(2 * r + 1, 2 * r + 1, CV_8U, cv::Scalar(255)), distance;
  centre.at<std::uint8_t>(r, r) = 0;
  cv::distanceTransform(centre, distance, cv::DIST_L2, cv::DIST_MASK_5);
  const cv::Mat ball = distance <= limit_px;
  cv::Mat within;
  cv::dilate(mask, within, ball);
  return within;
}

}  // namespace

double blooming_shift_mm(double dark_grey, double bright_grey, double psf_sigma_mm,
                         double dynamic_range_db) {
  if (!(bright_grey > dark_grey) || !(psf_sigma_mm > 0.0) || !(dynamic_range_db > 0.0)) return 0.0;
  const double ratio = std::pow(10.0, (bright_grey - dark_grey) * dynamic_range_db / 255.0 / 10.0);
  return -psf_sigma_mm * inverse_normal(1.0 / (std::sqrt(ratio) + 1.0));
}

void undo_blooming(cv::Mat& map, const cv::Mat& sector, const cv::Mat& grey,
                   const std::vector<GreyClass>& classes, double psf_sigma_mm,
                   double dynamic_range_db, double spacing_mm, int excluded) {
  if (!(psf_sigma_mm > 0.0)) return;
  const cv::Mat original = map.clone();
  // The grey's slope (per pixel) across the boundary: the distance from a pixel's centre to the
  // grey midpoint between two classes is its grey's excess over the midpoint over that slope.
  cv::Mat dx, dy, slope;
  cv::Sobel(grey, dx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(grey, dy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  cv::magnitude(dx, dy, slope);
  for (const GreyClass& bright : classes) {
    if (bright.value == excluded) continue;
    const cv::Mat bright_mask = (original == bright.value) & sector;
    if (cv::countNonZero(bright_mask) == 0) continue;
    std::vector<GreyClass> darker;
    for (const GreyClass& c : classes)
      if (c.grey_mean < bright.grey_mean && c.value != excluded) darker.push_back(c);
    std::sort(darker.begin(), darker.end(), [](const GreyClass& a, const GreyClass& b) {
      return a.grey_mean > b.grey_mean;  // the nearest in grey first
    });
    cv::Mat taken(map.size(), CV_8U, cv::Scalar(0));
    for (const GreyClass& dark : darker) {
      const double shift_px =
          blooming_shift_mm(dark.grey_mean, bright.grey_mean, psf_sigma_mm, dynamic_range_db) /
          spacing_mm;
      if (shift_px <= 0.0) continue;
      const float midpoint = static_cast<float>(0.5 * (dark.grey_mean + bright.grey_mean));
      // Only the bright pixels near a dark one can lie within the shift of the boundary.
      const cv::Mat near =
          bright_mask & ~taken & within_distance(original == dark.value, shift_px + 1.5);
      for (int j = 0; j < map.rows; ++j) {
        const std::uint8_t* n = near.ptr<std::uint8_t>(j);
        const float* g = grey.ptr<float>(j);
        const float* s = slope.ptr<float>(j);
        std::uint8_t* m = map.ptr<std::uint8_t>(j);
        std::uint8_t* t = taken.ptr<std::uint8_t>(j);
        for (int i = 0; i < map.cols; ++i)
          // The grey midpoint lies shift_px into the darker tissue: a bright pixel whose centre
          // is nearer the midpoint than that lies in the darker tissue (to a fraction of a
          // pixel, where a rule of whole pixels moved nothing at 0.63 mm a pixel).
          if (n[i] && s[i] > 0.0f && g[i] - midpoint < shift_px * s[i]) {
            m[i] = dark.value;
            t[i] = 255;
          }
      }
    }
  }
}

}  // namespace sonoshape::segmentation::detail
