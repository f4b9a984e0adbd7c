#include "raster_ops.hpp"

#include <algorithm>
#include <cstdint>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <vector>

namespace sonoshape::seg::detail {
namespace {

// Row distances are bytes (twice the SIMD width of 16 bits); a kernel row wider than this falls
// back to OpenCV.
constexpr std::uint8_t kFar = std::numeric_limits<std::uint8_t>::max();

// Half-widths of the kernel's rows (-1 for an empty row), or none when a row is not one run
// centred on the anchor column (then only OpenCV's general code is right).
std::optional<std::vector<int>> row_half_widths(const cv::Mat& kernel) {
  if (kernel.type() != CV_8U || kernel.rows % 2 == 0 || kernel.cols % 2 == 0 || kernel.cols >= kFar)
    return std::nullopt;
  const int centre = kernel.cols / 2;
  std::vector<int> half(static_cast<std::size_t>(kernel.rows), -1);
  for (int k = 0; k < kernel.rows; ++k) {
    const std::uint8_t* row = kernel.ptr<std::uint8_t>(k);
    const std::uint8_t* first = std::find_if(row, row + kernel.cols, [](auto v) { return v; });
    if (first == row + kernel.cols) continue;
    const int from = static_cast<int>(first - row);
    const int to = kernel.cols - 1 - from;
    if (std::any_of(row, row + from, [](auto v) { return v; }) ||
        std::any_of(row + from, row + to + 1, [](auto v) { return !v; }) ||
        std::any_of(row + to + 1, row + kernel.cols, [](auto v) { return v; }))
      return std::nullopt;
    half[static_cast<std::size_t>(k)] = centre - from;
  }
  return half;
}

// hits[x] |= distance[x] <= reach: the inner loop of morph_runs, compiled for AVX2 as well
// (chosen at run time) since it is most of the time.
__attribute__((target_clones("avx2", "default"))) void mark_within(std::uint8_t* hits,
                                                                   const std::uint8_t* distance,
                                                                   std::uint8_t reach, int n) {
  for (int x = 0; x < n; ++x) hits[x] |= static_cast<std::uint8_t>(distance[x] <= reach);
}

// Dilation of the set pixels by the kernel rows' runs; with `erode`, the set pixels are the
// mask's zeros and the result is inverted (erosion is the dilation of the complement, and
// outside the image is in neither). Per row, the distance to the nearest set pixel of the row;
// a pixel is then reached when some kernel row's source row has a set pixel within that row's
// half-width. The inner loops are branch-free and vectorise.
cv::Mat morph_runs(const cv::Mat& mask, const std::vector<int>& half, bool erode) {
  CV_Assert(mask.type() == CV_8U);
  const int w = mask.cols, h = mask.rows, anchor = static_cast<int>(half.size()) / 2;
  std::vector<std::uint8_t> distance(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  std::vector<bool> row_has_set(static_cast<std::size_t>(h));
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* src = mask.ptr<std::uint8_t>(y);
    std::uint8_t* d = distance.data() + static_cast<std::ptrdiff_t>(y) * w;
    std::uint8_t run = kFar;
    bool any = false;
    for (int x = 0; x < w; ++x) {
      const bool set = (src[x] != 0) != erode;
      run = set ? 0 : run == kFar ? kFar : static_cast<std::uint8_t>(run + 1);
      d[x] = run;
      any = any || set;
    }
    run = kFar;
    for (int x = w - 1; x >= 0; --x) {
      const bool set = (src[x] != 0) != erode;
      run = set ? 0 : run == kFar ? kFar : static_cast<std::uint8_t>(run + 1);
      d[x] = std::min(d[x], run);
    }
    row_has_set[static_cast<std::size_t>(y)] = any;
  }
  cv::Mat out(h, w, CV_8U);
  std::vector<std::uint8_t> hit(static_cast<std::size_t>(w));
  const std::uint8_t reached = erode ? 0 : 255, missed = erode ? 255 : 0;
  for (int y = 0; y < h; ++y) {
    std::fill(hit.begin(), hit.end(), std::uint8_t{0});
    std::uint8_t* hits = hit.data();
    for (int k = 0; k < static_cast<int>(half.size()); ++k) {
      const int source = y + k - anchor;
      const int r = half[static_cast<std::size_t>(k)];
      if (source < 0 || source >= h || r < 0 || !row_has_set[static_cast<std::size_t>(source)])
        continue;
      mark_within(hits, distance.data() + static_cast<std::ptrdiff_t>(source) * w,
                  static_cast<std::uint8_t>(r), w);
    }
    std::uint8_t* o = out.ptr<std::uint8_t>(y);
    for (int x = 0; x < w; ++x) o[x] = hits[x] ? reached : missed;
  }
  return out;
}

}  // namespace

cv::Mat dilate_runs(const cv::Mat& mask, const cv::Mat& kernel) {
  if (const auto half = row_half_widths(kernel)) return morph_runs(mask, *half, false);
  cv::Mat out;
  cv::dilate(mask, out, kernel);
  return out;
}

cv::Mat erode_runs(const cv::Mat& mask, const cv::Mat& kernel) {
  if (const auto half = row_half_widths(kernel)) return morph_runs(mask, *half, true);
  cv::Mat out;
  cv::erode(mask, out, kernel);
  return out;
}

cv::Mat open_runs(const cv::Mat& mask, const cv::Mat& kernel) {
  return dilate_runs(erode_runs(mask, kernel), kernel);
}

cv::Mat gaussian_blur_rows(const cv::Mat& src, double sigma) {
  CV_Assert(src.type() == CV_32F);
  cv::Mat dst(src.size(), src.type());
  // Stripes much thinner than the kernel would filter the rows around them more than once.
  const int stripes = std::clamp(cv::getNumThreads(), 1, std::max(1, src.rows / 64));
  cv::parallel_for_(cv::Range(0, stripes), [&](const cv::Range& range) {
    for (int s = range.start; s < range.end; ++s) {
      const int from = src.rows * s / stripes, to = src.rows * (s + 1) / stripes;
      cv::Mat out = dst.rowRange(from, to);  // a view: GaussianBlur writes into dst
      // A row range is a view into src, so the blur reads the real rows beyond it.
      cv::GaussianBlur(src.rowRange(from, to), out, cv::Size(0, 0), sigma);
    }
  });
  return dst;
}

}  // namespace sonoshape::seg::detail
