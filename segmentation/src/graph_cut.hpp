#pragma once
// Multi-label Potts labelling of a grid by alpha-expansion (Boykov, Veksler and Zabih 2001), each
// expansion a binary cut solved by Boost.Graph's Boykov-Kolmogorov max-flow. The grid's graph is
// built once (its topology depends only on which cells take part) and reused for every
// expansion and every frame of a sweep.
#include <cstdint>
#include <memory>
#include <vector>

namespace sonoshape::segmentation::detail {

/// A cost at or above this keeps a cell off a label; an expansion that no cell can take (every
/// cell has the label or this cost for it) is skipped.
constexpr float kExcludedCost = 1e6f;

/// A 4-connected grid of `width` x `height` cells of which `active` ones take part; a cell's
/// labels are indices 0..labels-1.
class GridLabelling {
 public:
  /// `active` has width*height entries (non-zero: the cell takes part). Throws
  /// std::invalid_argument when sizes disagree or there are no labels.
  GridLabelling(int width, int height, const std::vector<std::uint8_t>& active, int labels);
  ~GridLabelling();
  GridLabelling(const GridLabelling&) = delete;
  GridLabelling& operator=(const GridLabelling&) = delete;

  int width() const { return width_; }
  int height() const { return height_; }
  int labels() const { return labels_; }

  /// Minimises sum_c cost[c * labels + label_c] + sum_{c~d} w(c, d) [label_c != label_d] from
  /// `labelling` (one label per cell; inactive cells are left as they are), by `cycles` passes
  /// of expansions over every label, stopping early when a pass lowers nothing. `right_weight`
  /// and `down_weight` (width*height each) hold w between a cell and its right / lower
  /// neighbour (>= 0). Returns the final energy.
  double minimise(const std::vector<float>& cost, const std::vector<float>& right_weight,
                  const std::vector<float>& down_weight, std::vector<std::uint8_t>& labelling,
                  int cycles);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int width_, height_, labels_;
};

}  // namespace sonoshape::segmentation::detail
