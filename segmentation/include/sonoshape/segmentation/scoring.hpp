#pragma once
// Segmentation as its own stage: a frame's label map against the truth label frame of the same
// index (`sonoshape simulate --truth DIR` writes DIR/labels.mha): Dice per label and
// precision/recall of the unknown (shadow) area, per frame and summed over a sweep.
#include <cstddef>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::segmentation {

/// Pixel counts of one class: in the truth, in ours, in both.
struct PixelCounts {
  std::size_t truth_px = 0;
  std::size_t ours_px = 0;
  std::size_t both_px = 0;

  /// 2 |both| / (|truth| + |ours|); NaN when the class is in neither map.
  double dice() const;
  /// |both| / |ours|; NaN when ours has none.
  double precision() const;
  /// |both| / |truth|; NaN when the truth has none.
  double recall() const;
  void add(const PixelCounts& other);
};

/// One label map against the truth, over the pixels of a sector. Labels are scored on the
/// pixels whose truth is known (a label we put where the truth is unknown is a miss of the
/// unknown area, not a label error); the unknown area on every sector pixel.
struct LabelComparison {
  /// Per label id (0 background, material ids) that occurs in either map.
  std::map<int, PixelCounts> labels;
  /// kLabelPixelUnknown pixels inside the sector (shadows, areas without signal).
  PixelCounts unknown;
  std::size_t sector_px = 0;  ///< pixels compared

  /// Sums the counts (so that a sweep's figures are ratios of sums, not means of ratios).
  void add(const LabelComparison& other);
};

/// Compares `ours` with `truth` on the pixels where `sector` is non-zero. Throws
/// std::invalid_argument when the three images differ in size.
LabelComparison compare_labels(const LabelImage& truth, const LabelImage& ours,
                               const ImageU8& sector);

/// Checks that `truth` (read from `truth_path`) holds one label frame per frame of `sweep`
/// (read from `sweep_path`), of the same size; the error names both files, the frame and the fix.
Status check_truth_labels(const acquisition::SequenceFile& sweep,
                          const std::filesystem::path& sweep_path,
                          const acquisition::SequenceFile& truth,
                          const std::filesystem::path& truth_path);

/// The comparison of one frame of a sweep.
struct FrameComparison {
  std::size_t frame = 0;  ///< index in the file
  LabelComparison comparison;
};

/// A short table for the terminal: per label its name (from `names`, else "label_<id>") and
/// Dice over the sweep, then the unknown area's precision and recall.
std::string format_comparison(const LabelComparison& total,
                              const std::map<int, std::string>& names);

/// The JSON text of one comparison: {"sector_px", "labels": {id: {dice, truth_px, ours_px,
/// both_px, name}}, "unknown": {precision, recall, ...}} (NaN as null), as in the report.
std::string comparison_json_text(const LabelComparison& comparison,
                                 const std::map<int, std::string>& names);

/// Writes the JSON report {"frames": [{"frame", "labels": {id: {dice, truth_px, ours_px,
/// both_px}}, "unknown": {precision, recall, ...}}], "total": {...}} (NaN as null) to `path`;
/// fails naming the file.
Status write_comparison_report(const std::vector<FrameComparison>& frames,
                               const LabelComparison& total,
                               const std::map<int, std::string>& names,
                               const std::filesystem::path& path);

}  // namespace sonoshape::segmentation
