#pragma once
// A check of a sweep's label maps for a labelling that says nothing: one label (a material, or
// unknown) filling nearly all of the sector in most frames. On real recordings that is what
// models that do not fit the recording give: one `echogenic` region over the whole field of
// view, water included, or nothing but "no signal" over a phantom in water.
#include <cstddef>
#include <map>
#include <optional>
#include <string>

#include "sonoshape/core/image.hpp"

namespace sonoshape::segmentation {

class SectorShareCheck {
 public:
  /// A label fills "nearly all" of a sector from this share of its pixels ...
  static constexpr double kNearlyAll = 0.95;
  /// ... and "most" sectors are more than this share of the frames.
  static constexpr double kMost = 0.5;

  /// `sector`: 255 where the probe sees (the frames' size); an empty one counts no frame.
  explicit SectorShareCheck(const ImageU8& sector);
  /// Counts one frame's label map (0 background, material ids, kLabelPixelUnknown); throws
  /// std::invalid_argument when its size differs from the sector's.
  void add(const LabelImage& labels);
  std::size_t frames() const { return frames_; }
  /// The label that fills nearly all of most sectors (kLabelPixelUnknown for unknown); none
  /// when there is none. The background (outside every organ) may fill a sector: water around
  /// wires is a right answer.
  std::optional<int> dominant_label() const;
  /// A warning naming that label (by `names`: material id -> name), in how many frames, and
  /// what to try; none when there is no such label.
  std::optional<std::string> warning(const std::map<int, std::string>& names) const;

 private:
  ImageU8 sector_;
  std::size_t sector_px_ = 0;
  std::size_t frames_ = 0;
  std::map<int, std::size_t> filled_frames_;  // label -> frames it fills nearly all of
};

}  // namespace sonoshape::segmentation
