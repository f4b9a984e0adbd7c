#include "sonoshape/segmentation/labeller.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <stdexcept>
#include <vector>

#include "graph_cut.hpp"
#include "parallel.hpp"
#include "segmenter_internal.hpp"

namespace sonoshape::segmentation {
namespace {

// Fewer interior pixels than this in a frame leave a label's appearance model as it was.
constexpr int kMinModelPixels = 200;
// Before any frame has taught a label's model, its spread in the smoothed grey is this share of
// the raw grey's spread: the median and the Gaussian average several speckle cells (0.3 to 0.4
// inside the simulator's organs, 0.5 in its background); the larger share keeps the first
// frames from trusting a model that no frame has checked yet.
constexpr double kSmoothedSpreadShare = 0.5;
// The cost that keeps a cell off a label (a reflector's cells on it, the others off it).
constexpr float kExcluded = detail::kExcludedCost;
// Cells this far (in cells) from a boundary of the starting labelling take part in the cut.
constexpr int kBandCells = 3;

// Organs whose grey means differ by less than this share of their spread look alike: the image
// cannot tell which is which, only where each region is.
constexpr double kLookAlikeShare = 0.5;
// A region takes an organ's label from the prior when at least this share of it lies where the
// reconstruction predicts that organ (a region at the edge of a prediction overlaps it partly).
constexpr double kPredictedShare = 0.1;

struct Appearance {
  double mean = 0.0, variance = 1.0;
};

}  // namespace

struct GraphCutLabeller::Impl {
  SegmentationConfig config;
  ImageGeometry geometry;
  GraphCutOptions options;
  int block_px = 1;
  int grid_w = 0, grid_h = 0;
  std::vector<std::uint8_t> values;  // label index -> pixel value
  int reflector = -1;                // index of the reflector label, if any
  std::vector<Appearance> models;
  // Groups of look-alike materials (indices into values), each of two or more.
  std::vector<std::vector<int>> look_alikes;

  Impl(const SegmentationConfig& c, const ImageGeometry& g, const GraphCutOptions& o)
      : config(c), geometry(g), options(o) {
    geometry.check();
    if (const Status valid = config.validate(); !valid)
      throw std::invalid_argument(valid.message());
    if (const Status valid = options.validate(); !valid)
      throw std::invalid_argument("GraphCutLabeller: " + valid.message());
    block_px = std::max(1, static_cast<int>(std::lround(options.cell_mm / geometry.spacing_mm)));
    grid_w = (geometry.width_px + block_px - 1) / block_px;
    grid_h = (geometry.height_px + block_px - 1) / block_px;
    std::vector<const LabelModel*> all{&config.background};
    for (const LabelModel& m : config.materials) all.push_back(&m);
    for (const LabelModel* m : all) {
      values.push_back(static_cast<std::uint8_t>(m->label));
      const double s = m->grey_std * kSmoothedSpreadShare;
      models.push_back({m->grey_mean, s * s});
    }
    std::vector<std::size_t> order(all.size());
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return all[a]->grey_mean > all[b]->grey_mean; });
    const double gap_grey =
        order.size() > 1 ? all[order[0]]->grey_mean - all[order[1]]->grey_mean : 0.0;
    if (gap_grey > detail::kReflectorGapGrey && order[0] != 0)
      reflector = static_cast<int>(order[0]);
    group_look_alikes(all);
    merge_look_alike_models();
  }

  // The threshold labelling that seeds the cut classifies by the nearest grey mean: a group of
  // look-alikes classifies as one tissue at the group's mean (apart, the brighter member would
  // pull the boundary with the background towards it and let dark speckle in).
  void merge_look_alike_models() {
    for (const std::vector<int>& group : look_alikes) {
      double mean = 0.0, variance = 0.0;
      for (const int k : group) {
        const LabelModel& m = config.materials[static_cast<std::size_t>(k) - 1];
        mean += m.grey_mean;
        variance += m.grey_std * m.grey_std;
      }
      mean /= static_cast<double>(group.size());
      variance /= static_cast<double>(group.size());
      for (const int k : group) {
        LabelModel& m = config.materials[static_cast<std::size_t>(k) - 1];
        m.grey_mean = mean;
        m.grey_std = std::sqrt(variance);
        const double share = kSmoothedSpreadShare * kSmoothedSpreadShare;
        models[static_cast<std::size_t>(k)] = {mean, variance * share};
      }
    }
  }

  void group_look_alikes(const std::vector<const LabelModel*>& all) {
    std::vector<int> group(all.size(), -1);
    for (std::size_t a = 1; a < all.size(); ++a)
      for (std::size_t b = a + 1; b < all.size(); ++b) {
        if (static_cast<int>(a) == reflector || static_cast<int>(b) == reflector) continue;
        const double spread = std::min(all[a]->grey_std, all[b]->grey_std);
        if (std::abs(all[a]->grey_mean - all[b]->grey_mean) >= kLookAlikeShare * spread) continue;
        if (group[a] < 0 && group[b] < 0) {
          group[a] = group[b] = static_cast<int>(look_alikes.size());
          look_alikes.push_back({static_cast<int>(a), static_cast<int>(b)});
        } else if (group[b] < 0) {
          group[b] = group[a];
          look_alikes[static_cast<std::size_t>(group[a])].push_back(static_cast<int>(b));
        } else if (group[a] < 0) {
          group[a] = group[b];
          look_alikes[static_cast<std::size_t>(group[b])].push_back(static_cast<int>(a));
        } else if (group[a] != group[b]) {  // join b's group into a's
          const int from = group[b];
          for (const int k : look_alikes[static_cast<std::size_t>(from)]) {
            group[static_cast<std::size_t>(k)] = group[a];
            look_alikes[static_cast<std::size_t>(group[a])].push_back(k);
          }
          look_alikes[static_cast<std::size_t>(from)].clear();
        }
      }
    std::erase_if(look_alikes, [](const std::vector<int>& g) { return g.empty(); });
  }

  int index_of(std::uint8_t value) const {
    for (std::size_t k = 0; k < values.size(); ++k)
      if (values[k] == value) return static_cast<int>(k);
    return -1;
  }

  // The per-cell sums of the usable pixels' grey, and each cell's reflector pixels.
  struct CellSums {
    std::vector<double> count, sum, sum_sq;
    std::vector<int> reflector_px;
    // The one label of a cell whose pixels are all usable and of that label; kNotPure else.
    std::vector<int> pure;
  };
  static constexpr int kNotPure = -1, kNoPixelYet = -2;

  CellSums cell_sums(const cv::Mat& map, const cv::Mat& grey, const cv::Mat& usable) const {
    const std::size_t cells = static_cast<std::size_t>(grid_w) * grid_h;
    CellSums s{std::vector<double>(cells, 0.0), std::vector<double>(cells, 0.0),
               std::vector<double>(cells, 0.0), std::vector<int>(cells, 0),
               std::vector<int>(cells, kNoPixelYet)};
    std::vector<std::size_t> cell_of_column(static_cast<std::size_t>(map.cols));
    for (int i = 0; i < map.cols; ++i)
      cell_of_column[static_cast<std::size_t>(i)] = static_cast<std::size_t>(i / block_px);
    const int reflector_value = reflector >= 0 ? values[static_cast<std::size_t>(reflector)] : -1;
    // Rows of cells in parallel: each writes only its own cells.
    detail::parallel_for(cv::Range(0, grid_h), [&](const cv::Range& cell_rows) {
      const int j_end = std::min(map.rows, cell_rows.end * block_px);
      for (int j = cell_rows.start * block_px; j < j_end; ++j) {
        const float* g = grey.ptr<float>(j);
        const std::uint8_t* use = usable.ptr<std::uint8_t>(j);
        const std::uint8_t* m = map.ptr<std::uint8_t>(j);
        const std::size_t row = static_cast<std::size_t>(j / block_px) * grid_w;
        for (int i = 0; i < map.cols; ++i) {
          const std::size_t c = row + cell_of_column[static_cast<std::size_t>(i)];
          if (m[i] == reflector_value) ++s.reflector_px[c];
          int& pure = s.pure[c];
          if (!use[i]) {
            pure = kNotPure;
            continue;
          }
          if (pure == kNoPixelYet)
            pure = m[i];
          else if (pure != m[i])
            pure = kNotPure;
          s.count[c] += 1.0;
          s.sum[c] += g[i];
          s.sum_sq[c] += static_cast<double>(g[i]) * g[i];
        }
      }
    });
    return s;
  }

  // Running appearance models from the interiors of the threshold labelling: the cells all of
  // whose pixels, and all of whose four neighbours' pixels, are usable and of one label (the
  // pixels whose label the blur of an edge cannot have changed), from the cells' sums.
  void learn(const CellSums& sums) {
    const std::size_t labels = values.size();
    std::vector<double> n(labels, 0.0), sum(labels, 0.0), sum_sq(labels, 0.0);
    std::array<int, 256> index{};
    index.fill(-1);
    for (std::size_t k = 0; k < labels; ++k) index[values[k]] = static_cast<int>(k);
    for (int cj = 1; cj + 1 < grid_h; ++cj)
      for (int ci = 1; ci + 1 < grid_w; ++ci) {
        const std::size_t c = static_cast<std::size_t>(cj) * grid_w + ci;
        const int value = sums.pure[c];
        if (value < 0 || sums.pure[c - 1] != value || sums.pure[c + 1] != value ||
            sums.pure[c - grid_w] != value || sums.pure[c + grid_w] != value)
          continue;
        const int k = index[static_cast<std::size_t>(value)];
        if (k < 0) continue;
        n[static_cast<std::size_t>(k)] += sums.count[c];
        sum[static_cast<std::size_t>(k)] += sums.sum[c];
        sum_sq[static_cast<std::size_t>(k)] += sums.sum_sq[c];
      }
    for (std::size_t k = 0; k < labels; ++k) {
      if (static_cast<int>(k) == reflector || n[k] < kMinModelPixels) continue;
      const double mean = sum[k] / n[k];
      const double variance = std::max(1.0, sum_sq[k] / n[k] - mean * mean);
      const double w = options.model_update;
      models[k].mean = (1.0 - w) * models[k].mean + w * mean;
      models[k].variance = (1.0 - w) * models[k].variance + w * variance;
    }
  }

  void refine(cv::Mat& map, const cv::Mat& grey, const cv::Mat& low, const cv::Mat& sector,
              const LabelImage* prior) {
    const cv::Mat usable = sector & ~low & (map != kLabelPixelUnknown);
    const std::size_t cells = static_cast<std::size_t>(grid_w) * grid_h;
    const std::size_t labels = values.size();
    const CellSums sums = cell_sums(map, grey, usable);
    learn(sums);
    const std::vector<double>& count = sums.count;
    // The threshold labelling seeds the cut: each cell starts with its centre pixel's label,
    // a cell mostly of reflector pixels with the reflector's.
    std::vector<std::uint8_t> start(cells, 0), reflector_cell(cells, 0);
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci) {
        const std::size_t c = static_cast<std::size_t>(cj) * grid_w + ci;
        const int i = std::min(map.cols - 1, ci * block_px + block_px / 2);
        const int j = std::min(map.rows - 1, cj * block_px + block_px / 2);
        start[c] = static_cast<std::uint8_t>(std::max(0, index_of(map.at<std::uint8_t>(j, i))));
        reflector_cell[c] = reflector >= 0 && 2 * sums.reflector_px[c] > count[c];
        if (reflector_cell[c]) start[c] = static_cast<std::uint8_t>(reflector);
      }
    std::optional<PriorCells> predicted;
    if (prior) predicted = prior_cells(*prior, count, start);
    // The cut starts from the threshold labelling without its speckle grains; a cell whose
    // label differs from the threshold labelling's at the end moves its pixels.
    const std::vector<std::uint8_t> threshold_start = start;
    drop_small_start_regions(start, count, reflector_cell, predicted);
    // Only cells near a boundary of the starting labelling, or where the prior disagrees with
    // it, can change at an optimum of reasonable weights: the cut runs on that band, and the
    // cells outside it enter as fixed neighbours (their Potts terms become unary ones). Costs
    // and weights are needed on the band alone.
    const std::vector<std::uint8_t> band = changeable_band(
        start, count, predicted ? predicted->disagrees : std::vector<std::uint8_t>{});
    std::vector<float> cost(cells * labels, 0.0f);
    band_costs(sums, reflector_cell, band, cost);
    if (predicted) add_prior(*predicted, count, band, cost);
    std::vector<float> right(cells, 0.0f), down(cells, 0.0f);
    potts_weights(sums, band, right, down);
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci) {
        const std::size_t c = static_cast<std::size_t>(cj) * grid_w + ci;
        if (!band[c]) continue;
        auto fixed_neighbour = [&](std::size_t d, float w) {
          if (band[d] || count[d] == 0.0 || w == 0.0f) return;
          for (std::size_t l = 0; l < labels; ++l)
            if (l != start[d]) cost[c * labels + l] += w;
        };
        if (ci + 1 < grid_w) fixed_neighbour(c + 1, right[c]);
        if (ci > 0) fixed_neighbour(c - 1, right[c - 1]);
        if (cj + 1 < grid_h) fixed_neighbour(c + static_cast<std::size_t>(grid_w), down[c]);
        if (cj > 0) fixed_neighbour(c - static_cast<std::size_t>(grid_w), down[c - grid_w]);
      }
    detail::GridLabelling cut(grid_w, grid_h, band, static_cast<int>(labels));
    const std::vector<std::uint8_t> initial = start;
    cut.minimise(cost, right, down, start, options.cycles);
    revert_new_regions(start, initial, predicted);

    // The cut decides cells; where it keeps a cell's starting label the threshold labelling's
    // pixels stay (their boundaries are finer than a cell), elsewhere the cell's pixels move.
    const int reflector_value = reflector >= 0 ? values[static_cast<std::size_t>(reflector)] : -1;
    for (std::size_t c = 0; c < cells; ++c) {
      if (start[c] == threshold_start[c] || count[c] == 0.0) continue;
      const int ci = static_cast<int>(c % static_cast<std::size_t>(grid_w));
      const int cj = static_cast<int>(c / static_cast<std::size_t>(grid_w));
      const int i_end = std::min(map.cols, (ci + 1) * block_px);
      const int j_end = std::min(map.rows, (cj + 1) * block_px);
      for (int j = cj * block_px; j < j_end; ++j) {
        const std::uint8_t* use = usable.ptr<std::uint8_t>(j);
        std::uint8_t* m = map.ptr<std::uint8_t>(j);
        for (int i = ci * block_px; i < i_end; ++i)
          if (use[i] && m[i] != reflector_value) m[i] = values[start[c]];
      }
    }
  }

  // The band cells' costs: each label's negative log-likelihood of the cell's grey under its
  // Gaussian model, less the cell's lowest; a reflector cell takes only the reflector and the
  // others never.
  void band_costs(const CellSums& sums, const std::vector<std::uint8_t>& reflector_cell,
                  const std::vector<std::uint8_t>& band, std::vector<float>& cost) const {
    const std::size_t labels = values.size();
    std::vector<double> half_log_variance(labels), half_precision(labels);
    for (std::size_t l = 0; l < labels; ++l) {
      half_log_variance[l] = 0.5 * std::log(models[l].variance);
      half_precision[l] = 0.5 / models[l].variance;
    }
    for (std::size_t c = 0; c < band.size(); ++c) {
      if (!band[c]) continue;
      const double n = sums.count[c];
      double lowest = 1e300;
      for (std::size_t l = 0; l < labels && n > 0.0; ++l) {
        const double mean = models[l].mean;
        const double squares = sums.sum_sq[c] - 2.0 * mean * sums.sum[c] + n * mean * mean;
        const double e = n * half_log_variance[l] + squares * half_precision[l];
        cost[c * labels + l] = static_cast<float>(e);
        lowest = std::min(lowest, e);
      }
      for (std::size_t l = 0; l < labels; ++l) {
        float& e = cost[c * labels + l];
        if (n > 0.0) e -= static_cast<float>(lowest);
        if (reflector >= 0 && (static_cast<int>(l) == reflector) != (reflector_cell[c] != 0))
          e = kExcluded;
        else if (reflector_cell[c])
          e = 0.0f;
      }
    }
  }

  // Contrast-sensitive Potts weights between neighbouring cells (right[c]: c and the cell to
  // its right; down[c]: c and the one below), where one of the two is on the band: cheap to cut
  // where the grey changes by much more than one tissue's spread.
  void potts_weights(const CellSums& sums, const std::vector<std::uint8_t>& band,
                     std::vector<float>& right, std::vector<float>& down) const {
    double mean_variance = 0.0;
    for (const Appearance& a : models) mean_variance += a.variance;
    mean_variance /= static_cast<double>(models.size());
    const double per_edge = options.smoothness * block_px;
    const double half_precision = 0.5 / mean_variance;
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci) {
        const std::size_t c = static_cast<std::size_t>(cj) * grid_w + ci;
        if (sums.count[c] == 0.0) continue;
        const double g = sums.sum[c] / sums.count[c];
        auto weight = [&](std::size_t d) {
          if (sums.count[d] == 0.0 || !(band[c] || band[d])) return 0.0f;
          const double diff = g - sums.sum[d] / sums.count[d];
          return static_cast<float>(per_edge * std::exp(-diff * diff * half_precision));
        };
        if (ci + 1 < grid_w) right[c] = weight(c + 1);
        if (cj + 1 < grid_h) down[c] = weight(c + static_cast<std::size_t>(grid_w));
      }
  }

  // Gives each connected region of look-alike labels its organ's identity (see segment()).
  void assign_identities(cv::Mat& map, const LabelImage* prior, const ImagePlane* plane) const {
    for (const std::vector<int>& group : look_alikes) {
      cv::Mat member(map.size(), CV_8U, cv::Scalar(0));
      for (const int k : group) member |= map == values[static_cast<std::size_t>(k)];
      cv::Mat regions, stats, centroids;
      const int n = cv::connectedComponentsWithStats(member, regions, stats, centroids, 8, CV_32S);
      if (n <= 1) continue;
      const std::vector<int> overlap = predicted_overlap(regions, n, group, prior);
      const std::size_t g_count = group.size();
      for (int r = 1; r < n; ++r) {
        const cv::Rect box(stats.at<int>(r, cv::CC_STAT_LEFT), stats.at<int>(r, cv::CC_STAT_TOP),
                           stats.at<int>(r, cv::CC_STAT_WIDTH),
                           stats.at<int>(r, cv::CC_STAT_HEIGHT));
        const double area = stats.at<int>(r, cv::CC_STAT_AREA);
        std::vector<std::uint8_t> predicted;
        for (std::size_t g = 0; g < g_count; ++g)
          if (overlap[static_cast<std::size_t>(r) * g_count + g] >= kPredictedShare * area)
            predicted.push_back(values[static_cast<std::size_t>(group[g])]);
        if (predicted.size() > 1) {
          split_by_prediction(map, regions, r, box, predicted, *prior);
          continue;
        }
        std::uint8_t label = 0;
        if (predicted.size() == 1)
          label = predicted[0];
        else if (plane)
          label =
              nearest_seed(group, *plane, centroids.at<double>(r, 0), centroids.at<double>(r, 1));
        if (label == 0) continue;
        cv::Mat part = map(box);
        part.setTo(label, regions(box) == r);
      }
    }
  }

  // Per region (rows) and group member (columns): the region's pixels the prior predicts as it.
  std::vector<int> predicted_overlap(const cv::Mat& regions, int n, const std::vector<int>& group,
                                     const LabelImage* prior) const {
    std::vector<int> overlap(static_cast<std::size_t>(n) * group.size(), 0);
    if (!prior) return overlap;
    std::array<int, 256> member_of{};
    member_of.fill(-1);
    for (std::size_t g = 0; g < group.size(); ++g)
      member_of[values[static_cast<std::size_t>(group[g])]] = static_cast<int>(g);
    for (int j = 0; j < regions.rows; ++j) {
      const int* region = regions.ptr<int>(j);
      const std::uint8_t* p = prior->pixels.data() + static_cast<std::size_t>(j) * prior->width;
      for (int i = 0; i < regions.cols; ++i)
        if (region[i] > 0 && member_of[p[i]] >= 0)
          ++overlap[static_cast<std::size_t>(region[i]) * group.size() +
                    static_cast<std::size_t>(member_of[p[i]])];
    }
    return overlap;
  }

  // A region over several predicted organs: each pixel takes the organ predicted nearest it.
  static void split_by_prediction(cv::Mat& map, const cv::Mat& regions, int r, const cv::Rect& box,
                                  const std::vector<std::uint8_t>& predicted,
                                  const LabelImage& prior) {
    const cv::Mat prior_box = cv::Mat(prior.height, prior.width, CV_8U,
                                      const_cast<std::uint8_t*>(prior.pixels.data()))(box);
    cv::Mat nearest(box.size(), CV_32F, cv::Scalar(std::numeric_limits<float>::max()));
    cv::Mat label(box.size(), CV_8U, cv::Scalar(predicted[0]));
    for (const std::uint8_t value : predicted) {
      cv::Mat distance;
      cv::distanceTransform(prior_box != value, distance, cv::DIST_L2, 3);
      const cv::Mat closer = distance < nearest;
      distance.copyTo(nearest, closer);
      label.setTo(value, closer);
    }
    label.copyTo(map(box), regions(box) == r);
  }

  // The look-alike whose seed lies nearest the region's centroid (pixel column x, row y); 0
  // when none of the group has a seed.
  std::uint8_t nearest_seed(const std::vector<int>& group, const ImagePlane& plane, double x,
                            double y) const {
    const Vec2 a = plane.to_plane(x, y);
    const Vec3 at = plane.origin_mm + a.x() * plane.u + a.y() * plane.v;
    std::uint8_t best = 0;
    double best_mm = std::numeric_limits<double>::infinity();
    for (const int k : group) {
      const LabelModel& m = config.materials[static_cast<std::size_t>(k) - 1];
      if (!m.seed_mm) continue;
      const double mm = (*m.seed_mm - at).norm();
      if (mm < best_mm) best_mm = mm, best = values[static_cast<std::size_t>(k)];
    }
    return best;
  }

  // Cells within kBandCells of a cell whose starting label differs from a neighbour's, or of a
  // cell whose prior disagrees with its starting label (and that has pixels to decide).
  std::vector<std::uint8_t> changeable_band(
      const std::vector<std::uint8_t>& start, const std::vector<double>& count,
      const std::vector<std::uint8_t>& prior_disagrees) const {
    cv::Mat seed(grid_h, grid_w, CV_8U, cv::Scalar(0));
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci) {
        const std::size_t c = static_cast<std::size_t>(cj) * grid_w + ci;
        if (count[c] == 0.0) continue;
        const bool edge =
            (ci + 1 < grid_w && count[c + 1] > 0.0 && start[c + 1] != start[c]) ||
            (cj + 1 < grid_h && count[c + grid_w] > 0.0 && start[c + grid_w] != start[c]);
        if (edge || (!prior_disagrees.empty() && prior_disagrees[c])) {
          seed.at<std::uint8_t>(cj, ci) = 255;
          if (ci + 1 < grid_w) seed.at<std::uint8_t>(cj, ci + 1) = 255;
          if (cj + 1 < grid_h) seed.at<std::uint8_t>(cj + 1, ci) = 255;
        }
      }
    cv::dilate(seed, seed,
               cv::getStructuringElement(cv::MORPH_RECT,
                                         cv::Size(2 * kBandCells + 1, 2 * kBandCells + 1)));
    std::vector<std::uint8_t> band(static_cast<std::size_t>(grid_w) * grid_h, 0);
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci) {
        const std::size_t c = static_cast<std::size_t>(cj) * grid_w + ci;
        band[c] = seed.at<std::uint8_t>(cj, ci) && count[c] > 0.0;
      }
    return band;
  }

  // What the prior predicts of each cell: its label index (-1: nothing) and the confidence,
  // which grows from nothing on the prediction's own boundaries (where the reconstruction is
  // least sure) to full prior_margin_mm inside its regions; and where it disagrees with `start`.
  struct PriorCells {
    std::vector<int> expected;
    std::vector<float> confidence;
    std::vector<std::uint8_t> disagrees;
  };

  PriorCells prior_cells(const LabelImage& prior, const std::vector<double>& count,
                         const std::vector<std::uint8_t>& start) const {
    if (prior.width != geometry.width_px || prior.height != geometry.height_px)
      throw std::invalid_argument("GraphCutLabeller: the prior label map is " +
                                  std::to_string(prior.width) + "x" + std::to_string(prior.height) +
                                  ", the frames " + std::to_string(geometry.width_px) + "x" +
                                  std::to_string(geometry.height_px));
    cv::Mat predicted(grid_h, grid_w, CV_8U);
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci)
        predicted.at<std::uint8_t>(cj, ci) =
            prior.at(std::min(prior.width - 1, ci * block_px + block_px / 2),
                     std::min(prior.height - 1, cj * block_px + block_px / 2));
    cv::Mat interior(grid_h, grid_w, CV_8U, cv::Scalar(255));
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci) {
        const std::uint8_t v = predicted.at<std::uint8_t>(cj, ci);
        const bool edge = (ci + 1 < grid_w && predicted.at<std::uint8_t>(cj, ci + 1) != v) ||
                          (cj + 1 < grid_h && predicted.at<std::uint8_t>(cj + 1, ci) != v) ||
                          (ci > 0 && predicted.at<std::uint8_t>(cj, ci - 1) != v) ||
                          (cj > 0 && predicted.at<std::uint8_t>(cj - 1, ci) != v);
        if (edge || v == kLabelPixelUnknown) interior.at<std::uint8_t>(cj, ci) = 0;
      }
    cv::Mat distance;
    cv::distanceTransform(interior, distance, cv::DIST_L2, 3);
    const double cell_mm = block_px * geometry.spacing_mm;
    const std::size_t cells = count.size();
    PriorCells out{std::vector<int>(cells, -1), std::vector<float>(cells, 0.0f),
                   std::vector<std::uint8_t>(cells, 0)};
    for (int cj = 0; cj < grid_h; ++cj)
      for (int ci = 0; ci < grid_w; ++ci) {
        const std::size_t c = static_cast<std::size_t>(cj) * grid_w + ci;
        const int expected = index_of(predicted.at<std::uint8_t>(cj, ci));
        if (expected < 0 || count[c] == 0.0) continue;
        out.expected[c] = expected;
        out.disagrees[c] = start[c] != expected;
        out.confidence[c] = static_cast<float>(
            std::min(1.0, distance.at<float>(cj, ci) * cell_mm / options.prior_margin_mm));
      }
    return out;
  }

  // Material regions of the starting labelling smaller than min_region_mm2 that the prior does
  // not predict start as the label around them. They are speckle grains the threshold's cleaning
  // would remove; left in, the cut's smoothness merges neighbouring grains into regions larger
  // than that (dark speckle at depth came out as 24-30 mm2 pieces of a hypoechoic organ in frames
  // where no organ is), and the cleaning after the cut no longer removes them. Without a
  // boundary there the cut leaves such areas alone.
  void drop_small_start_regions(std::vector<std::uint8_t>& start, const std::vector<double>& count,
                                const std::vector<std::uint8_t>& reflector_cell,
                                const std::optional<PriorCells>& predicted) const {
    const double min_px = config.min_region_mm2 / (geometry.spacing_mm * geometry.spacing_mm);
    for_each_material_regions(start, [&](std::size_t l, const cv::Mat& regions, int n) {
      const int* region_of = regions.ptr<int>(0);  // continuous: one row after another
      std::vector<double> area_px(static_cast<std::size_t>(n), 0.0);
      std::vector<double> predicted_px(static_cast<std::size_t>(n), 0.0);
      for (std::size_t c = 0; c < start.size(); ++c) {
        const int r = region_of[c];
        if (r == 0) continue;
        area_px[static_cast<std::size_t>(r)] += count[c];
        if (predicted && predicted->expected[c] == static_cast<int>(l))
          predicted_px[static_cast<std::size_t>(r)] += count[c];
      }
      // Each small region takes the most common label among the cells around it.
      std::vector<std::array<int, 256>> around(static_cast<std::size_t>(n));
      for (auto& a : around) a.fill(0);
      for (int cj = 0; cj < grid_h; ++cj)
        for (int ci = 0; ci < grid_w; ++ci) {
          const int r = regions.at<int>(cj, ci);
          if (r == 0) continue;
          const auto count_neighbour = [&](int i, int j) {
            if (i < 0 || j < 0 || i >= grid_w || j >= grid_h || regions.at<int>(j, i) == r) return;
            const std::size_t d = static_cast<std::size_t>(j) * grid_w + i;
            if (count[d] > 0.0 && !reflector_cell[d])
              ++around[static_cast<std::size_t>(r)][start[d]];
          };
          count_neighbour(ci - 1, cj);
          count_neighbour(ci + 1, cj);
          count_neighbour(ci, cj - 1);
          count_neighbour(ci, cj + 1);
        }
      for (std::size_t c = 0; c < start.size(); ++c) {
        const auto r = static_cast<std::size_t>(region_of[c]);
        if (r == 0 || area_px[r] >= min_px || 2.0 * predicted_px[r] >= area_px[r]) continue;
        const auto& a = around[r];
        const auto most = std::max_element(a.begin(), a.end());
        if (*most > 0) start[c] = static_cast<std::uint8_t>(most - a.begin());
      }
    });
  }

  // The cut refines the boundaries of the regions the starting labelling found and the prior
  // predicts; it does not make new ones. A region of a material in `cut` that holds no cell of
  // that material in `start` and none the prior predicts as it goes back to `start`: summed over
  // a cell's pixels, the likelihood of dark speckle can outweigh the smoothness, and the cut
  // grew speckle grains at depth into pieces of a hypoechoic organ.
  void revert_new_regions(std::vector<std::uint8_t>& cut, const std::vector<std::uint8_t>& start,
                          const std::optional<PriorCells>& predicted) const {
    for_each_material_regions(cut, [&](std::size_t l, const cv::Mat& regions, int n) {
      std::vector<std::uint8_t> anchored(static_cast<std::size_t>(n), 0);
      const int* r = regions.ptr<int>(0);  // continuous: one row after another
      for (std::size_t c = 0; c < cut.size(); ++c)
        if (r[c] > 0 &&
            (start[c] == l || (predicted && predicted->expected[c] == static_cast<int>(l))))
          anchored[static_cast<std::size_t>(r[c])] = 1;
      for (std::size_t c = 0; c < cut.size(); ++c)
        if (r[c] > 0 && !anchored[static_cast<std::size_t>(r[c])]) cut[c] = start[c];
    });
  }

  // Calls visit(l, regions, n) for every material label l but the reflector whose cells in
  // `labels` form regions: `regions` numbers each cell's 8-connected region of l (1..n-1, 0
  // elsewhere). `labels` may change in a visit; later labels see the change.
  template <typename Visit>
  void for_each_material_regions(std::vector<std::uint8_t>& labels, Visit&& visit) const {
    const cv::Mat grid(grid_h, grid_w, CV_8U, labels.data());
    for (std::size_t l = 1; l < values.size(); ++l) {
      if (static_cast<int>(l) == reflector) continue;
      cv::Mat regions;
      const int n = cv::connectedComponents(grid == static_cast<int>(l), regions, 8, CV_32S);
      if (n > 1) visit(l, regions, n);
    }
  }

  // Disagreeing with the prediction costs prior_weight per pixel, scaled by its confidence.
  void add_prior(const PriorCells& predicted, const std::vector<double>& count,
                 const std::vector<std::uint8_t>& band, std::vector<float>& cost) const {
    const std::size_t labels = values.size();
    for (std::size_t c = 0; c < count.size(); ++c) {
      const int expected = predicted.expected[c];
      if (!band[c] || expected < 0) continue;
      const auto penalty =
          static_cast<float>(options.prior_weight * count[c] * predicted.confidence[c]);
      for (std::size_t l = 0; l < labels; ++l)
        if (static_cast<int>(l) != expected && cost[c * labels + l] < kExcluded)
          cost[c * labels + l] += penalty;
    }
  }
};

GraphCutLabeller::GraphCutLabeller(const SegmentationConfig& config, const ImageGeometry& geometry,
                                   const GraphCutOptions& options)
    : impl_(std::make_unique<Impl>(config, geometry, options)) {}
GraphCutLabeller::~GraphCutLabeller() = default;
GraphCutLabeller::GraphCutLabeller(GraphCutLabeller&&) noexcept = default;
GraphCutLabeller& GraphCutLabeller::operator=(GraphCutLabeller&&) noexcept = default;

const SegmentationConfig& GraphCutLabeller::config() const { return impl_->config; }
const ImageGeometry& GraphCutLabeller::geometry() const { return impl_->geometry; }

Segmentation GraphCutLabeller::segment(const GreyImage& image, const LabelImage* prior,
                                       const ImagePlane* plane) {
  return detail::segment_frame(image, impl_->geometry, impl_->config,
                               [&](cv::Mat& map, const cv::Mat& grey, const cv::Mat& low,
                                   const cv::Mat& sector, cv::Mat& keep) {
                                 impl_->refine(map, grey, low, sector, prior);
                                 impl_->assign_identities(map, prior, plane);
                                 // Small parts where the reconstruction predicts the same organ are
                                 // kept.
                                 if (prior) {
                                   const cv::Mat predicted(
                                       prior->height, prior->width, CV_8U,
                                       const_cast<std::uint8_t*>(prior->pixels.data()));
                                   keep = (map == predicted) & (predicted != kLabelPixelOutside) &
                                          (predicted != kLabelPixelUnknown);
                                 }
                               });
}

}  // namespace sonoshape::segmentation
