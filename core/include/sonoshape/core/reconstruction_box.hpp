#pragma once
// The reconstruction box around the extent of the input: one rule for a slice set's default
// bounds and for a scan volume known in advance (a recording's swept sectors).
#include <algorithm>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape {

/// `extent` (the box of what the slices show) made into a reconstruction box: a flat extent
/// (parallel slices) gets the thickness of its largest side first, then every side is padded by
/// 10% of the diagonal, so that the end caps beyond the outermost slices fit in.
inline Box3 reconstruction_box(Box3 extent) {
  const double largest_side = extent.size().maxCoeff();
  for (int k = 0; k < 3; ++k) {
    if (extent.max[k] - extent.min[k] < 1e-9 * std::max(1.0, largest_side)) {
      extent.min[k] -= 0.5 * largest_side;
      extent.max[k] += 0.5 * largest_side;
    }
  }
  return extent.padded(0.1 * extent.diagonal());
}

}  // namespace sonoshape
