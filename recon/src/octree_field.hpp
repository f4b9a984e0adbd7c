#pragma once
// Adaptive sampling of the label functions on an octree (Bermano et al. 2011, Section 4.6):
// coarse-to-fine refinement where the label changes or contour vertices lie, a closed band of
// finest-level cells around every label boundary, and bi-Laplacian smoothing that keeps the
// values next to the input contours.
#include <array>
#include <cstdint>
#include <functional>
#include <unordered_map>
#include <vector>

#include "grid_index.hpp"
#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon {

/// Finest-level grid: vertex (i, j, k) sits at origin + cell_size * (i, j, k).
struct Grid {
  Vec3 origin = Vec3::Zero();
  double cell_size = 1.0;
  int depth = 6;  ///< resolution = 2^depth cells per axis of the root cube
  Vec3 position(int i, int j, int k) const { return origin + cell_size * Vec3(i, j, k); }
};

/// Packs grid indices (each in [-2^20, 2^20)) into one key.
inline std::uint64_t grid_key(int i, int j, int k) {
  constexpr std::int64_t kBias = 1 << 20;
  return (static_cast<std::uint64_t>(i + kBias) << 42) |
         (static_cast<std::uint64_t>(j + kBias) << 21) | static_cast<std::uint64_t>(k + kBias);
}
inline void grid_unkey(std::uint64_t key, int& i, int& j, int& k) {
  constexpr std::int64_t kBias = 1 << 20;
  i = static_cast<int>(static_cast<std::int64_t>(key >> 42) - kBias);
  j = static_cast<int>(static_cast<std::int64_t>((key >> 21) & 0x1fffff) - kBias);
  k = static_cast<int>(static_cast<std::int64_t>(key & 0x1fffff) - kBias);
}

/// Evaluates grid vertices (world positions) into `values` (count * function_count doubles), in
/// parallel, and gives each value a tag (`tags`, count of them, zero on entry) that the field
/// keeps with its row (SampledField::row_tags): an online engine tags a value with the
/// arrangement cell and the update it was evaluated in, to tell which kept rows are current.
using BatchEvaluator =
    std::function<void(const std::vector<Vec3>& points, double* values, std::uint64_t* tags)>;

struct OctreeOptions {
  int max_depth = 6;
  int start_depth = 3;
  int smoothing_iterations = 8;
};

/// The sampled field: values of every function at the evaluated grid vertices.
struct SampledField {
  Grid grid;
  int function_count = 2;
  GridIndex index;                  ///< vertex key -> row in values
  std::vector<double> values;       ///< row-major, function_count each
  std::vector<std::uint64_t> keys;  ///< vertex key of each row
  std::vector<std::uint64_t>
      row_tags;  ///< per row, the evaluator's tag of its value (BatchEvaluator)
  std::vector<std::uint64_t> surface_cells;  ///< finest cells (key of their min corner) with
                                             ///< corners of different labels; closed under
                                             ///< face adjacency
  std::size_t evaluations = 0;
  std::size_t snapped_vertices = 0;  ///< grid vertices set to a thin region's label
  double smoothing_seconds = 0.0;
  /// Per row, the sample_field pass that last read it: a field kept across passes (see
  /// OctreeWorkspace::previous) also holds rows that only earlier passes read.
  std::vector<std::uint32_t> row_pass;
  std::uint32_t pass = 0;
  /// Rows the smoothing and the thin-region snap changed in place, with their values before (in
  /// the order saved): a later pass that keeps this field puts them back first.
  std::vector<std::uint32_t> changed_rows;
  std::vector<double> changed_values;

  /// Per row, the argmax label of its values (the lowest index wins ties), kept by every pass
  /// that writes values: the band closures, the refinement's mixed tests, the smoothing and the
  /// mesher read labels of rows scattered over the field, and two bytes per row are read from cache
  /// where the values' two or more doubles per row were not.
  std::vector<std::uint16_t> row_labels;

  const double* at(std::uint64_t key) const {
    return values.data() +
           static_cast<std::size_t>(index.at(key)) * static_cast<std::size_t>(function_count);
  }
  /// Argmax label of a vertex's values.
  int label(std::uint64_t key) const { return row_label(index.at(key)); }
  /// The same for a row (as last labelled by set_row_label).
  int row_label(std::uint32_t row) const { return row_labels[row]; }
  /// Labels a row from its values, after they were written.
  void set_row_label(std::uint32_t row) {
    const double* row_values =
        values.data() + static_cast<std::size_t>(row) * static_cast<std::size_t>(function_count);
    int best = 0;
    for (int l = 1; l < function_count; ++l)
      if (row_values[l] > row_values[best]) best = l;
    row_labels[row] = static_cast<std::uint16_t>(best);
  }
};

/// A point of a slice region (world, mm) and its function index: the grid vertex nearest to it
/// must carry that label, or a region thinner than the finest cells would vanish from the mesh.
struct RegionSample {
  Vec3 position;
  int function = 1;
};

/// The finest grid of an octree of `depth` levels over `box`.
Grid make_grid(const Box3& box, int depth);

/// Where the input contours lie on one grid. It depends on each slice alone, so an online engine
/// computes it for the new slices only and merges it into what it has (the field does not).
struct ContourKeys {
  /// Per level (index = level, from the start depth up): keys of the cells, at that level's
  /// indices, holding a contour vertex; they are refined. Sorted, unique.
  std::vector<std::vector<std::uint64_t>> cells_by_level;
  /// Corners of the finest cells the contour segments pass through: they keep their
  /// interpolated values in the smoothing (Section 4.6). Sorted, unique.
  std::vector<std::uint64_t> fixed_vertices;
};

/// The contour keys of `segments` (pairs of consecutive contour vertices, world mm; the first
/// point of each is a contour vertex) on the finest grid of `options` over `grid`.
ContourKeys contour_keys(const Grid& grid, const OctreeOptions& options,
                         const std::vector<std::pair<Vec3, Vec3>>& segments);

/// Adds `more` to `keys` (both sorted, unique; the result too).
void merge_contour_keys(ContourKeys& keys, const ContourKeys& more);

/// The lookup tables sample_field fills at every call. At the default depth each is a direct
/// table of 9 MiB whose allocation and fill cost more than an online update's octree passes: an
/// online engine keeps one workspace across updates (one-shot calls make their own).
struct OctreeWorkspace {
  GridIndex pending;  ///< vertices queued for evaluation
  GridIndex scratch;  ///< band closure and smoothing
  /// The field of a previous call on the same grid, and per row of it whether its value is still
  /// the field's (an online engine knows which cells changed). Its valid rows are read instead of
  /// evaluated again, and its tables are reused; an empty `previous_valid` keeps only the tables.
  /// An online update of a few changed cells spent most of its octree passes copying the
  /// unchanged rows from its cache into a fresh field.
  SampledField previous;
  std::vector<char> previous_valid;
  /// The refinement of the pass that made `previous`, per level from the start depth: a cell
  /// whose corner rows all kept their values keeps its mixed test, so an online update looks up
  /// and tests only the cells with a corner in a changed arrangement cell (it looked up all eight
  /// corners of every cell of every level: the largest of its octree passes).
  struct RefinementLevel {
    std::vector<std::array<int, 3>> cells;                  ///< min corners, finest units
    std::vector<std::array<std::uint32_t, 8>> corner_rows;  ///< rows of `previous`
    std::vector<char> mixed;                                ///< corners of different labels
    std::vector<char> split;                                ///< refined (mixed or contour cell)
  };
  std::vector<RefinementLevel> refinement;
  /// The smoothing's stencil vertices of the pass that made `previous` (sorted keys), their rows
  /// and their values before the sweeps. A vertex of the next pass whose row kept its value is
  /// read from here, in key order, instead of being looked up and read from its row: an online
  /// update's stencils are nearly all the last pass's, and those scattered look-ups and reads
  /// would be a third of its smoothing set-up.
  struct SmoothingInputs {
    std::vector<std::uint64_t> keys;
    std::vector<std::uint32_t> rows;
    std::vector<double> values;  ///< function_count per key
  };
  SmoothingInputs smoothing;
};

/// Samples the field over `box` (everything outside it is the outside label). `contours` refine
/// the octree and fix the smoothing next to the contours (see ContourKeys); `region_samples`
/// snap thin regions to their nearest grid vertices after smoothing.
SampledField sample_field(const Box3& box, int function_count, const BatchEvaluator& evaluate,
                          const ContourKeys& contours,
                          const std::vector<RegionSample>& region_samples,
                          const OctreeOptions& options, OctreeWorkspace& workspace);
SampledField sample_field(const Box3& box, int function_count, const BatchEvaluator& evaluate,
                          const ContourKeys& contours,
                          const std::vector<RegionSample>& region_samples,
                          const OctreeOptions& options);

/// The default octree depth: the coarsest whose finest cells are at most 1/128 of the box diagonal.
int default_depth(const Box3& box);

}  // namespace sonoshape::recon
