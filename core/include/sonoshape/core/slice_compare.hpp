#pragma once
// Whether two slices are copies of each other, byte for byte: what the reader's coincident-plane
// check and the engine's duplicate handling both ask before anything more costly.
#include "sonoshape/core/slice.hpp"

namespace sonoshape {

/// The same frame (origin, u, v), the same fov and the same regions with the same rings in the
/// same order, compared exactly.
bool identical_slices(const LabeledSlice& a, const LabeledSlice& b);

}  // namespace sonoshape
