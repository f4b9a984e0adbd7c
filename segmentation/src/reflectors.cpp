#include "reflectors.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "sonoshape/core/image.hpp"

namespace sonoshape::segmentation::detail {
namespace {

// The width of the ellipse is fitted within these multiples of the band's half width: a band
// is at least the section's visible top, and a section wider than three times the band would
// be a guess beyond what the image shows.
constexpr double kMinWidthFactor = 1.0;
constexpr double kMaxWidthFactor = 3.0;
// Columns whose surface lies within this many rows of the apex share the apex (their mean is
// the section's centre column).
constexpr int kApexRowsPx = 1;

struct Section {
  double centre_x = 0.0, centre_y = 0.0;  // px
  double half_width = 0.0, half_height = 0.0;
};

// The ellipse of one band, from the surface depth of each of its columns (rows, sub-pixel; NaN:
// none): the apex is the shallowest surface and the centre lies half the thickness below it,
// under the columns at the apex (the arc a fan sees can reach further down one side than the
// other, so its column span is no measure of the centre). A point (x, y) of the upper arc
// satisfies (x - cx)^2 = a^2 (1 - ((cy - y) / b)^2); a^2 is the least-squares solution over the
// columns. The arc drops only a pixel or two over the band at a coarse pixel size, so whole
// rows would flatten it (and a flat arc reads as a narrow section): the depths are sub-pixel.
Section fit_section(const std::vector<double>& surface_row, int first_column, double thickness_px) {
  Section s;
  s.half_height = 0.5 * thickness_px;
  double apex = std::numeric_limits<double>::infinity();
  int first = -1, last = -1;
  for (std::size_t k = 0; k < surface_row.size(); ++k)
    if (!std::isnan(surface_row[k])) {
      apex = std::min(apex, surface_row[k]);
      if (first < 0) first = static_cast<int>(k);
      last = static_cast<int>(k);
    }
  double apex_sum = 0.0;
  int apex_columns = 0;
  for (std::size_t k = 0; k < surface_row.size(); ++k)
    if (!std::isnan(surface_row[k]) && surface_row[k] <= apex + kApexRowsPx) {
      apex_sum += static_cast<double>(k);
      ++apex_columns;
    }
  s.centre_x = first_column + apex_sum / apex_columns;
  s.centre_y = apex + s.half_height;
  const double half_band = 0.5 * (last - first + 1);
  double num = 0.0, den = 0.0;
  for (std::size_t k = 0; k < surface_row.size(); ++k) {
    if (std::isnan(surface_row[k])) continue;
    const double dx = first_column + static_cast<double>(k) - s.centre_x;
    const double dy = std::min(1.0, (s.centre_y - surface_row[k]) / s.half_height);
    const double u = 1.0 - dy * dy;
    num += dx * dx * u;
    den += u * u;
  }
  const double fitted = den > 0.0 ? std::sqrt(num / den) : half_band;
  s.half_width = std::clamp(fitted, kMinWidthFactor * half_band, kMaxWidthFactor * half_band);
  // A long bone's section is at least as wide as thick (an oblique cut only widens it); a
  // narrower one is a cut through its rounded end, as deep as it is wide.
  if (s.half_width < s.half_height) {
    s.centre_y -= s.half_height - s.half_width;
    s.half_height = s.half_width;
  }
  return s;
}

// The band's pixels above the section's arc are the echo spread upwards by the point-spread
// function, not bone: each goes to the label just above the band's top in its column (the
// tissue over the bone), when there is one.
void trim_band_above(cv::Mat& map, const cv::Mat& components, int c, const cv::Mat& stats,
                     const Section& s, std::uint8_t label) {
  const int x0 = stats.at<int>(c, cv::CC_STAT_LEFT), y0 = stats.at<int>(c, cv::CC_STAT_TOP);
  const int w = stats.at<int>(c, cv::CC_STAT_WIDTH), h = stats.at<int>(c, cv::CC_STAT_HEIGHT);
  for (int i = x0; i < x0 + w; ++i) {
    int top = -1;
    for (int j = y0; j < y0 + h && top < 0; ++j)
      if (components.at<int>(j, i) == c) top = j;
    if (top <= 0) continue;
    const std::uint8_t above = map.at<std::uint8_t>(top - 1, i);
    if (above == label || above == kLabelPixelUnknown) continue;
    const double dx = (i - s.centre_x) / s.half_width;
    for (int j = top; j < y0 + h && j < s.centre_y; ++j) {
      const double dy = (j - s.centre_y) / s.half_height;
      if (components.at<int>(j, i) == c && dx * dx + dy * dy > 1.0)
        map.at<std::uint8_t>(j, i) = above;
    }
  }
}

}  // namespace

void fill_reflector_sections(cv::Mat& map, const cv::Mat& grey, const cv::Mat& sector,
                             std::uint8_t label, double thickness_px, int min_width_px) {
  if (!(thickness_px > 0.0)) return;
  const cv::Mat band = map == label;
  cv::Mat components, stats, centroids;
  const int n = cv::connectedComponentsWithStats(band, components, stats, centroids, 8, CV_32S);
  std::vector<Section> sections;
  for (int c = 1; c < n; ++c) {
    const int x0 = stats.at<int>(c, cv::CC_STAT_LEFT), y0 = stats.at<int>(c, cv::CC_STAT_TOP);
    const int w = stats.at<int>(c, cv::CC_STAT_WIDTH), h = stats.at<int>(c, cv::CC_STAT_HEIGHT);
    if (w < min_width_px) continue;
    // The surface is where the echo peaks down each column: the point-spread function spreads
    // a specular echo evenly about the boundary, so the band's top lies above it. Its depth is
    // the grey-weighted mean row of the band's pixels in the column (sub-pixel).
    std::vector<double> weighted_rows(static_cast<std::size_t>(w), 0.0);
    std::vector<double> weights(static_cast<std::size_t>(w), 0.0);
    for (int j = y0; j < y0 + h; ++j) {
      const int* row = components.ptr<int>(j);
      const float* g = grey.ptr<float>(j);
      for (int i = x0; i < x0 + w; ++i) {
        const auto k = static_cast<std::size_t>(i - x0);
        if (row[i] != c) continue;
        const double weight = std::max(1e-3, static_cast<double>(g[i]));
        weighted_rows[k] += weight * j;
        weights[k] += weight;
      }
    }
    std::vector<double> surface_row(static_cast<std::size_t>(w),
                                    std::numeric_limits<double>::quiet_NaN());
    for (std::size_t k = 0; k < surface_row.size(); ++k)
      if (weights[k] > 0.0) surface_row[k] = weighted_rows[k] / weights[k];
    sections.push_back(fit_section(surface_row, x0, thickness_px));
    trim_band_above(map, components, c, stats, sections.back(), label);
  }
  for (const Section& s : sections) {
    const int i0 = std::max(0, static_cast<int>(std::floor(s.centre_x - s.half_width)));
    const int i1 = std::min(map.cols - 1, static_cast<int>(std::ceil(s.centre_x + s.half_width)));
    const int j0 = std::max(0, static_cast<int>(std::floor(s.centre_y - s.half_height)));
    const int j1 = std::min(map.rows - 1, static_cast<int>(std::ceil(s.centre_y + s.half_height)));
    for (int j = j0; j <= j1; ++j) {
      const double dy = (j - s.centre_y) / s.half_height;
      std::uint8_t* out = map.ptr<std::uint8_t>(j);
      const std::uint8_t* in = sector.ptr<std::uint8_t>(j);
      for (int i = i0; i <= i1; ++i) {
        const double dx = (i - s.centre_x) / s.half_width;
        if (in[i] && dx * dx + dy * dy <= 1.0) out[i] = label;
      }
    }
  }
}

}  // namespace sonoshape::segmentation::detail
