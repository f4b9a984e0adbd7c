#pragma once
// Pictures for checking a segmentation by eye: the B-mode frame with the outlines of our label
// map and, when known, of the truth drawn over it.
#include <filesystem>

#include "sonoshape/core/image.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::segmentation {

/// Writes `frame` (grey) as a colour PNG with the outline of every material of `ours` in the
/// label's colour and the unknown area (shadow, no signal) inside `sector` tinted; with `truth`,
/// the outline of every truth material is drawn in white beside ours, and the picture carries
/// a legend. All images must be of one size (an error names the mismatch); fails naming the
/// file when it cannot be written.
Status write_overlay(const std::filesystem::path& path, const GreyImage& frame,
                     const LabelImage& ours, const ImageU8& sector,
                     const LabelImage* truth = nullptr);

}  // namespace sonoshape::segmentation
