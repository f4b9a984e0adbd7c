#include "octree_field.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <initializer_list>
#include <iterator>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <unordered_set>

#include "key_masks.hpp"
#include "sonoshape/core/log.hpp"
#include "sorted_keys.hpp"

namespace sonoshape::recon {
namespace {

constexpr std::array<std::array<int, 3>, 6> kFaceNeighbours{
    {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}}};

// Copies one row of `count` function values. std::copy_n of two or three doubles became a call
// to memmove per row (perf profiles of online updates showed it in the smoothing's copies).
inline void copy_row(const double* from, std::size_t count, double* to) {
  if (count == 2) {
    to[0] = from[0];
    to[1] = from[1];
  } else if (count == 3) {
    to[0] = from[0];
    to[1] = from[1];
    to[2] = from[2];
  } else {
    for (std::size_t l = 0; l < count; ++l) to[l] = from[l];
  }
}

// Runs body(n) for n in [0, count) on the calling arena's threads; each n writes only its own rows.
template <typename Body>
void for_rows(std::size_t count, const Body& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t n = r.begin(); n < r.end(); ++n) body(n);
                    });
}

class Sampler {
 public:
  /// `pending_keys` is scratch space, emptied here; `valid` says per row of `field` whether its
  /// value is current (rows kept from an earlier pass may not be).
  Sampler(SampledField& field, const BatchEvaluator& evaluate, GridIndex& pending_keys,
          std::vector<char> valid)
      : field_(field), evaluate_(evaluate), pending_keys_(pending_keys), valid_(std::move(valid)) {
    pending_keys_.reset(1 << field.grid.depth);
  }

  /// The row of `key` if it has a current value (the row then counts as read in this pass), else
  /// GridIndex::kNone. Safe to call from several threads between flushes.
  std::uint32_t valid_row(std::uint64_t key) const {
    const std::uint32_t row = field_.index.find(key);
    if (row == GridIndex::kNone || !valid_[row]) return GridIndex::kNone;
    std::atomic_ref<std::uint32_t>(field_.row_pass[row])
        .store(field_.pass, std::memory_order_relaxed);
    return row;
  }
  bool has_value(std::uint64_t key) const { return valid_row(key) != GridIndex::kNone; }
  /// Counts a row as read in this pass without looking it up (its value is current).
  void mark_read(std::uint32_t row) const {
    std::atomic_ref<std::uint32_t>(field_.row_pass[row])
        .store(field_.pass, std::memory_order_relaxed);
  }
  /// Queues a vertex for evaluation unless it has a value or is queued.
  void request(int i, int j, int k) {
    const std::uint64_t key = grid_key(i, j, k);
    if (has_value(key) || !pending_keys_.insert(key, 0)) return;
    pending_.push_back(key);
  }
  /// Queues the vertices that generate(n, request) requests for n in [0, count), in parallel (each
  /// request returns the vertex's row, or GridIndex::kNone when it was queued): in
  /// an online update nearly all of them have values already, and the serial look-ups of those
  /// (hundreds of thousands per pass) were most of the octree passes' time. Queued in the order
  /// of n (each fixed chunk of n lists its own; sorting them instead cost more than the look-ups).
  template <typename Generate>
  void request_each(std::size_t count, const Generate& generate) {
    constexpr std::size_t kChunk = 512;
    std::vector<std::vector<std::uint64_t>> missing((count + kChunk - 1) / kChunk);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, missing.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t chunk = r.begin(); chunk < r.end(); ++chunk) {
                          std::vector<std::uint64_t>& local = missing[chunk];
                          // Returns the vertex's row, or GridIndex::kNone when it is queued for
                          // evaluation.
                          const auto request_one = [&](int i, int j, int k) {
                            const std::uint64_t key = grid_key(i, j, k);
                            const std::uint32_t row = valid_row(key);
                            if (row == GridIndex::kNone) local.push_back(key);
                            return row;
                          };
                          for (std::size_t n = chunk * kChunk;
                               n < std::min(count, (chunk + 1) * kChunk); ++n)
                            generate(n, request_one);
                        }
                      });
    for (const std::vector<std::uint64_t>& local : missing)
      for (const std::uint64_t key : local) queue(key);
  }
  /// Queues a vertex that has no current value (valid_row gave kNone) unless it is queued.
  void queue(std::uint64_t key) {
    if (pending_keys_.insert(key, 0)) pending_.push_back(key);
  }
  /// Evaluates every queued vertex in one parallel batch. Only the new rows are appended
  /// serially (in queue order); the rest runs in parallel (the serial copy of every value
  /// was a part of each pass that an online update's re-evaluated end cap made long).
  void flush() {
    if (pending_.empty()) return;
    const std::size_t count = pending_.size();
    std::vector<Vec3> points(count);
    std::vector<std::uint32_t> rows(count);  // a kept row whose value was out of date, or kNone
    for_rows(count, [&](std::size_t n) {
      int i, j, k;
      grid_unkey(pending_[n], i, j, k);
      points[n] = field_.grid.position(i, j, k);
      rows[n] = field_.index.find(pending_[n]);
    });
    const std::size_t fc = static_cast<std::size_t>(field_.function_count);
    std::vector<double> evaluated(count * fc);
    std::vector<std::uint64_t> tags(count, 0);
    evaluate_(points, evaluated.data(), tags.data());
    for (std::size_t n = 0; n < count; ++n)
      if (rows[n] == GridIndex::kNone) {
        rows[n] = static_cast<std::uint32_t>(field_.keys.size());
        field_.index.insert(pending_[n], rows[n]);
        field_.keys.push_back(pending_[n]);
      }
    const std::size_t row_count = field_.keys.size();
    field_.values.resize(row_count * fc);
    field_.row_labels.resize(row_count, 0);
    field_.row_tags.resize(row_count, 0);
    field_.row_pass.resize(row_count, field_.pass);
    valid_.resize(row_count, 1);
    for_rows(count, [&](std::size_t n) {
      const std::uint32_t row = rows[n];
      copy_row(evaluated.data() + n * fc, fc, field_.values.data() + row * fc);
      field_.set_row_label(row);
      field_.row_tags[row] = tags[n];
      field_.row_pass[row] = field_.pass;
      valid_[row] = 1;
    });
    field_.evaluations += count;
    pending_.clear();
    pending_keys_.clear();
  }

 private:
  SampledField& field_;
  const BatchEvaluator& evaluate_;
  std::vector<std::uint64_t> pending_;
  GridIndex& pending_keys_;  // the keys of pending_, for de-duplication
  std::vector<char> valid_;  // per row of the field
};

// Sorts and de-duplicates keys: the sets of the octree stages are built in bulk, then queried,
// where std::unordered_set's node allocations cost more than the whole smoothing arithmetic.
void sort_unique(std::vector<std::uint64_t>& keys) {
  tbb::parallel_sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
}

bool contains(const std::vector<std::uint64_t>& sorted, std::uint64_t key) {
  return std::binary_search(sorted.begin(), sorted.end(), key);
}

// The cell whose min corner is (i, j, k) with side `step`, from its corners' rows as a request
// pass found them: fills those it left at GridIndex::kNone (evaluated since), and tells whether
// the corners' labels differ. The mixed tests of the refinement and the band closure read these
// rows instead of looking every corner up a second time.
bool corners_mixed(const SampledField& f, std::array<std::uint32_t, 8>& rows, int i, int j, int k,
                   int step) {
  for (int corner = 0; corner < 8; ++corner)
    if (rows[static_cast<std::size_t>(corner)] == GridIndex::kNone)
      rows[static_cast<std::size_t>(corner)] = f.index.at(grid_key(
          i + (corner & 1) * step, j + ((corner >> 1) & 1) * step, k + ((corner >> 2) & 1) * step));
  const int first = f.row_label(rows[0]);
  for (std::size_t corner = 1; corner < 8; ++corner)
    if (f.row_label(rows[corner]) != first) return true;
  return false;
}

// The corners of a finest cell on its face towards kFaceNeighbours[d]: corner c has offset
// (c & 1, (c >> 1) & 1, (c >> 2) & 1).
constexpr std::array<std::array<int, 4>, 6> kFaceCorners{
    {{0, 2, 4, 6}, {1, 3, 5, 7}, {0, 1, 4, 5}, {2, 3, 6, 7}, {0, 1, 2, 3}, {4, 5, 6, 7}}};

// Keeps the mixed cells among `seeds` (they may repeat; with `seed_rows`, all are mixed, with
// current corner values, as the refinement's finest cells, and those are their corner rows) and
// adds, until closed, every finest cell across a face with mixed corners: otherwise the surface
// would end at that face. `closed` is a band that was closed before labels changed at corners of
// seeds only: its other cells kept their corner labels, so they are still mixed (every band cell
// is) and their faces need not be expanded again. Result in field.surface_cells. `in_band` is
// scratch space (a direct table is costly to allocate). The faces are tested on the corner rows
// the mixed tests found (looking the four corners of each of six faces up again cost more than
// the rest of the closure).
using CornerRows = std::array<std::uint32_t, 8>;

// The mixed cells of `cells` and their corner rows, in their order, their corners evaluated
// first where they have no value (the tests run in parallel).
void mixed_cells_of(SampledField& field, Sampler& sampler, const std::vector<std::uint64_t>& cells,
                    std::vector<std::uint64_t>& kept, std::vector<CornerRows>& kept_rows) {
  std::vector<CornerRows> corner_rows(cells.size());
  sampler.request_each(cells.size(), [&](std::size_t n, const auto& request) {
    int i, j, k;
    grid_unkey(cells[n], i, j, k);
    for (int corner = 0; corner < 8; ++corner)
      corner_rows[n][static_cast<std::size_t>(corner)] =
          request(i + (corner & 1), j + ((corner >> 1) & 1), k + ((corner >> 2) & 1));
  });
  sampler.flush();
  std::vector<char> is_mixed(cells.size());
  for_rows(cells.size(), [&](std::size_t n) {
    int i, j, k;
    grid_unkey(cells[n], i, j, k);
    is_mixed[n] = corners_mixed(field, corner_rows[n], i, j, k, 1);
  });
  kept.clear();
  kept_rows.clear();
  for (std::size_t n = 0; n < cells.size(); ++n)
    if (is_mixed[n]) {
      kept.push_back(cells[n]);
      kept_rows.push_back(corner_rows[n]);
    }
}

// The cells across the mixed faces of the frontier's cells that are in neither `in_band` nor
// `closed`, added to `in_band`: a bit per direction per frontier cell in parallel, then the
// cells in order.
std::vector<std::uint64_t> cells_across_mixed_faces(const SampledField& field,
                                                    const std::vector<std::uint64_t>& frontier,
                                                    const std::vector<CornerRows>& frontier_rows,
                                                    const std::vector<std::uint64_t>& closed,
                                                    GridIndex& in_band, int resolution) {
  std::vector<std::uint8_t> across(frontier.size());
  for_rows(frontier.size(), [&](std::size_t n) {
    int i, j, k;
    grid_unkey(frontier[n], i, j, k);
    std::array<int, 8> labels;
    for (std::size_t c = 0; c < 8; ++c) labels[c] = field.row_label(frontier_rows[n][c]);
    std::uint8_t bits = 0;
    for (std::size_t d = 0; d < kFaceNeighbours.size(); ++d) {
      const int ni = i + kFaceNeighbours[d][0], nj = j + kFaceNeighbours[d][1],
                nk = k + kFaceNeighbours[d][2];
      if (ni < 0 || nj < 0 || nk < 0 || ni >= resolution || nj >= resolution || nk >= resolution)
        continue;
      const std::array<int, 4>& face = kFaceCorners[d];
      const int first = labels[static_cast<std::size_t>(face[0])];
      const bool mixed = labels[static_cast<std::size_t>(face[1])] != first ||
                         labels[static_cast<std::size_t>(face[2])] != first ||
                         labels[static_cast<std::size_t>(face[3])] != first;
      if (mixed && !in_band.count(grid_key(ni, nj, nk)) && !contains(closed, grid_key(ni, nj, nk)))
        bits = static_cast<std::uint8_t>(bits | (1u << d));
    }
    across[n] = bits;
  });
  std::vector<std::uint64_t> candidates;
  for (std::size_t n = 0; n < frontier.size(); ++n) {
    if (across[n] == 0) continue;
    int i, j, k;
    grid_unkey(frontier[n], i, j, k);
    for (std::size_t d = 0; d < kFaceNeighbours.size(); ++d) {
      if (!((across[n] >> d) & 1u)) continue;
      const std::uint64_t nkey =
          grid_key(i + kFaceNeighbours[d][0], j + kFaceNeighbours[d][1], k + kFaceNeighbours[d][2]);
      if (in_band.insert(nkey, 0)) candidates.push_back(nkey);
    }
  }
  return candidates;
}

void close_band(SampledField& field, Sampler& sampler, const std::vector<std::uint64_t>& seeds,
                const std::vector<CornerRows>* seed_rows, GridIndex& in_band, int resolution,
                const std::vector<std::uint64_t>& closed = {}) {
  in_band.clear();
  std::vector<std::uint64_t> unique_seeds;
  std::vector<CornerRows> unique_seed_rows;
  unique_seeds.reserve(seeds.size());
  for (std::size_t n = 0; n < seeds.size(); ++n)
    if (in_band.insert(seeds[n], 0)) {
      unique_seeds.push_back(seeds[n]);
      if (seed_rows != nullptr) unique_seed_rows.push_back((*seed_rows)[n]);
    }
  std::vector<std::uint64_t> frontier;
  std::vector<CornerRows> frontier_rows;
  if (seed_rows != nullptr) {
    frontier = std::move(unique_seeds);
    frontier_rows = std::move(unique_seed_rows);
  } else {
    mixed_cells_of(field, sampler, unique_seeds, frontier, frontier_rows);
  }
  // The new cells: the mixed seeds and what the closure adds. The closed band is not put into
  // `in_band` (tens of thousands of serial inserts for a handful of seeds): its cells are found
  // by a search in it, and it is merged with the new cells at the end.
  std::vector<std::uint64_t> band = frontier;
  while (!frontier.empty()) {
    const std::vector<std::uint64_t> candidates =
        cells_across_mixed_faces(field, frontier, frontier_rows, closed, in_band, resolution);
    mixed_cells_of(field, sampler, candidates, frontier, frontier_rows);
    band.insert(band.end(), frontier.begin(), frontier.end());
  }
  tbb::parallel_sort(band.begin(), band.end());
  if (!closed.empty()) {
    // The closed band less the seeds (a seed is in the band only if it is still mixed, so it is
    // among the new cells or gone), merged with the new cells: both sorted, no key in both.
    tbb::parallel_sort(unique_seeds.begin(), unique_seeds.end());
    std::vector<std::uint64_t> kept;
    kept.reserve(closed.size());
    std::set_difference(closed.begin(), closed.end(), unique_seeds.begin(), unique_seeds.end(),
                        std::back_inserter(kept));
    std::vector<std::uint64_t> merged(kept.size() + band.size());
    std::merge(kept.begin(), kept.end(), band.begin(), band.end(), merged.begin());
    band = std::move(merged);
  }
  field.surface_cells = std::move(band);
}

void smooth(SampledField& field, Sampler& sampler, const std::vector<std::uint64_t>& fixed,
            int iterations, GridIndex& scratch, const std::vector<char>* valid_at_start,
            const OctreeWorkspace::SmoothingInputs& last, OctreeWorkspace::SmoothingInputs& next);
void snap_thin_regions(SampledField& field, Sampler& sampler,
                       const std::vector<RegionSample>& samples, GridIndex& scratch);

}  // namespace

Grid make_grid(const Box3& box, int depth) {
  Grid grid;
  grid.depth = depth;
  grid.cell_size = box.size().maxCoeff() / (1 << depth);
  grid.origin = box.min;
  return grid;
}

int default_depth(const Box3& box) {
  // Smallest depth whose finest cells are at most 1/128 of the diagonal.
  const double cells = box.size().maxCoeff() * 128.0 / box.diagonal();
  return std::clamp(static_cast<int>(std::ceil(std::log2(cells) - 1e-9)), 1, 11);
}

ContourKeys contour_keys(const Grid& grid, const OctreeOptions& options,
                         const std::vector<std::pair<Vec3, Vec3>>& segments) {
  const int depth = options.max_depth;
  const int resolution = 1 << depth;
  auto fine_index = [&](const Vec3& p) {
    const Vec3 q = (p - grid.origin) / grid.cell_size;
    return std::array<int, 3>{std::clamp(static_cast<int>(std::floor(q.x())), 0, resolution - 1),
                              std::clamp(static_cast<int>(std::floor(q.y())), 0, resolution - 1),
                              std::clamp(static_cast<int>(std::floor(q.z())), 0, resolution - 1)};
  };
  ContourKeys keys;
  keys.cells_by_level.resize(static_cast<std::size_t>(depth + 1));
  const int start = std::min(options.start_depth, depth);
  for (const auto& [a, b] : segments) {
    const auto idx = fine_index(a);
    for (int level = start; level <= depth; ++level) {
      const int shift = depth - level;
      keys.cells_by_level[static_cast<std::size_t>(level)].push_back(
          grid_key(idx[0] >> shift, idx[1] >> shift, idx[2] >> shift));
    }
    // Samples at half a cell find every cell the segment crosses.
    const int steps =
        std::max(1, static_cast<int>(std::ceil((b - a).norm() / (0.5 * grid.cell_size))));
    for (int s = 0; s <= steps; ++s) {
      const auto cell = fine_index(a + (b - a) * (static_cast<double>(s) / steps));
      for (int corner = 0; corner < 8; ++corner)
        keys.fixed_vertices.push_back(grid_key(
            cell[0] + (corner & 1), cell[1] + ((corner >> 1) & 1), cell[2] + ((corner >> 2) & 1)));
    }
  }
  for (auto& cells : keys.cells_by_level) sort_unique(cells);
  sort_unique(keys.fixed_vertices);
  return keys;
}

void merge_contour_keys(ContourKeys& keys, const ContourKeys& more) {
  auto merge = [](std::vector<std::uint64_t>& into, const std::vector<std::uint64_t>& add) {
    std::vector<std::uint64_t> merged;
    merged.reserve(into.size() + add.size());
    std::set_union(into.begin(), into.end(), add.begin(), add.end(), std::back_inserter(merged));
    into = std::move(merged);
  };
  keys.cells_by_level.resize(std::max(keys.cells_by_level.size(), more.cells_by_level.size()));
  for (std::size_t level = 0; level < more.cells_by_level.size(); ++level)
    merge(keys.cells_by_level[level], more.cells_by_level[level]);
  merge(keys.fixed_vertices, more.fixed_vertices);
}

SampledField sample_field(const Box3& box, int function_count, const BatchEvaluator& evaluate,
                          const ContourKeys& contours,
                          const std::vector<RegionSample>& region_samples,
                          const OctreeOptions& options) {
  OctreeWorkspace workspace;
  return sample_field(box, function_count, evaluate, contours, region_samples, options, workspace);
}

namespace {

// The last pass's field when it can be kept (same functions and grid, and the rows that kept
// their values are known): its rows go back to their values before the smoothing and the snap
// (latest change first), and its out-of-date rows are evaluated again when read. Otherwise a
// fresh field that keeps only the last pass's lookup table. `valid` gets the kept rows' flags.
bool take_previous_field(SampledField& field, OctreeWorkspace& workspace, const Grid& grid,
                         int function_count, std::vector<char>& valid) {
  SampledField& previous = workspace.previous;
  const bool kept = !workspace.previous_valid.empty() &&
                    workspace.previous_valid.size() == previous.keys.size() &&
                    previous.function_count == function_count &&
                    previous.grid.depth == grid.depth && previous.grid.origin == grid.origin &&
                    previous.grid.cell_size == grid.cell_size;
  if (kept) {
    field = std::move(previous);
    const std::size_t fc = static_cast<std::size_t>(function_count);
    for (std::size_t n = field.changed_rows.size(); n-- > 0;)
      copy_row(field.changed_values.data() + n * fc, fc,
               field.values.data() + field.changed_rows[n] * fc);
    for (const std::uint32_t row : field.changed_rows) field.set_row_label(row);
    field.changed_rows.clear();
    field.changed_values.clear();
    field.surface_cells.clear();
    field.evaluations = field.snapped_vertices = 0;
    field.smoothing_seconds = 0.0;
    ++field.pass;
    valid = std::move(workspace.previous_valid);
  } else {
    field.index = std::move(previous.index);
    field.index.reset(1 << grid.depth);
    field.function_count = function_count;
    field.grid = grid;
  }
  previous = SampledField{};
  workspace.previous_valid.clear();
  return kept;
}

// Coarse-to-fine refinement from options.start_depth to the finest level: cells whose corners
// have mixed labels or that hold contour vertices are split. Cells are given by their min corner
// in finest units. With a kept field, a cell the last pass also had (`before_index_`) and whose
// corner rows all kept their values keeps its mixed test: the test reads those values only.
// Validity is taken as it was at the start of the pass, before this pass evaluated rows again.
class Refinement {
 public:
  Refinement(SampledField& field, Sampler& sampler, const ContourKeys& contours,
             const std::vector<char>& valid_at_start,
             std::vector<OctreeWorkspace::RefinementLevel> before,
             std::vector<OctreeWorkspace::RefinementLevel>& levels)
      : field_(field),
        sampler_(sampler),
        contours_(contours),
        valid_at_start_(valid_at_start),
        before_(std::move(before)),
        levels_(levels) {}

  // The finest split cells' corner rows, in the order of field.surface_cells.
  std::vector<CornerRows> run(int start, int depth) {
    start_ = start;
    depth_ = depth;
    levels_.clear();
    const int resolution = 1 << depth;
    const int step = 1 << (depth - start);
    for (int i = 0; i < resolution; i += step)
      for (int j = 0; j < resolution; j += step)
        for (int k = 0; k < resolution; k += step) cells_.push_back({i, j, k});
    const bool same_start = !before_.empty() && before_.front().cells == cells_;
    before_index_.resize(cells_.size(), GridIndex::kNone);
    if (same_start)
      for (std::size_t n = 0; n < cells_.size(); ++n)
        before_index_[n] = static_cast<std::uint32_t>(n);
    for (int level = start;; ++level)
      if (!refine_level(level)) break;
    return std::move(finest_mixed_rows_);
  }

 private:
  // Tests and splits the cells of one level; false at the finest level.
  bool refine_level(int level) {
    const int step = 1 << (depth_ - level);
    const std::size_t level_index = static_cast<std::size_t>(level - start_);
    const OctreeWorkspace::RefinementLevel* last =
        level_index < before_.size() ? &before_[level_index] : nullptr;
    OctreeWorkspace::RefinementLevel now;
    now.corner_rows.resize(cells_.size());
    now.mixed.resize(cells_.size());
    now.split.resize(cells_.size());
    test_cells(last, step, now);
    if (level == depth_) {
      for_rows(cells_.size(), [&](std::size_t n) { now.split[n] = now.mixed[n]; });
      for (std::size_t n = 0; n < cells_.size(); ++n)
        if (now.split[n]) {
          field_.surface_cells.push_back(grid_key(cells_[n][0], cells_[n][1], cells_[n][2]));
          finest_mixed_rows_.push_back(now.corner_rows[n]);
        }
      now.cells = std::move(cells_);
      levels_.push_back(std::move(now));
      return false;
    }
    // Above the finest level, cells holding contour vertices are split too.
    const std::vector<char> holds_contours = contour_cells(level, step);
    for_rows(cells_.size(),
             [&](std::size_t n) { now.split[n] = now.mixed[n] || holds_contours[n] != 0; });
    std::vector<std::array<int, 3>> refined;
    std::vector<std::uint32_t> refined_before;
    children(last, now, step, refined, refined_before);
    now.cells = std::move(cells_);
    levels_.push_back(std::move(now));
    cells_ = std::move(refined);
    before_index_ = std::move(refined_before);
    return true;
  }

  // Each cell's corner rows and mixed test: kept from the last pass (in parallel) where its
  // corners kept their values, else looked up (as the request pass finds them, see
  // corners_mixed) and tested.
  void test_cells(const OctreeWorkspace::RefinementLevel* last, int step,
                  OctreeWorkspace::RefinementLevel& now) {
    std::vector<char> is_kept(cells_.size(), 0);
    if (last != nullptr)
      for_rows(cells_.size(), [&](std::size_t n) {
        if (before_index_[n] == GridIndex::kNone) return;
        const std::array<std::uint32_t, 8>& rows = last->corner_rows[before_index_[n]];
        for (const std::uint32_t row : rows)
          if (!valid_at_start_[row]) return;
        for (const std::uint32_t row : rows) sampler_.mark_read(row);
        now.corner_rows[n] = rows;
        now.mixed[n] = last->mixed[before_index_[n]];
        is_kept[n] = 1;
      });
    std::vector<std::uint32_t> tested;
    for (std::size_t n = 0; n < cells_.size(); ++n)
      if (!is_kept[n]) tested.push_back(static_cast<std::uint32_t>(n));
    sampler_.request_each(tested.size(), [&](std::size_t m, const auto& request) {
      const auto& c = cells_[tested[m]];
      std::array<std::uint32_t, 8>& rows = now.corner_rows[tested[m]];
      for (int corner = 0; corner < 8; ++corner)
        rows[static_cast<std::size_t>(corner)] =
            request(c[0] + (corner & 1) * step, c[1] + ((corner >> 1) & 1) * step,
                    c[2] + ((corner >> 2) & 1) * step);
    });
    sampler_.flush();
    for_rows(tested.size(), [&](std::size_t m) {
      const auto& c = cells_[tested[m]];
      now.mixed[tested[m]] =
          corners_mixed(field_, now.corner_rows[tested[m]], c[0], c[1], c[2], step);
    });
  }

  // Which cells of this level (above the finest) hold contour vertices, from a bit per cell
  // where the level is coarse enough, instead of a binary search in the level's contour cells
  // for every cell.
  std::vector<char> contour_cells(int level, int step) const {
    std::vector<char> holds(cells_.size(), 0);
    const auto contour_level = static_cast<std::size_t>(level);
    if (contour_level >= contours_.cells_by_level.size()) return holds;
    const std::vector<std::uint64_t>& keys = contours_.cells_by_level[contour_level];
    constexpr int kMaxBitLevel = 8;  // 2^24 bits, 2 MiB
    const auto bit_of = [level](int i, int j, int k) {
      return (static_cast<std::size_t>(i) << (2 * level)) | (static_cast<std::size_t>(j) << level) |
             static_cast<std::size_t>(k);
    };
    std::vector<std::uint64_t> bits;
    if (level <= kMaxBitLevel) {
      bits.assign(((std::size_t{1} << (3 * level)) + 63) / 64, 0);
      for (const std::uint64_t key : keys) {
        int i, j, k;
        grid_unkey(key, i, j, k);
        const std::size_t bit = bit_of(i, j, k);
        bits[bit / 64] |= std::uint64_t{1} << (bit % 64);
      }
    }
    for_rows(cells_.size(), [&](std::size_t n) {
      const std::array<int, 3>& c = cells_[n];
      if (bits.empty()) {
        holds[n] = contains(keys, grid_key(c[0] / step, c[1] / step, c[2] / step));
        return;
      }
      const std::size_t bit = bit_of(c[0] / step, c[1] / step, c[2] / step);
      holds[n] = ((bits[bit / 64] >> (bit % 64)) & 1u) != 0;
    });
    return holds;
  }

  // The children of the split cells, in order; a child's index in the last pass is found from
  // its parent's: children follow their parents' order, eight each.
  void children(const OctreeWorkspace::RefinementLevel* last,
                const OctreeWorkspace::RefinementLevel& now, int step,
                std::vector<std::array<int, 3>>& refined,
                std::vector<std::uint32_t>& refined_before) const {
    std::vector<std::uint32_t> last_child_start;
    if (last != nullptr) {
      last_child_start.resize(last->split.size());
      std::uint32_t children = 0;
      for (std::size_t q = 0; q < last->split.size(); ++q) {
        last_child_start[q] = children;
        if (last->split[q]) children += 8;
      }
    }
    const int half = step / 2;
    for (std::size_t n = 0; n < cells_.size(); ++n) {
      if (!now.split[n]) continue;
      const auto& c = cells_[n];
      const std::uint32_t q = before_index_[n];
      const bool had_children = q != GridIndex::kNone && last->split[q];
      for (int child = 0; child < 8; ++child) {
        refined.push_back({c[0] + (child & 1) * half, c[1] + ((child >> 1) & 1) * half,
                           c[2] + ((child >> 2) & 1) * half});
        refined_before.push_back(had_children
                                     ? last_child_start[q] + static_cast<std::uint32_t>(child)
                                     : GridIndex::kNone);
      }
    }
  }

  SampledField& field_;
  Sampler& sampler_;
  const ContourKeys& contours_;
  const std::vector<char>& valid_at_start_;
  const std::vector<OctreeWorkspace::RefinementLevel> before_;  // the last pass's levels
  std::vector<OctreeWorkspace::RefinementLevel>& levels_;       // this pass's, for the next
  int start_ = 0, depth_ = 0;
  std::vector<std::array<int, 3>> cells_;    // of the level being refined
  std::vector<std::uint32_t> before_index_;  // per cell, its index in the last pass's level
  std::vector<CornerRows> finest_mixed_rows_;
};

}  // namespace

SampledField sample_field(const Box3& box, int function_count, const BatchEvaluator& evaluate,
                          const ContourKeys& contours,
                          const std::vector<RegionSample>& region_samples,
                          const OctreeOptions& options, OctreeWorkspace& workspace) {
  if (function_count < 1 || function_count > 65536)
    throw std::invalid_argument("sample_field: " + std::to_string(function_count) +
                                " functions; labels are kept in 16 bits (at most 65535 materials)");
  const int depth = options.max_depth;
  const int resolution = 1 << depth;
  const Grid grid = make_grid(box, depth);
  SampledField field;
  std::vector<char> valid;
  const bool kept = take_previous_field(field, workspace, grid, function_count, valid);
  const std::vector<char> valid_at_start =
      valid;  // the rows of the kept field that kept their values
  Sampler sampler(field, evaluate, workspace.pending, std::move(valid));

  std::vector<OctreeWorkspace::RefinementLevel> before;
  if (kept) before = std::move(workspace.refinement);
  OctreeWorkspace::SmoothingInputs last_smoothing;  // rows of the kept field only
  if (kept) last_smoothing = std::move(workspace.smoothing);
  workspace.smoothing = {};
  std::vector<CornerRows> finest_mixed_rows =
      Refinement(field, sampler, contours, valid_at_start, std::move(before), workspace.refinement)
          .run(std::min(options.start_depth, depth), depth);

  GridIndex& scratch = workspace.scratch;
  scratch.reset(resolution);
  close_band(field, sampler, field.surface_cells, &finest_mixed_rows, scratch, resolution);

  if (options.smoothing_iterations > 0)
    smooth(field, sampler, contours.fixed_vertices, options.smoothing_iterations, scratch,
           kept ? &valid_at_start : nullptr, last_smoothing, workspace.smoothing);
  snap_thin_regions(field, sampler, region_samples, scratch);
  return field;
}

namespace {

// Bi-Laplacian smoothing of the band (Section 4.6), in steps: the node sets and stencils, the
// stencil vertices' values, the sweeps, the values written back, and the band closed again
// around the nodes whose label changed.
class Smoothing {
 public:
  Smoothing(SampledField& field, Sampler& sampler) : field_(field), sampler_(sampler) {}

  void run(const std::vector<std::uint64_t>& fixed, int iterations, GridIndex& scratch,
           const std::vector<char>* valid_at_start, const OctreeWorkspace::SmoothingInputs& last,
           OctreeWorkspace::SmoothingInputs& next) {
    Stopwatch smoothing_clock;
    build_sets(fixed);
    read_stencil_values(valid_at_start, last);
    record_changes();
    if (fc_ == 2)
      sweeps(std::integral_constant<std::size_t, 2>{}, iterations);
    else if (fc_ == 3)
      sweeps(std::integral_constant<std::size_t, 3>{}, iterations);
    else
      sweeps(fc_, iterations);
    write_back();
    const std::vector<std::uint64_t> seeds = seeds_where_labels_changed();
    // This pass's inputs for the next.
    next.keys = std::move(stencil_vertices_);
    next.rows = std::move(stencil_rows_);
    next.values = std::move(smoothed_);
    close_band(field_, sampler_, seeds, nullptr, scratch, resolution_, field_.surface_cells);
    field_.smoothing_seconds = smoothing_clock.seconds();
  }

 private:
  // Smoothing nodes: corners of surface cells (the band is sorted), sorted. Nodes next to a
  // contour keep their values (Section 4.6); the others move (`moving_`, sorted). Laplacian
  // domain: the moving nodes and their six neighbours, sorted; moving_stencil_: per moving node,
  // its 7-point stencil's positions in laplacian_nodes_ (kStencilShifts). Only the moving nodes'
  // bi-Laplacians are computed, so only their stencils are sampled: on a dense sweep most nodes
  // lie next to a contour, and the stencils of every node were a tenth of a rebuild's
  // evaluations (80 slices of spot's sweep: 92k against 83k; `reconstruct --stats`,
  // field_evaluations). Every vertex the bi-Laplacian of a moving node reads: the Laplacian
  // nodes and their neighbours, sorted. Each is looked up (or evaluated) once and its values
  // copied into `smoothed_`, where the sweeps run: in key order, a vertex's neighbours along k
  // lie next to it and those along j and i a row or a slice away, where the field's rows (in the
  // order they were first evaluated) scattered every stencil over memory. The bit masks that
  // build the sets give each stencil's positions (key_masks.hpp); looking up the seven vertices
  // of every Laplacian and bi-Laplacian stencil in the grid index cost more than the sweeps.
  void build_sets(const std::vector<std::uint64_t>& fixed) {
    const std::vector<std::uint64_t> nodes = cube_corner_union(field_.surface_cells);
    moving_.reserve(nodes.size());
    std::set_difference(nodes.begin(), nodes.end(), fixed.begin(), fixed.end(),
                        std::back_inserter(moving_));
    laplacian_nodes_ = stencil_union(moving_, &moving_stencil_);
    stencil_vertices_ = stencil_union(laplacian_nodes_, &lap_stencil_);
    // Per moving node, its position in stencil_vertices_.
    moving_position_.resize(moving_.size());
    for_rows(moving_.size(), [&](std::size_t m) {
      moving_position_[m] = lap_stencil_[static_cast<std::size_t>(moving_stencil_[m * 7]) * 7];
    });
  }

  // Per stencil vertex, its row and its value before the sweeps (in `smoothed_`), in one parallel
  // walk per chunk. A vertex whose row kept its value since the last pass (valid at the start of
  // this pass: then nothing has written it) is read from the last pass's inputs, found by
  // walking both sorted lists from a binary search; the others are looked up, and those without
  // a current value are evaluated (queued in key order) and read after.
  void read_stencil_values(const std::vector<char>* valid_at_start,
                           const OctreeWorkspace::SmoothingInputs& last) {
    stencil_rows_.resize(stencil_vertices_.size());
    smoothed_.resize(stencil_vertices_.size() * fc_);
    const bool from_last = valid_at_start != nullptr && !last.keys.empty();
    constexpr std::size_t kChunk = 4096;
    std::vector<std::vector<std::uint32_t>> missing((stencil_vertices_.size() + kChunk - 1) /
                                                    kChunk);
    tbb::parallel_for(std::size_t{0}, missing.size(), [&](std::size_t chunk) {
      const std::size_t begin = chunk * kChunk,
                        end = std::min(stencil_vertices_.size(), begin + kChunk);
      std::size_t m =
          from_last ? static_cast<std::size_t>(std::lower_bound(last.keys.begin(), last.keys.end(),
                                                                stencil_vertices_[begin]) -
                                               last.keys.begin())
                    : 0;
      for (std::size_t n = begin; n < end; ++n) {
        if (from_last) {
          while (m < last.keys.size() && last.keys[m] < stencil_vertices_[n]) ++m;
          if (m < last.keys.size() && last.keys[m] == stencil_vertices_[n] &&
              (*valid_at_start)[last.rows[m]]) {
            stencil_rows_[n] = last.rows[m];
            sampler_.mark_read(stencil_rows_[n]);
            copy_row(&last.values[m * fc_], fc_, &smoothed_[n * fc_]);
            continue;
          }
        }
        stencil_rows_[n] = sampler_.valid_row(stencil_vertices_[n]);
        if (stencil_rows_[n] == GridIndex::kNone)
          missing[chunk].push_back(static_cast<std::uint32_t>(n));
        else
          copy_row(field_.values.data() + stencil_rows_[n] * fc_, fc_, &smoothed_[n * fc_]);
      }
    });
    std::vector<std::uint32_t> evaluated;  // positions, ascending
    for (const std::vector<std::uint32_t>& chunk : missing)
      evaluated.insert(evaluated.end(), chunk.begin(), chunk.end());
    for (const std::uint32_t n : evaluated) sampler_.queue(stencil_vertices_[n]);
    sampler_.flush();
    const double* values = field_.values.data();  // the flush may have grown the field
    for_rows(evaluated.size(), [&](std::size_t e) {
      const std::size_t n = evaluated[e];
      stencil_rows_[n] = field_.index.at(stencil_vertices_[n]);
      copy_row(values + stencil_rows_[n] * fc_, fc_, &smoothed_[n * fc_]);
    });
  }

  std::uint32_t node_row(std::size_t m) const { return stencil_rows_[moving_position_[m]]; }

  // The labels of the moving nodes before the sweeps, and the rows the sweeps move with their
  // values before, in node order (see changed_rows).
  void record_changes() {
    label_before_.resize(moving_.size());
    for_rows(moving_.size(),
             [&](std::size_t m) { label_before_[m] = field_.row_label(node_row(m)); });
    first_change_ = field_.changed_rows.size();
    field_.changed_rows.resize(first_change_ + moving_.size());
    field_.changed_values.resize(field_.changed_rows.size() * fc_);
    const double* values = field_.values.data();
    for_rows(moving_.size(), [&](std::size_t m) {
      const std::size_t change = first_change_ + m;
      field_.changed_rows[change] = node_row(m);
      copy_row(values + node_row(m) * fc_, fc_, field_.changed_values.data() + change * fc_);
    });
  }

  // Damped Jacobi on the bi-Laplacian (7-point Laplacian squared: diagonal 42); the damping
  // keeps the highest grid frequencies stable. Each sweep computes every Laplacian before it
  // moves a node. `width` functions per vertex: a compile-time width for the usual one and two
  // labels (two and three functions) lets the compiler unroll the functions' loops.
  template <typename Width>
  void sweeps(Width width, int iterations) {
    constexpr double kDamping = 0.5 / 42.0;
    const std::size_t w = width;
    std::vector<double> laplacian(laplacian_nodes_.size() * fc_);
    const auto laplacian_at = [&](std::size_t n) {
      const std::uint32_t* stencil = &lap_stencil_[n * 7];
      double* out = &laplacian[n * w];
      for (std::size_t l = 0; l < w; ++l) {
        double sum = -6.0 * smoothed_[stencil[0] * w + l];
        for (int d = 1; d <= 6; ++d) sum += smoothed_[stencil[d] * w + l];
        out[l] = sum;
      }
    };
    for (int iteration = 0; iteration < iterations; ++iteration) {
      for_rows(laplacian_nodes_.size(), laplacian_at);
      for_rows(moving_.size(), [&](std::size_t m) {
        const std::uint32_t* stencil = &moving_stencil_[m * 7];
        double* value = &smoothed_[moving_position_[m] * w];
        for (std::size_t l = 0; l < w; ++l) {
          double sum = -6.0 * laplacian[stencil[0] * w + l];
          for (int d = 1; d <= 6; ++d) sum += laplacian[stencil[d] * w + l];
          value[l] -= kDamping * sum;
        }
      });
    }
  }

  // The smoothed values go to the field's rows, and `smoothed_` gets the rows' values before the
  // sweeps back (saved in changed_values; they are what `smoothed_` held): this pass's inputs,
  // kept for the next pass (a copy of all of them before the sweeps cost more).
  void write_back() {
    double* values = field_.values.data();
    for_rows(moving_.size(), [&](std::size_t m) {
      double* value = &smoothed_[moving_position_[m] * fc_];
      copy_row(value, fc_, values + node_row(m) * fc_);
      field_.set_row_label(node_row(m));
      copy_row(field_.changed_values.data() + (first_change_ + m) * fc_, fc_, value);
    });
  }

  // Smoothing may move labels at the nodes. The band was closed before, and its cells whose
  // corners kept their labels keep their faces: only the cells around the nodes whose label
  // changed are seeds of the new, again closed, band (the rest of the old band is kept where
  // still mixed). Seeding every cell around every node cost more than the sweeps.
  std::vector<std::uint64_t> seeds_where_labels_changed() const {
    std::vector<char> label_changed(moving_.size());
    for_rows(moving_.size(), [&](std::size_t m) {
      label_changed[m] = field_.row_label(node_row(m)) != label_before_[m];
    });
    std::vector<std::uint64_t> seeds;
    for (std::size_t m = 0; m < moving_.size(); ++m) {
      if (!label_changed[m]) continue;
      int i, j, k;
      grid_unkey(moving_[m], i, j, k);
      for (int corner = 0; corner < 8; ++corner) {
        const int ci = i - (corner & 1), cj = j - ((corner >> 1) & 1), ck = k - ((corner >> 2) & 1);
        if (ci < 0 || cj < 0 || ck < 0 || ci >= resolution_ || cj >= resolution_ ||
            ck >= resolution_)
          continue;
        seeds.push_back(grid_key(ci, cj, ck));
      }
    }
    return seeds;
  }

  SampledField& field_;
  Sampler& sampler_;
  const int resolution_ = 1 << field_.grid.depth;
  const std::size_t fc_ = static_cast<std::size_t>(field_.function_count);
  std::vector<std::uint64_t> moving_;            // the nodes that move, sorted
  std::vector<std::uint64_t> laplacian_nodes_;   // the moving nodes and their neighbours
  std::vector<std::uint32_t> moving_stencil_;    // per moving node, 7 positions in laplacian_nodes_
  std::vector<std::uint64_t> stencil_vertices_;  // what the bi-Laplacians read, sorted
  std::vector<std::uint32_t> lap_stencil_;  // per Laplacian node, 7 positions in stencil_vertices_
  std::vector<std::uint32_t> moving_position_;  // per moving node, its position there
  std::vector<std::uint32_t> stencil_rows_;     // per stencil vertex, its row in the field
  std::vector<double> smoothed_;                // per stencil vertex, fc_ values
  std::vector<int> label_before_;               // per moving node
  std::size_t first_change_ = 0;                // its first entry in field_.changed_rows
};

void smooth(SampledField& field, Sampler& sampler, const std::vector<std::uint64_t>& fixed,
            int iterations, GridIndex& scratch, const std::vector<char>* valid_at_start,
            const OctreeWorkspace::SmoothingInputs& last, OctreeWorkspace::SmoothingInputs& next) {
  Smoothing(field, sampler).run(fixed, iterations, scratch, valid_at_start, last, next);
}

void snap_thin_regions(SampledField& field, Sampler& sampler,
                       const std::vector<RegionSample>& samples, GridIndex& scratch) {
  // A region narrower than the finest cells may have no grid vertex of its label, and would
  // vanish from the mesh; its nearest grid vertices take the slice's own value (as on the face).
  const Grid& grid = field.grid;
  const int resolution = 1 << grid.depth;
  std::vector<std::pair<std::uint64_t, int>> targets;
  for (const RegionSample& sample : samples) {
    const Vec3 q = (sample.position - grid.origin) / grid.cell_size;
    const int i = static_cast<int>(std::lround(q.x())), j = static_cast<int>(std::lround(q.y())),
              k = static_cast<int>(std::lround(q.z()));
    if (i <= 0 || j <= 0 || k <= 0 || i >= resolution || j >= resolution || k >= resolution)
      continue;
    sampler.request(i, j, k);
    targets.emplace_back(grid_key(i, j, k), sample.function);
  }
  sampler.flush();
  std::vector<std::uint64_t> seeds;
  const std::size_t fc = static_cast<std::size_t>(field.function_count);
  for (const auto& [key, function] : targets) {
    if (field.label(key) == function) continue;
    const std::uint32_t row_index = field.index.at(key);
    double* row = field.values.data() + static_cast<std::size_t>(row_index) * fc;
    field.changed_rows.push_back(row_index);
    field.changed_values.insert(field.changed_values.end(), row, row + fc);
    for (std::size_t l = 0; l < fc; ++l) row[l] = static_cast<int>(l) == function ? 1.0 : -1.0;
    field.set_row_label(row_index);
    ++field.snapped_vertices;
    int i, j, k;
    grid_unkey(key, i, j, k);
    for (int corner = 0; corner < 8; ++corner)
      seeds.push_back(grid_key(i - (corner & 1), j - ((corner >> 1) & 1), k - ((corner >> 2) & 1)));
  }
  if (seeds.empty()) return;
  close_band(field, sampler, seeds, nullptr, scratch, resolution, field.surface_cells);
}

}  // namespace
}  // namespace sonoshape::recon
