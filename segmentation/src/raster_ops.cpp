#include "raster_ops.hpp"

#include <algorithm>
#include <cstdint>
#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif
#include <limits>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <vector>

#include "parallel.hpp"
#include "sonoshape/core/target_clones.hpp"

namespace sonoshape::segmentation::detail {
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
SONOSHAPE_AVX2_CLONES void mark_within(std::uint8_t* hits, const std::uint8_t* distance,
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
  std::vector<char> row_has_set(static_cast<std::size_t>(h));
  // Rows are independent in both steps: they are spread over OpenCV's threads.
  detail::parallel_for(cv::Range(0, h), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
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
  });
  cv::Mat out(h, w, CV_8U);
  const std::uint8_t reached = erode ? 0 : 255, missed = erode ? 255 : 0;
  detail::parallel_for(cv::Range(0, h), [&](const cv::Range& rows) {
    std::vector<std::uint8_t> hit(static_cast<std::size_t>(w));
    for (int y = rows.start; y < rows.end; ++y) {
      std::fill(hit.begin(), hit.end(), std::uint8_t{0});
      for (int k = 0; k < static_cast<int>(half.size()); ++k) {
        const int source = y + k - anchor;
        const int r = half[static_cast<std::size_t>(k)];
        if (source < 0 || source >= h || r < 0 || !row_has_set[static_cast<std::size_t>(source)])
          continue;
        mark_within(hit.data(), distance.data() + static_cast<std::ptrdiff_t>(source) * w,
                    static_cast<std::uint8_t>(r), w);
      }
      std::uint8_t* o = out.ptr<std::uint8_t>(y);
      for (int x = 0; x < w; ++x) o[x] = hit[static_cast<std::size_t>(x)] ? reached : missed;
    }
  });
  return out;
}

// out[x] = k[0] c[x] + sum over i = 1..r of k[i] (c[x - i step] + c[x + i step]), x < n: one
// pass of a symmetric kernel along a row (step 1) or a column (step = the row pitch).
using SymmetricTaps = void (*)(float* out, const float* c, std::ptrdiff_t step, const float* k,
                               int r, int n);

void symmetric_taps_plain(float* out, const float* c, std::ptrdiff_t step, const float* k, int r,
                          int n) {
  for (int x = 0; x < n; ++x) {
    float sum = k[0] * c[x];
    for (int i = 1; i <= r; ++i) sum += k[i] * (c[x - i * step] + c[x + i * step]);
    out[x] = sum;
  }
}

#if defined(__x86_64__) || defined(__i386__)
// The same sums, 64 pixels at a time in eight AVX2 registers (enough independent sums to
// hide the additions' latency); the same operations in the same order as the plain path (no
// fused multiply-add), so the same bits.
__attribute__((target("avx2"))) void symmetric_taps_avx2(float* out, const float* c,
                                                         std::ptrdiff_t step, const float* k, int r,
                                                         int n) {
  constexpr int kRegisters = 8;
  int x = 0;
  for (; x + 8 * kRegisters <= n; x += 8 * kRegisters) {
    const __m256 centre = _mm256_set1_ps(k[0]);
    __m256 sum[kRegisters];
    for (int b = 0; b < kRegisters; ++b)
      sum[b] = _mm256_mul_ps(centre, _mm256_loadu_ps(c + x + 8 * b));
    for (int i = 1; i <= r; ++i) {
      const __m256 weight = _mm256_set1_ps(k[i]);
      const float* lo = c + x - i * step;
      const float* hi = c + x + i * step;
      for (int b = 0; b < kRegisters; ++b)
        sum[b] = _mm256_add_ps(sum[b],
                               _mm256_mul_ps(weight, _mm256_add_ps(_mm256_loadu_ps(lo + 8 * b),
                                                                   _mm256_loadu_ps(hi + 8 * b))));
    }
    for (int b = 0; b < kRegisters; ++b) _mm256_storeu_ps(out + x + 8 * b, sum[b]);
  }
  for (; x + 8 <= n; x += 8) {
    __m256 sum = _mm256_mul_ps(_mm256_set1_ps(k[0]), _mm256_loadu_ps(c + x));
    for (int i = 1; i <= r; ++i)
      sum = _mm256_add_ps(sum, _mm256_mul_ps(_mm256_set1_ps(k[i]),
                                             _mm256_add_ps(_mm256_loadu_ps(c + x - i * step),
                                                           _mm256_loadu_ps(c + x + i * step))));
    _mm256_storeu_ps(out + x, sum);
  }
  symmetric_taps_plain(out + x, c + x, step, k, r, n - x);
}

// (An AVX-512 variant was no faster here, and GCC contracts its multiply-adds into FMA, which
// would change the bits.)
SymmetricTaps symmetric_taps() {
  static const SymmetricTaps taps =
      __builtin_cpu_supports("avx2") ? symmetric_taps_avx2 : symmetric_taps_plain;
  return taps;
}
#else
SymmetricTaps symmetric_taps() { return symmetric_taps_plain; }
#endif

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

cv::Mat gaussian_blur_rows(const cv::Mat& src, double sigma, cv::Rect region, bool simd) {
  CV_Assert(src.type() == CV_32F && sigma > 0.0);
  const int w = src.cols, h = src.rows;
  const cv::Rect whole(0, 0, w, h);
  region = region.empty() ? whole : region & whole;
  cv::Mat dst(src.size(), src.type(), cv::Scalar(0));
  if (region.empty()) return dst;
  const int r = (cvRound(sigma * 8.0 + 1.0) | 1) / 2;  // OpenCV's size for float images
  const cv::Mat kernel = cv::getGaussianKernel(2 * r + 1, sigma, CV_32F);
  const float* k = kernel.ptr<float>() + r;  // k[-i] == k[i]
  const SymmetricTaps taps = simd ? symmetric_taps() : symmetric_taps_plain;
  // Rows first: the rows the columns pass reads (the region's, r more above and below,
  // reflected into the image), each padded by r reflected pixels on both sides.
  const int top = region.y - r, bottom = region.y + region.height + r;
  cv::Mat across(bottom - top, w, CV_32F);
  detail::parallel_for(cv::Range(top, bottom), [&](const cv::Range& rows) {
    std::vector<float> padded(static_cast<std::size_t>(w + 2 * r));
    for (int t = rows.start; t < rows.end; ++t) {
      const float* row = src.ptr<float>(cv::borderInterpolate(t, h, cv::BORDER_REFLECT_101));
      std::copy(row, row + w, padded.begin() + r);
      for (int x = 1; x <= r; ++x) {
        padded[static_cast<std::size_t>(r - x)] =
            row[cv::borderInterpolate(-x, w, cv::BORDER_REFLECT_101)];
        padded[static_cast<std::size_t>(r + w - 1 + x)] =
            row[cv::borderInterpolate(w - 1 + x, w, cv::BORDER_REFLECT_101)];
      }
      taps(across.ptr<float>(t - top) + region.x, padded.data() + r + region.x, 1, k, r,
           region.width);  // the columns pass reads no other column
    }
  });
  // Columns in blocks of 64, row after row: the 2r + 1 rows of a block under the kernel stay
  // in the first-level cache from one output row to the next.
  constexpr int kBlock = 64;
  const int blocks = (region.width + kBlock - 1) / kBlock;
  detail::parallel_for(cv::Range(0, blocks), [&](const cv::Range& range) {
    for (int b = range.start; b < range.end; ++b) {
      const int x = region.x + b * kBlock, n = std::min(kBlock, region.x + region.width - x);
      for (int y = region.y; y < region.y + region.height; ++y)
        taps(dst.ptr<float>(y) + x, across.ptr<float>(y - top) + x,
             static_cast<std::ptrdiff_t>(across.step1()), k, r, n);
    }
  });
  return dst;
}

}  // namespace sonoshape::segmentation::detail
