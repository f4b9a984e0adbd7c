#include "boundary_echo.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace sonoshape::segmentation::detail {
namespace {

// Lengths (mm) of the echo test: the average across the beam, and how far above and below the
// tissue on each side is read (beyond the point-spread function's axial extent).
constexpr double kAcrossMm = 2.0;
constexpr double kAsideMm = 1.0;

}  // namespace

cv::Mat fill_boundary_echoes(const cv::Mat& grey, const cv::Mat& sector, double spacing_mm,
                             double contrast_grey) {
  const int across_px =
      std::max(3, 2 * static_cast<int>(std::lround(0.5 * kAcrossMm / spacing_mm)) + 1);
  const int aside_px = std::max(1, static_cast<int>(std::lround(kAsideMm / spacing_mm)));
  const int longest_run_px = 2 * aside_px + 1;
  cv::Mat average;
  grey.convertTo(average, CV_32F);
  cv::blur(average, average, cv::Size(across_px, 1), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  const int w = grey.cols, h = grey.rows;
  cv::Mat echo(h, w, CV_8U, cv::Scalar(0));
  for (int j = aside_px; j + aside_px < h; ++j) {
    const float* above = average.ptr<float>(j - aside_px);
    const float* here = average.ptr<float>(j);
    const float* below = average.ptr<float>(j + aside_px);
    const std::uint8_t* in = sector.ptr<std::uint8_t>(j);
    std::uint8_t* e = echo.ptr<std::uint8_t>(j);
    for (int i = 0; i < w; ++i)
      e[i] = in[i] && here[i] - std::max(above[i], below[i]) > contrast_grey ? 255 : 0;
  }
  cv::Mat out = grey.clone();
  for (int i = 0; i < w; ++i)
    for (int j = 0; j < h; ++j) {
      if (!echo.at<std::uint8_t>(j, i)) continue;
      int last = j;
      while (last + 1 < h && echo.at<std::uint8_t>(last + 1, i)) ++last;
      const int top = j - 1, bottom = last + 1;
      if (last - j + 1 <= longest_run_px && top >= 0 && bottom < h &&
          sector.at<std::uint8_t>(top, i) && sector.at<std::uint8_t>(bottom, i)) {
        const float a = average.at<float>(top, i), b = average.at<float>(bottom, i);
        for (int k = j; k <= last; ++k) {
          const float t = static_cast<float>(k - top) / static_cast<float>(bottom - top);
          out.at<std::uint8_t>(k, i) = cv::saturate_cast<std::uint8_t>((1.0f - t) * a + t * b);
        }
      }
      j = last;
    }
  return out;
}

}  // namespace sonoshape::segmentation::detail
