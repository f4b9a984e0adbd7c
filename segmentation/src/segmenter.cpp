#include "sonoshape/segmentation/segmenter.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "blooming.hpp"
#include "boundary_echo.hpp"
#include "parallel.hpp"
#include "raster_ops.hpp"
#include "reflectors.hpp"
#include "segmenter_internal.hpp"
#include "stage_times.hpp"

namespace sonoshape::segmentation {
namespace {

using detail::wrap;

// One class of the nearest-mean classification: its label value and grey mean.
struct ClassMean {
  std::uint8_t value;
  double mean;
};

// Depth bins (mm) of the initial trend estimate, and the fewest pixels a bin needs to count.
constexpr double kDepthBinMm = 2.0;
constexpr int kMinBinPixels = 30;
// Refinements of the depth trend from the classified pixels (an EM-like alternation).
constexpr int kTrendIterations = 2;
// A residual trend steeper than this (grey per mm) is not attenuation but a bad fit.
constexpr double kMaxSlopeGreyPerMm = 3.0;
// Passes of the undecided-pixel fill and of the diagonal-contact repair before giving up.
constexpr int kMaxFillPasses = 200;
constexpr int kMaxRepairPasses = 20;
constexpr std::uint8_t kUndecided = 1;
// A reflector band narrower than this (mm) is speckle, not a bone surface.
constexpr double kMinReflectorWidthMm = 1.0;
// A material's component smaller than min_region_mm2 but of at least this share of it stays when
// its mean grey lies within kConfidentGreyShare of the gap to the next class from its material's
// mean (see confident_small_parts).
constexpr double kConfidentPartMinShare = 0.3;
constexpr double kConfidentGreyShare = 0.3;
// The median that decides for a reflector's band spans about this much (mm; the 5 px of the
// default median_px at 512 x 512 of the default scan, 0.31 mm a pixel).
constexpr double kReflectorMedianMm = 1.5;

// The median window (odd, px) for a reflector's band: kReflectorMedianMm, at least 3 pixels and
// at most the configured median (which a config may set lower, or to 1 for none).
int reflector_median_px(double px_mm, int median_px) {
  const int odd = 2 * static_cast<int>(std::lround(0.5 * (kReflectorMedianMm / px_mm - 1.0))) + 1;
  return std::min(median_px, std::max(3, odd));
}

// The speckle median's window (odd, px): median_px, but spanning at most kReflectorMedianMm
// (the 5 px of the default at 0.31 mm a pixel) and at least 3 px. Speckle grains are as large
// as the point-spread function, a length in mm: 5 pixels of 0.63 mm (the default scan's
// 256 x 256 frames) spanned 3.1 mm and cut an organ's ears and corners off.
int speckle_median_px(double px_mm, int median_px) {
  return median_px > 3 ? reflector_median_px(px_mm, median_px) : median_px;
}

ImageU8 to_image(const cv::Mat& mat) {
  ImageU8 out(mat.cols, mat.rows);
  for (int j = 0; j < mat.rows; ++j)
    std::copy(mat.ptr<std::uint8_t>(j), mat.ptr<std::uint8_t>(j) + mat.cols,
              out.pixels.begin() + static_cast<std::ptrdiff_t>(j) * mat.cols);
  return out;
}

cv::Mat disk(double radius_px) {
  const int r = std::max(0, static_cast<int>(std::lround(radius_px)));
  return cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1));
}

// Depth below the sector's first row in each column, when the geometry gives none.
std::vector<float> column_depth(const ImageU8& sector, double spacing_mm) {
  std::vector<float> depth(sector.pixels.size(), 0.0f);
  for (int i = 0; i < sector.width; ++i) {
    int top = -1;
    for (int j = 0; j < sector.height; ++j) {
      if (top < 0 && sector.at(i, j)) top = j;
      depth[static_cast<std::size_t>(j) * sector.width + i] =
          static_cast<float>(top < 0 ? 0.0 : (j - top) * spacing_mm);
    }
  }
  return depth;
}

// The radius of OpenCV's Gaussian kernel for a float image (ksize = round(8 sigma + 1) | 1).
int gaussian_radius_px(double sigma_px) {
  return sigma_px > 0.0 ? (cvRound(sigma_px * 8.0 + 1.0) | 1) / 2 : 0;
}

// The bounding box of a mask's pixels grown by `reach_px` on every side, clipped to the mask
// (the whole mask when it is empty).
cv::Rect grown_box(const cv::Mat& mask, int reach_px) {
  const cv::Rect box = cv::boundingRect(mask);
  if (box.empty()) return {0, 0, mask.cols, mask.rows};
  return cv::Rect(box.x - reach_px, box.y - reach_px, box.width + 2 * reach_px,
                  box.height + 2 * reach_px) &
         cv::Rect(0, 0, mask.cols, mask.rows);
}

bool same_pixels(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  const std::size_t row_bytes = static_cast<std::size_t>(a.cols) * a.elemSize();
  for (int j = 0; j < a.rows; ++j)
    if (std::memcmp(a.ptr(j), b.ptr(j), row_bytes) != 0) return false;
  return true;
}

// Mean of `src` over a Gaussian window restricted to the mask (normalised convolution), so
// the black outside the sector does not darken its edges. Computed only in `region` (the
// mask's bounding box: nothing reads it elsewhere), zero outside.
class MaskedBlur {
 public:
  MaskedBlur(const cv::Mat& mask01, double sigma_px, const cv::Rect& region)
      : mask_(mask01), weight_(weight(mask01, sigma_px)), sigma_(sigma_px), region_(region) {}
  cv::Mat operator()(const cv::Mat& src) const {
    return detail::gaussian_blur_rows(src.mul(mask_), sigma_, region_) / weight_;
  }

 private:
  // The blurred mask depends on the sector alone, the same in every frame of a sweep, so each
  // thread keeps the last few (a few MB each) instead of blurring the mask again per frame.
  static cv::Mat weight(const cv::Mat& mask01, double sigma_px) {
    struct Entry {
      cv::Mat mask, weight;
      double sigma;
    };
    constexpr std::size_t kEntries = 4;
    thread_local std::vector<Entry> cache;
    for (const Entry& e : cache)
      if (e.sigma == sigma_px && same_pixels(e.mask, mask01)) return e.weight;
    cv::Mat w = detail::gaussian_blur_rows(mask01, sigma_px);
    cv::max(w, 1e-4, w);
    if (cache.size() == kEntries) cache.erase(cache.begin());
    cache.push_back({mask01.clone(), w, sigma_px});
    return w;
  }

  cv::Mat mask_, weight_;
  double sigma_;
  cv::Rect region_;
};

// Least-squares line y = a + b x with weights.
struct Line {
  double a = 0.0, b = 0.0;
};
struct LineFit {
  double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  void add(double x, double y, double w = 1.0) {
    sw += w;
    sx += w * x;
    sy += w * y;
    sxx += w * x * x;
    sxy += w * x * y;
  }
  Line solve() const {
    Line line;
    if (sw <= 0.0) return line;
    const double det = sw * sxx - sx * sx;
    if (std::abs(det) < 1e-9 * std::max(1.0, sw * sxx)) {
      line.a = sy / sw;
      return line;
    }
    line.b = std::clamp((sw * sxy - sx * sy) / det, -kMaxSlopeGreyPerMm, kMaxSlopeGreyPerMm);
    line.a = (sy - line.b * sx) / sw;
    return line;
  }
};

// Re-labels undecided pixels (flag set) from their decided 8-neighbours in the sector, by
// majority, growing inwards; what stays undecided becomes unknown. A pass looks only at the
// undecided pixels next to those the previous pass decided (at first, at all): no other can
// have gained a decided neighbour. A label `fixed` (a bone's section, drawn from its model)
// neither votes nor grows: where the cleaning removed the bright echo tail over a bone, the
// fill had grown the section by a row into it.
void fill_undecided(cv::Mat& map, cv::Mat& undecided, const cv::Mat& sector, int fixed = -1) {
  const int w = map.cols, h = map.rows;
  std::vector<int> todo;
  for (int j = 0; j < h; ++j) {
    const std::uint8_t* u = undecided.ptr<std::uint8_t>(j);
    for (int i = 0; i < w; ++i)
      if (u[i]) todo.push_back(j * w + i);
  }
  if (todo.empty()) return;
  std::vector<std::pair<int, std::uint8_t>> assigned;
  std::vector<int> candidates = todo, next;
  cv::Mat queued(map.size(), CV_8U, cv::Scalar(0));
  for (int pass = 0; pass < kMaxFillPasses && !candidates.empty(); ++pass) {
    assigned.clear();
    for (const int p : candidates) {
      const int i = p % w, j = p / w;
      std::array<std::uint8_t, 8> values{};
      std::array<int, 8> counts{};
      int distinct = 0;
      for (int y = std::max(j - 1, 0); y <= std::min(j + 1, h - 1); ++y) {
        const std::uint8_t* in = sector.ptr<std::uint8_t>(y);
        const std::uint8_t* u = undecided.ptr<std::uint8_t>(y);
        const std::uint8_t* m = map.ptr<std::uint8_t>(y);
        for (int x = std::max(i - 1, 0); x <= std::min(i + 1, w - 1); ++x) {
          if ((x == i && y == j) || !in[x] || u[x] || m[x] == fixed) continue;
          const std::uint8_t v = m[x];
          int k = 0;
          while (k < distinct && values[static_cast<std::size_t>(k)] != v) ++k;
          if (k == distinct) values[static_cast<std::size_t>(distinct++)] = v;
          ++counts[static_cast<std::size_t>(k)];
        }
      }
      if (distinct == 0) continue;
      std::size_t best = 0;
      for (std::size_t k = 1; k < static_cast<std::size_t>(distinct); ++k)
        if (counts[k] > counts[best]) best = k;
      assigned.emplace_back(p, values[best]);
    }
    if (assigned.empty()) break;
    for (const auto& [p, v] : assigned) {
      map.ptr<std::uint8_t>(p / w)[p % w] = v;
      undecided.ptr<std::uint8_t>(p / w)[p % w] = 0;
    }
    next.clear();
    for (const auto& [p, v] : assigned) {
      const int i = p % w, j = p / w;
      for (int y = std::max(j - 1, 0); y <= std::min(j + 1, h - 1); ++y) {
        const std::uint8_t* u = undecided.ptr<std::uint8_t>(y);
        std::uint8_t* q = queued.ptr<std::uint8_t>(y);
        for (int x = std::max(i - 1, 0); x <= std::min(i + 1, w - 1); ++x)
          if (u[x] && !q[x]) {
            q[x] = 1;
            next.push_back(y * w + x);
          }
      }
    }
    for (const int p : next) queued.ptr<std::uint8_t>(p / w)[p % w] = 0;
    candidates.swap(next);
  }
  for (const int p : todo) {
    std::uint8_t& u = undecided.ptr<std::uint8_t>(p / w)[p % w];
    if (!u) continue;
    map.ptr<std::uint8_t>(p / w)[p % w] = kLabelPixelUnknown;
    u = 0;
  }
}

// Opening of every label's mask: the thin parts it removes are re-labelled by their neighbours
// (for the background this closes the materials, and the other way round). All labels at once,
// the same as cv::morphologyEx(MORPH_OPEN) of each label's mask: a pixel survives the erosion
// of its label's mask when the disk around it lies in the sector and holds that label alone
// (the map's grey-level erosion and dilation agree there); since the disk is symmetric, the
// disks of two survivors of different labels cannot overlap, so a pixel is in its own label's
// opening exactly when the disk around it holds a survivor. Four passes instead of two per
// label.
void open_labels(cv::Mat& map, const cv::Mat& sector, double radius_px, int fixed) {
  if (radius_px < 0.5) return;
  const cv::Mat kernel = disk(radius_px);
  cv::Mat lowest, highest, inside;
  cv::erode(map, lowest, kernel);
  cv::dilate(map, highest, kernel);
  cv::erode(sector, inside, kernel);
  const cv::Mat survivors = (lowest == highest) & inside;
  cv::Mat opened;
  cv::dilate(survivors, opened, kernel);
  cv::Mat undecided(map.size(), CV_8U, cv::Scalar(0));
  undecided.setTo(kUndecided, sector & ~opened);
  fill_undecided(map, undecided, sector, fixed);
}

// Components of any label smaller than min_px are re-labelled from their surroundings. The
// components are each label's 8-connected components inside the sector (what
// cv::connectedComponents finds label by label), found for all labels at once: the runs of one
// label in a row, joined to the runs of the same label in the row above that they touch. A
// small component stays when at least half its pixels are set in `keep` (when not empty): a
// small part of an organ that the reconstruction predicts there is no speckle.
void remove_small_components(cv::Mat& map, const cv::Mat& sector, double min_px,
                             const cv::Mat& keep, int fixed) {
  if (min_px < 1.0) return;
  struct Run {
    int row, from, to;  // columns from..to, inclusive
    std::uint8_t value;
  };
  std::vector<Run> runs;
  std::vector<std::size_t> row_begin(static_cast<std::size_t>(map.rows) + 1);
  for (int j = 0; j < map.rows; ++j) {
    row_begin[static_cast<std::size_t>(j)] = runs.size();
    const std::uint8_t* in = sector.ptr<std::uint8_t>(j);
    const std::uint8_t* m = map.ptr<std::uint8_t>(j);
    for (int i = 0; i < map.cols; ++i) {
      if (!in[i]) continue;
      const int from = i;
      while (i + 1 < map.cols && in[i + 1] && m[i + 1] == m[from]) ++i;
      runs.push_back({j, from, i, m[from]});
    }
  }
  row_begin.back() = runs.size();
  std::vector<std::size_t> parent(runs.size());
  for (std::size_t r = 0; r < runs.size(); ++r) parent[r] = r;
  auto root = [&](std::size_t r) {
    while (parent[r] != r) r = parent[r] = parent[parent[r]];
    return r;
  };
  for (std::size_t j = 1; j < static_cast<std::size_t>(map.rows); ++j) {
    std::size_t above = row_begin[j - 1];
    for (std::size_t r = row_begin[j]; r < row_begin[j + 1]; ++r) {
      const Run& run = runs[r];
      while (above < row_begin[j] && runs[above].to + 1 < run.from) ++above;
      // Runs above that touch this one, diagonally included.
      for (std::size_t a = above; a < row_begin[j] && runs[a].from <= run.to + 1; ++a)
        if (runs[a].value == run.value) parent[root(a)] = root(r);
    }
  }
  std::vector<double> area(runs.size(), 0.0), kept(runs.size(), 0.0);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const std::size_t c = root(r);
    area[c] += runs[r].to - runs[r].from + 1;
    if (!keep.empty()) {
      const std::uint8_t* k = keep.ptr<std::uint8_t>(runs[r].row);
      kept[c] += static_cast<double>(std::count_if(k + runs[r].from, k + runs[r].to + 1,
                                                   [](std::uint8_t v) { return v != 0; }));
    }
  }
  cv::Mat undecided(map.size(), CV_8U, cv::Scalar(0));
  for (std::size_t r = 0; r < runs.size(); ++r)
    if (const std::size_t c = root(r); area[c] < min_px && 2.0 * kept[c] < area[c]) {
      std::uint8_t* u = undecided.ptr<std::uint8_t>(runs[r].row);
      std::fill(u + runs[r].from, u + runs[r].to + 1, kUndecided);
    }
  fill_undecided(map, undecided, sector, fixed);
}

// The pixels of the components of the materials brighter than the background (not `fixed`)
// smaller than min_px but of at least floor_px, touching no pixel of `excluded`, whose mean grey
// (the classified, compensated grey) lies near their material's mean: within `share` of the
// gap to every other class on that side. A speckle grain misread as tissue lies just past the
// grey boundary between the classes; the small end of an organ (an ear, the tip of its body)
// shows the organ's own grey.
cv::Mat confident_small_parts(const cv::Mat& map, const cv::Mat& sector, const cv::Mat& grey,
                              const std::vector<ClassMean>& classes, double min_px, double floor_px,
                              double share, int fixed, const cv::Mat& excluded) {
  cv::Mat confident(map.size(), CV_8U, cv::Scalar(0));
  cv::Mat near_fixed;
  cv::dilate(excluded, near_fixed, cv::Mat());
  const double background_grey = classes.front().mean;
  for (const ClassMean& c : classes) {
    // Log-compressed speckle has a long dark tail (its nulls): dark blobs of a few speckle cells
    // with a hypoechoic organ's grey are common in any tissue, bright ones are not.
    if (c.value == kLabelPixelOutside || c.value == fixed || c.mean <= background_grey) continue;
    const cv::Mat mask = (map == c.value) & sector;
    cv::Mat components, stats, centroids;
    const int n = cv::connectedComponentsWithStats(mask, components, stats, centroids, 8, CV_32S);
    std::vector<double> sum(static_cast<std::size_t>(n), 0.0);
    std::vector<std::uint8_t> touches_excluded(static_cast<std::size_t>(n), 0);
    for (int j = 0; j < map.rows; ++j) {
      const int* component = components.ptr<int>(j);
      const float* g = grey.ptr<float>(j);
      const std::uint8_t* f = near_fixed.ptr<std::uint8_t>(j);
      for (int i = 0; i < map.cols; ++i) {
        sum[static_cast<std::size_t>(component[i])] += g[i];
        touches_excluded[static_cast<std::size_t>(component[i])] |= f[i];
      }
    }
    std::vector<std::uint8_t> keep(static_cast<std::size_t>(n), 0);
    for (int k = 1; k < n; ++k) {
      const double area = stats.at<int>(k, cv::CC_STAT_AREA);
      if (area >= min_px || area < floor_px || touches_excluded[static_cast<std::size_t>(k)])
        continue;
      const double mean = sum[static_cast<std::size_t>(k)] / area, off = mean - c.mean;
      bool near = true;
      for (const ClassMean& other : classes) {
        const double gap = other.mean - c.mean;
        if (other.value != c.value && gap * off > 0.0 && std::abs(off) > share * std::abs(gap))
          near = false;
      }
      keep[static_cast<std::size_t>(k)] = near ? 255 : 0;
    }
    for (int j = 0; j < map.rows; ++j) {
      const int* component = components.ptr<int>(j);
      std::uint8_t* out = confident.ptr<std::uint8_t>(j);
      for (int i = 0; i < map.cols; ++i) out[i] |= keep[static_cast<std::size_t>(component[i])];
    }
  }
  return confident;
}

// Removes diagonal-only contacts: where a label holds exactly one diagonal of a 2x2 block, its
// outline would pass through that corner twice (not a simple polygon) and cross the outline of
// the label on the other diagonal. The block's other diagonal gets a pixel of the label.
// A bone's section is drawn whole (its far side from its thickness), so what lies along it in
// its shadow is not bone: those unknown pixels (4-neighbours of the bone) become background.
// Where the bone touched its shadow, the reconstruction's completion of unknown regions carried
// the bone on down the shadow column.
void separate_bone_from_shadow(cv::Mat& map, const cv::Mat& sector, std::uint8_t bone) {
  const cv::Mat bone_mask = map == bone;
  cv::Mat near_bone;
  cv::dilate(bone_mask, near_bone, cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(3, 3)));
  map.setTo(kLabelPixelOutside, near_bone & (map == kLabelPixelUnknown) & sector);
}

void repair_diagonal_contacts(cv::Mat& map, const cv::Mat& sector) {
  constexpr int kOutside = 256;
  for (int pass = 0; pass < kMaxRepairPasses; ++pass) {
    bool changed = false;
    for (int j = 0; j + 1 < map.rows; ++j) {
      std::uint8_t* top = map.ptr<std::uint8_t>(j);
      std::uint8_t* bottom = map.ptr<std::uint8_t>(j + 1);
      const std::uint8_t* top_in = sector.ptr<std::uint8_t>(j);
      const std::uint8_t* bottom_in = sector.ptr<std::uint8_t>(j + 1);
      for (int i = 0; i + 1 < map.cols; ++i) {
        const int a = top_in[i] ? top[i] : kOutside, b = top_in[i + 1] ? top[i + 1] : kOutside,
                  c = bottom_in[i] ? bottom[i] : kOutside,
                  d = bottom_in[i + 1] ? bottom[i + 1] : kOutside;
        // The diagonal (i, j)-(i+1, j+1) ...
        if (a == d && a != kOutside && b != a && c != a) {
          if (top_in[i + 1])
            top[i + 1] = static_cast<std::uint8_t>(a);
          else if (bottom_in[i])
            bottom[i] = static_cast<std::uint8_t>(a);
          else
            top[i] = kLabelPixelUnknown;
          changed = true;
        } else if (b == c && b != kOutside && a != b && d != b) {  // ... and the other one.
          if (top_in[i])
            top[i] = static_cast<std::uint8_t>(b);
          else if (bottom_in[i + 1])
            bottom[i + 1] = static_cast<std::uint8_t>(b);
          else
            top[i + 1] = kLabelPixelUnknown;
          changed = true;
        }
      }
    }
    if (!changed) return;
  }
}

}  // namespace

void ImageGeometry::check() const {
  const auto n = static_cast<std::size_t>(width_px) * static_cast<std::size_t>(height_px);
  if (width_px <= 0 || height_px <= 0 || sector.width != width_px || sector.height != height_px ||
      sector.pixels.size() != n)
    throw std::invalid_argument("ImageGeometry: the sector mask does not match the image size");
  if (!depth_mm.empty() && depth_mm.size() != n)
    throw std::invalid_argument("ImageGeometry: depth_mm does not match the image size");
  if (!(spacing_mm > 0.0) || !std::isfinite(spacing_mm))
    throw std::invalid_argument("ImageGeometry: the pixel spacing must be positive");
}

ImageGeometry full_image_geometry(int width_px, int height_px, double spacing_mm) {
  ImageGeometry g;
  g.width_px = width_px;
  g.height_px = height_px;
  g.sector = ImageU8(width_px, height_px, 255);
  // Pixel centres are integers, so the image covers [-0.5, size - 0.5].
  g.sector_px = {{-0.5, -0.5},
                 {width_px - 0.5, -0.5},
                 {width_px - 0.5, height_px - 0.5},
                 {-0.5, height_px - 0.5}};
  g.spacing_mm = spacing_mm;
  g.depth_mm = column_depth(g.sector, spacing_mm);
  return g;
}

ImageGeometry polygon_geometry(int width_px, int height_px, double spacing_mm,
                               const Ring2& sector_px) {
  if (sector_px.size() < 3)
    throw std::invalid_argument("polygon_geometry: the sector needs at least 3 points");
  ImageGeometry g;
  g.width_px = width_px;
  g.height_px = height_px;
  cv::Mat mask(height_px, width_px, CV_8U, cv::Scalar(0));
  constexpr int kShift = 4;  // sub-pixel vertices for fillPoly
  std::vector<cv::Point> points;
  for (const Vec2& p : sector_px)
    points.emplace_back(static_cast<int>(std::lround(p.x() * (1 << kShift))),
                        static_cast<int>(std::lround(p.y() * (1 << kShift))));
  cv::fillPoly(mask, std::vector<std::vector<cv::Point>>{points}, cv::Scalar(255), cv::LINE_8,
               kShift);
  g.sector = to_image(mask);
  g.sector_px = sector_px;
  g.spacing_mm = spacing_mm;
  g.depth_mm = column_depth(g.sector, spacing_mm);
  return g;
}

namespace {

// The scanner's burnt-in graphics (text, scale bars, depth ticks, a logo) are the same in every
// frame but for the noise of an analogue video capture (up to a tenth of their grey on the VLCUS
// recording), where the image inside the fan changes with the probe's motion: pixels with signal
// whose raw grey never varies by more than this over the sampled frames are graphics.
constexpr double kStaticGraphicsGrey = 2.0;
constexpr double kStaticGraphicsShare = 0.1;
// What changes is grouped by this share of the image's diagonal (a fan's speckle is spread over
// it); groups holding less than kMinFanPartShare of the image's pixels are a clock's digits or
// a cursor, not the fan.
constexpr double kGroupShare = 0.01;
constexpr double kMinFanPartShare = 0.002;

// The pixels that carry signal and change between frames, in groups large enough to be the fan;
// none (an empty Mat) when the frames hold no graphics, or nothing large changes (one frame, a
// frozen image, a few frames of echoes in water that barely move: nothing tells graphics from
// image).
cv::Mat changing_signal(const std::vector<const GreyImage*>& frames, const cv::Mat& signal,
                        double signal_grey) {
  const int w = signal.cols, h = signal.rows;
  cv::Mat lowest = wrap(*frames.front()).clone(), highest = lowest.clone();
  for (const GreyImage* frame : frames) {
    cv::min(lowest, wrap(*frame), lowest);
    cv::max(highest, wrap(*frame), highest);
  }
  cv::Mat range, tolerance;
  cv::Mat(highest - lowest).convertTo(range, CV_32F);
  highest.convertTo(tolerance, CV_32F, kStaticGraphicsShare);
  cv::max(tolerance, kStaticGraphicsGrey, tolerance);
  cv::Mat graphics = (range <= tolerance) & (highest > signal_grey);
  // No graphics (a research interface's image, a phantom in water whose echoes all move): the
  // hull of all signal, small echoes included.
  if (cv::countNonZero(graphics) < kMinFanPartShare * w * h) return {};
  // The graphics' anti-aliased rims are dim, so their noise is large beside their grey.
  cv::dilate(graphics, graphics, disk(1.0));
  cv::Mat changing = signal & ~graphics;
  cv::morphologyEx(changing, changing, cv::MORPH_OPEN, disk(1.0));
  cv::Mat grouped, groups, stats, centroids;
  cv::dilate(changing, grouped, disk(kGroupShare * std::hypot(w, h)));
  const int n = cv::connectedComponentsWithStats(grouped, groups, stats, centroids, 8, CV_32S);
  std::vector<double> changing_px(static_cast<std::size_t>(n), 0.0);
  for (int j = 0; j < h; ++j) {
    const int* group = groups.ptr<int>(j);
    const std::uint8_t* c = changing.ptr<std::uint8_t>(j);
    for (int i = 0; i < w; ++i) changing_px[static_cast<std::size_t>(group[i])] += c[i] ? 1.0 : 0.0;
  }
  bool any = false;
  for (int g = 1; g < n; ++g)
    any |= changing_px[static_cast<std::size_t>(g)] >= kMinFanPartShare * w * h;
  if (!any) return {};
  for (int j = 0; j < h; ++j) {
    const int* group = groups.ptr<int>(j);
    std::uint8_t* c = changing.ptr<std::uint8_t>(j);
    for (int i = 0; i < w; ++i)
      if (changing_px[static_cast<std::size_t>(group[i])] < kMinFanPartShare * w * h) c[i] = 0;
  }
  return changing;
}

}  // namespace

ImageGeometry auto_geometry(const std::vector<const GreyImage*>& frames, double spacing_mm,
                            double signal_grey) {
  if (frames.empty() || frames.front()->empty())
    throw std::invalid_argument("auto_geometry: no frames");
  const int w = frames.front()->width, h = frames.front()->height;
  cv::Mat peak(h, w, CV_8U, cv::Scalar(0)), filtered;
  for (const GreyImage* frame : frames) {
    if (frame->width != w || frame->height != h)
      throw std::invalid_argument("auto_geometry: frames differ in size");
    cv::medianBlur(wrap(*frame), filtered, 5);
    cv::max(peak, filtered, peak);
  }
  cv::Mat signal = peak > signal_grey;
  // Isolated specks (noise, a cursor) must not widen the sector.
  cv::morphologyEx(signal, signal, cv::MORPH_OPEN, disk(1.0));
  // A screen capture (a frame grabber on the scanner's video output) holds the scanner's text
  // and scale bars beside the fan: the sector is the hull of what changes.
  if (frames.size() > 1)
    if (cv::Mat changing = changing_signal(frames, signal, signal_grey); !changing.empty())
      signal = changing;
  std::vector<cv::Point> points;
  cv::findNonZero(signal, points);
  if (points.size() < 3) return full_image_geometry(w, h, spacing_mm);
  // The sector is the convex hull of what carries signal: an outline traced from the mask
  // touches itself at one-pixel necks and diagonal corners (and simplifying it can make it
  // cross), while a hull is simple by construction. A linear probe's image is a rectangle and a
  // convex probe's a fan, so the hull adds at most the sliver under a convex probe's face, which
  // is dark and so becomes unknown by the confidence rule.
  std::vector<cv::Point> hull;
  cv::convexHull(points, hull);
  if (hull.size() < 3 || cv::contourArea(hull) < 0.01 * w * h)
    return full_image_geometry(w, h, spacing_mm);
  Ring2 ring;
  for (const cv::Point& p : hull) ring.emplace_back(p.x, p.y);
  ImageGeometry g;
  g.width_px = w;
  g.height_px = h;
  cv::Mat mask(h, w, CV_8U, cv::Scalar(0));
  cv::fillConvexPoly(mask, hull, cv::Scalar(255));
  g.sector = to_image(mask);
  g.sector_px = ring;
  g.spacing_mm = spacing_mm;
  g.depth_mm = column_depth(g.sector, spacing_mm);
  return g;
}

Segmentation segment_frame(const GreyImage& image, const ImageGeometry& geometry,
                           const SegmentationConfig& config) {
  return detail::segment_frame(image, geometry, config, {});
}

namespace {

// The steps of detail::segment_frame, in the order of docs/segmentation.md's "Method": speckle
// reduction, confidence, the classes, depth compensation and classification, the steps on the
// whole frame (bone sections, the graph cut, blooming), cleaning, and the output maps.
// Everything works in the sector's bounding box grown by the farthest any filter reads from a
// pixel (clipped to the image): only sector pixels are read back, so the labels are those of
// the whole image, at a fraction of the cost for a fan or a narrow sector.
class FrameSegmenter {
 public:
  FrameSegmenter(const GreyImage& image, const ImageGeometry& geometry,
                 const SegmentationConfig& config, const detail::RefineStep& refine)
      : image_(image), geometry_(geometry), config_(config), refine_(refine) {}

  Segmentation run() {
    set_work_region();
    reduce_speckle();
    clock_.lap(detail::Stage::kFilter);
    find_low_confidence();
    clock_.lap(detail::Stage::kConfidence);
    choose_classes();
    if (config_.depth_compensation) fit_depth_trend();
    classify_all();
    whole_frame_steps();
    clean();
    Segmentation result = output();
    clock_.lap(detail::Stage::kCleaning);
    return result;
  }

 private:
  void set_work_region() {
    px_mm_ = geometry_.spacing_mm;
    const cv::Mat whole_sector = wrap(geometry_.sector) > 0;
    const SegmentationConfig& c = config_;
    roi_ = grown_box(whole_sector,
                     std::max({c.median_px / 2, gaussian_radius_px(c.smoothing_mm / px_mm_),
                               gaussian_radius_px(c.confidence_window_mm / px_mm_),
                               disk(c.shadow_margin_mm / px_mm_).rows / 2,
                               disk(c.opening_mm / px_mm_).rows / 2}) +
                         1);
    w_ = roi_.width;
    h_ = roi_.height;
    grey_ = wrap(image_)(roi_);
    sector_ = whole_sector(roi_);
    sector_box_ = cv::boundingRect(sector_);
    sector_.convertTo(mask01_, CV_32F, 1.0 / 255.0);
    depth_values_ =
        geometry_.depth_mm.empty() ? column_depth(geometry_.sector, px_mm_) : geometry_.depth_mm;
    depth_ = cv::Mat(image_.height, image_.width, CV_32F, depth_values_.data())(roi_);
  }

  // Speckle reduction: the median removes speckle's bright and dark outliers without blurring
  // edges; the Gaussian then averages over several speckle cells.
  void reduce_speckle() {
    median_px_ = speckle_median_px(px_mm_, config_.median_px);
    // A boundary's specular echo, brighter than both tissues, would go to the brighter one.
    speckle_ = config_.boundary_echo_contrast > 0.0
                   ? detail::fill_boundary_echoes(
                         grey_, sector_, px_mm_,
                         config_.boundary_echo_contrast * config_.background.grey_std)
                   : grey_;
    if (median_px_ > 1)
      cv::medianBlur(speckle_, median_, median_px_);
    else
      median_ = speckle_;
    median_.convertTo(smoothed_, CV_32F);
    if (config_.smoothing_mm > 0.0)
      smoothed_ = MaskedBlur(mask01_, config_.smoothing_mm / px_mm_, sector_box_)(smoothed_);
  }

  // Confidence from local statistics of the raw grey: where nearly every pixel of the window is
  // dark there is no echo (shadow, lost signal). Speckle of log-compressed tissue keeps a large
  // spread at any echogenicity, so dark tissue leaves bright pixels in the window; a fraction
  // is robust where a local mean or variance is not (a few bright pixels at the window's edge
  // would dominate them).
  void find_low_confidence() {
    shadow_grey_ = config_.effective_shadow_grey();
    const cv::Mat dark_mask = grey_ <= shadow_grey_;
    cv::Mat dark;
    dark_mask.convertTo(dark, CV_32F, 1.0 / 255.0);
    const cv::Mat dark_fraction =
        MaskedBlur(mask01_, config_.confidence_window_mm / px_mm_, sector_box_)(dark);
    low_ = (dark_fraction > config_.shadow_fraction) & sector_;
    // With an anechoic material (a cyst reads as black as a shadow) only dark areas that reach
    // the far end of the sector are shadows: a shadow runs down its beams to the bottom.
    const bool anechoic_material =
        std::any_of(config_.materials.begin(), config_.materials.end(),
                    [&](const LabelModel& m) { return m.grey_mean < shadow_grey_; });
    if (anechoic_material) keep_dark_reaching_far_end();
    if (config_.max_depth_mm > 0.0) low_ |= (depth_ > config_.max_depth_mm) & sector_;
    if (config_.shadow_margin_mm > 0.0)
      low_ = detail::dilate_runs(low_, disk(config_.shadow_margin_mm / px_mm_));
    low_ &= sector_;
  }

  // Clears the dark components of low_ that do not reach the sector's far end.
  void keep_dark_reaching_far_end() {
    cv::Mat components;
    const int n = cv::connectedComponents(low_, components, 8, CV_32S);
    std::vector<bool> reaches_far_end(static_cast<std::size_t>(n), false);
    // (The work region leaves a row below the sector unless the sector reaches the image's end.)
    for (int j = 0; j < h_; ++j) {
      const std::uint8_t* in = sector_.ptr<std::uint8_t>(j);
      const std::uint8_t* below = j + 1 < h_ ? sector_.ptr<std::uint8_t>(j + 1) : nullptr;
      const int* component = components.ptr<int>(j);
      for (int i = 0; i < w_; ++i)
        if (in[i] && (!below || !below[i]))
          reaches_far_end[static_cast<std::size_t>(component[i])] = true;
    }
    for (int j = 0; j < h_; ++j) {
      const int* component = components.ptr<int>(j);
      std::uint8_t* dark = low_.ptr<std::uint8_t>(j);
      for (int i = 0; i < w_; ++i)
        if (component[i] > 0 && !reaches_far_end[static_cast<std::size_t>(component[i])])
          dark[i] = 0;
    }
  }

  // Classes: background then materials, each with its grey mean; and the strong reflector.
  void choose_classes() {
    classes_ = {{kLabelPixelOutside, config_.background.grey_mean}};
    for (const LabelModel& m : config_.materials)
      classes_.push_back({static_cast<std::uint8_t>(m.label), m.grey_mean});
    for (const ClassMean& c : classes_) class_mean_[c.value] = c.mean;
    // Strong reflectors (bone surfaces) are thin bright bands that the Gaussian smears into the
    // grey of bright tissue; where the brightest class stands far above the others, the median
    // (which keeps bands thicker than half its window and removes speckle) decides for it.
    by_mean_ = classes_;
    std::sort(by_mean_.begin(), by_mean_.end(),
              [](const ClassMean& x, const ClassMean& y) { return x.mean > y.mean; });
    reflector_class_ =
        by_mean_.size() > 1 && by_mean_[0].mean - by_mean_[1].mean > detail::kReflectorGapGrey;
    reflector_grey_ = reflector_class_ ? 0.5 * (by_mean_[0].mean + by_mean_[1].mean) : 1e9;
    // The band is about as thick as the point-spread function's axial extent, a length in mm: a
    // median of median_px pixels that keeps it at a fine pixel size wipes it out at a coarse one
    // (0.63 mm at 256 x 256 of the default scan), so its median has a window in mm.
    const int band_median_px =
        reflector_class_ ? reflector_median_px(px_mm_, config_.median_px) : 0;
    // (From the grey as recorded: a bone's band is itself a line brighter than both its sides.)
    if (band_median_px > 0 && (band_median_px != median_px_ || speckle_.data != grey_.data)) {
      cv::Mat band_median;
      cv::medianBlur(grey_, band_median, band_median_px);
      band_median.convertTo(median_f_, CV_32F);
    } else {
      median_.convertTo(median_f_, CV_32F);
    }
    map_ = cv::Mat(h_, w_, CV_8U, cv::Scalar(kLabelPixelUnknown));
  }

  std::uint8_t nearest_class(double g) const {
    std::size_t best = 0;
    for (std::size_t k = 1; k < classes_.size(); ++k)
      if (std::abs(g - classes_[k].mean) < std::abs(g - classes_[best].mean)) best = k;
    return classes_[best].value;
  }

  // Labels of row j's pixels first, first + step, ... under the current trend.
  void classify_row(int j, int first, int step) {
    const float* s = smoothed_.ptr<float>(j);
    const float* d = depth_.ptr<float>(j);
    const std::uint8_t* in = sector_.ptr<std::uint8_t>(j);
    const std::uint8_t* dark = low_.ptr<std::uint8_t>(j);
    const float* m = median_f_.ptr<float>(j);
    std::uint8_t* out = map_.ptr<std::uint8_t>(j);
    for (int i = first; i < w_; i += step) {
      const double offset = trend_.a + trend_.b * d[i];
      // A reflector's echo is signal even inside the margin of the shadow it casts; but an
      // anechoic pixel (water, gel: its median at most the shadow grey) is none, whatever the
      // depth trend says (a trend fitted to such labels fed itself: every pixel of a phantom
      // in water became the bright class).
      out[i] = !in[i]                                                    ? kLabelPixelUnknown
               : m[i] > shadow_grey_ && m[i] - offset >= reflector_grey_ ? by_mean_[0].value
               : dark[i]                                                 ? kLabelPixelUnknown
                         : nearest_class(s[i] - offset);
    }
  }

  void classify_all() {
    detail::parallel_for(cv::Range(0, h_), [&](const cv::Range& rows) {
      for (int j = rows.start; j < rows.end; ++j) classify_row(j, 0, 1);
    });
  }

  // Residual depth trend (grey = class mean + a + b * depth): first from per-depth medians
  // (mostly background), then refined from all classified pixels against their class means.
  // Two starts: the per-depth medians (right when the background fills most depths) and no
  // trend (right when one organ fills the image, as under a linear probe inside a large organ,
  // where the medians are the organ's and would shift every class); the better fit wins.
  void fit_depth_trend() {
    const auto from_medians = refine_trend(trend_of_depth_medians());
    const auto from_none = refine_trend(Line{});
    trend_ = from_none.second < from_medians.second ? from_none.first : from_medians.first;
  }

  // The line through the medians of the confident sector pixels' grey per depth bin, less the
  // background's mean.
  Line trend_of_depth_medians() const {
    std::vector<std::vector<float>> bins;
    for (int j = 0; j < h_; ++j) {
      const std::uint8_t* in = sector_.ptr<std::uint8_t>(j);
      const std::uint8_t* dark = low_.ptr<std::uint8_t>(j);
      const float* d = depth_.ptr<float>(j);
      const float* s = smoothed_.ptr<float>(j);
      for (int i = 0; i < w_; ++i) {
        if (!in[i] || dark[i]) continue;
        const auto bin = static_cast<std::size_t>(std::max(0.0f, d[i]) / kDepthBinMm);
        if (bin >= bins.size()) bins.resize(bin + 1);
        bins[bin].push_back(s[i]);
      }
    }
    LineFit fit;
    for (std::size_t b = 0; b < bins.size(); ++b) {
      auto& v = bins[b];
      if (static_cast<int>(v.size()) < kMinBinPixels) continue;
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      fit.add((static_cast<double>(b) + 0.5) * kDepthBinMm,
              v[v.size() / 2] - config_.background.grey_mean, static_cast<double>(v.size()));
    }
    return fit.solve();
  }

  // The EM-like alternation from a start: label the samples (every other row and column of the
  // work region: plenty, and only these need a label before the final classification) with the
  // trend, refit the trend to their residuals; returns the trend and the samples' mean squared
  // residual under it.
  std::pair<Line, double> refine_trend(Line start) {
    trend_ = start;
    double squares = 0.0, samples = 0.0;
    for (int iteration = 0; iteration <= kTrendIterations; ++iteration) {
      LineFit residuals;
      squares = samples = 0.0;
      for (int j = roi_.y % 2; j < h_; j += 2) {
        classify_row(j, roi_.x % 2, 2);
        const std::uint8_t* m = map_.ptr<std::uint8_t>(j);
        const float* d = depth_.ptr<float>(j);
        const float* s = smoothed_.ptr<float>(j);
        for (int i = roi_.x % 2; i < w_; i += 2) {
          if (m[i] == kLabelPixelUnknown) continue;
          const double r = s[i] - class_mean_[m[i]];
          residuals.add(d[i], r);
          const double e = r - (trend_.a + trend_.b * d[i]);
          squares += e * e;
          samples += 1.0;
        }
      }
      if (iteration < kTrendIterations) trend_ = residuals.solve();
    }
    return std::make_pair(trend_, samples > 0.0 ? squares / samples : 0.0);
  }

  // `part` (of the work region) inside the whole image, `outside` elsewhere; itself when the
  // work region is the image or no whole-frame step runs.
  cv::Mat in_image(const cv::Mat& part, double outside) const {
    if (!cropped_) return part;
    cv::Mat out(image_.height, image_.width, part.type(), cv::Scalar(outside));
    part.copyTo(out(roi_));
    return out;
  }

  // The steps between classification and cleaning (bone sections, the graph cut, blooming)
  // work on whole frames (the graph cut's cells and prior are in image pixels): they get the
  // work region inside the whole image, with what the image holds outside the sector there
  // (unknown labels; zero grey and masks, which they read only inside the sector).
  void whole_frame_steps() {
    const std::uint8_t reflector = by_mean_[0].value;
    sections_ =
        reflector_class_ && reflector != kLabelPixelOutside &&
        std::any_of(config_.materials.begin(), config_.materials.end(), [&](const LabelModel& m) {
          return m.label == reflector && m.thickness_mm > 0.0;
        });
    cropped_ = roi_.size() != cv::Size(image_.width, image_.height) &&
               (sections_ || refine_ || config_.psf_sigma_mm > 0.0);
    cv::Mat whole_map = in_image(map_, kLabelPixelUnknown);
    const cv::Mat sector_in_image = in_image(sector_, 0);
    if (sections_)
      for (const LabelModel& m : config_.materials)
        if (m.label == reflector && m.thickness_mm > 0.0)
          detail::fill_reflector_sections(
              whole_map, in_image(median_f_, 0), sector_in_image, reflector,
              m.thickness_mm / px_mm_,
              std::max(3, static_cast<int>(std::lround(kMinReflectorWidthMm / px_mm_))));
    compensated_ = smoothed_ - (trend_.a + trend_.b * depth_);
    if (refine_) {
      // The graph cut reads the grey the classification read (median, then Gaussian): on the
      // median alone, dark speckle inside a bright organ outweighed the smoothness and bit into
      // it.
      refine_(whole_map, in_image(compensated_, 0), in_image(low_, 0), sector_in_image, keep_);
      if (!keep_.empty() && cropped_) keep_ = keep_(roi_);
    }
    clock_.lap(detail::Stage::kClassify);
    std::vector<detail::GreyClass> grey_classes;
    for (const ClassMean& c : classes_) grey_classes.push_back({c.value, c.mean});
    detail::undo_blooming(whole_map, sector_in_image, in_image(compensated_, 0), grey_classes,
                          config_.psf_sigma_mm, config_.dynamic_range_db, px_mm_,
                          reflector_class_ ? reflector : -1);
    if (cropped_) whole_map(roi_).copyTo(map_);
  }

  // Morphological cleaning on the label map (every label from the same map, so regions cannot
  // overlap), then no diagonal-only contacts so that every outline is a simple polygon.
  void clean() {
    // A bone's section is drawn from its model: the cleaning's re-labelling does not grow it.
    const int fixed = sections_ ? by_mean_[0].value : -1;
    open_labels(map_, sector_, config_.opening_mm / px_mm_, fixed);
    const double min_px = config_.min_region_mm2 / (px_mm_ * px_mm_);
    // Small parts of an organ (its ends, an ear) whose grey is the organ's own stay; but not
    // what touches a bone's section (its echo spreads beyond the drawn section as bright as
    // bright tissue) or lies within two smoothing sigmas of the sector's edge (there the
    // smoothing averages half as many speckle cells: two false pieces at the fan's edge in one
    // slice of the default 512 px sweep, `segment --every 4`).
    cv::Mat inner;
    cv::erode(sector_, inner, disk(2.0 * config_.smoothing_mm / px_mm_), cv::Point(-1, -1), 1,
              cv::BORDER_CONSTANT, cv::Scalar(0));  // (the image's edge is the sector's there)
    const cv::Mat excluded = (map_ == fixed) | (sector_ & ~inner);
    const cv::Mat confident = confident_small_parts(map_, sector_, compensated_, classes_, min_px,
                                                    kConfidentPartMinShare * min_px,
                                                    kConfidentGreyShare, fixed, excluded);
    remove_small_components(map_, sector_, min_px, keep_.empty() ? confident : (keep_ | confident),
                            fixed);
    repair_diagonal_contacts(map_, sector_);
    if (sections_) separate_bone_from_shadow(map_, sector_, by_mean_[0].value);
    map_.setTo(kLabelPixelUnknown, ~sector_);
  }

  // The label, compensated grey and confidence maps in the whole image: outside the work region
  // is outside the sector.
  Segmentation output() {
    auto whole = [&](const cv::Mat& part, std::uint8_t outside) {
      cv::Mat out(image_.height, image_.width, CV_8U, cv::Scalar(outside));
      part.copyTo(out(roi_));
      return to_image(out);
    };
    Segmentation result;
    result.labels = whole(map_, kLabelPixelUnknown);
    compensated_.setTo(0.0, ~sector_);
    cv::Mat compensated_u8;
    compensated_.convertTo(compensated_u8, CV_8U);  // saturates to 0..255
    result.smoothed = whole(compensated_u8, 0);
    result.low_confidence = whole(low_, 0);
    result.depth_slope_grey_per_mm = trend_.b;
    for (int j = 0; j < h_; ++j) {
      const std::uint8_t* in = sector_.ptr<std::uint8_t>(j);
      const std::uint8_t* m = map_.ptr<std::uint8_t>(j);
      for (int i = 0; i < w_; ++i)
        if (in[i] && m[i] == kLabelPixelUnknown) ++result.unknown_in_sector_px;
    }
    return result;
  }

  const GreyImage& image_;
  const ImageGeometry& geometry_;
  const SegmentationConfig& config_;
  const detail::RefineStep& refine_;
  detail::StageClock clock_;
  double px_mm_ = 0.0;
  cv::Rect roi_, sector_box_;  // the work region in the image; the sector's box in it
  int w_ = 0, h_ = 0;          // the work region's size (px)
  cv::Mat grey_, sector_, mask01_, depth_;
  std::vector<float> depth_values_;  // depth_'s pixels (mm)
  int median_px_ = 0;
  cv::Mat speckle_, median_, smoothed_;  // speckle reduction's input, median, Gaussian
  double shadow_grey_ = 0.0;
  cv::Mat low_;  // low confidence: unknown
  std::vector<ClassMean> classes_, by_mean_;
  std::array<double, 256> class_mean_{};
  bool reflector_class_ = false;
  double reflector_grey_ = 1e9;
  cv::Mat median_f_;  // the median the reflector test reads
  Line trend_;
  cv::Mat map_, keep_, compensated_;
  bool sections_ = false, cropped_ = false;
};

}  // namespace

Segmentation detail::segment_frame(const GreyImage& image, const ImageGeometry& geometry,
                                   const SegmentationConfig& config, const RefineStep& refine) {
  geometry.check();
  if (image.width != geometry.width_px || image.height != geometry.height_px ||
      image.pixels.size() != geometry.sector.pixels.size())
    throw std::invalid_argument("segment_frame: the image is " + std::to_string(image.width) + "x" +
                                std::to_string(image.height) + ", the geometry " +
                                std::to_string(geometry.width_px) + "x" +
                                std::to_string(geometry.height_px));
  if (const Status valid = config.validate(); !valid) throw std::invalid_argument(valid.message());
  return FrameSegmenter(image, geometry, config, refine).run();
}

}  // namespace sonoshape::segmentation
