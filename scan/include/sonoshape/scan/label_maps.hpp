#pragma once
// `scan --labels`: a site's own label maps instead of sonoshape's segmenter ("bring your own
// labels", docs/segmentation.md). A feed gives each tracked frame its label map, from a label-map
// sequence aligned to a replayed recording (frame k for frame k) or from OpenIGTLink IMAGE
// messages of another device beside the B-mode stream (paired by timestamp); LabelMapStage turns
// it into a slice exactly as the segmenter's label maps are (segmentation::make_slice: polygons per
// label, unknown regions, fov = the sector).
#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/acquisition/label_sequence.hpp"
#include "sonoshape/core/frame.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/scan/setup.hpp"
#include "sonoshape/scan/stages.hpp"

namespace sonoshape::acquisition {
template <typename T>
class StreamSource;
using FrameSource = StreamSource<Frame>;
}  // namespace sonoshape::acquisition

namespace sonoshape::scan {

/// Where the label maps of a scan come from.
class LabelMapFeed {
 public:
  virtual ~LabelMapFeed() = default;
  /// Starts receiving (before the scan's first frame); fails naming the source.
  virtual Status start() { return Status::ok(); }
  /// The label map of `frame` as sonoshape's label pixels (0 background, organ ids, 255
  /// unknown), or why there is none. Called from the segmentation thread only.
  virtual Result<LabelImage> label_map(const Frame& frame) = 0;
  /// One line for the log, e.g. "label maps of labels.seq.nrrd (times agree)".
  virtual std::string describe() const = 0;
};

/// Frame k of `maps` (a LabelSequence checked against the recording) for the frame of index k.
std::unique_ptr<LabelMapFeed> sequence_label_feed(
    std::shared_ptr<const acquisition::SequenceFile> maps, std::string description);

/// Pairs label maps with frames by timestamp. Label maps come in time order (a network's outputs
/// in the order the frames went in), frames are asked for in time order.
class LabelMapMatcher {
 public:
  /// `capacity`: label maps kept at most (the oldest go first).
  explicit LabelMapMatcher(double tolerance_s = acquisition::kLabelTimeToleranceS,
                           std::size_t capacity = 64);
  /// Keeps a label map stamped `timestamp_s`.
  void offer(double timestamp_s, LabelImage labels);
  /// The label map stamped within the tolerance of `timestamp_s`, removed with every older one
  /// (no later frame needs them); none when none is held.
  std::optional<LabelImage> take(double timestamp_s);
  /// Whether a label map stamped after `timestamp_s` (beyond the tolerance) is held: then the
  /// one for `timestamp_s` will not come.
  bool passed(double timestamp_s) const;
  /// The stamp nearest `timestamp_s` among those held (for messages); none when none is held.
  std::optional<double> nearest(double timestamp_s) const;

 private:
  double tolerance_s_;
  std::size_t capacity_;
  std::map<double, LabelImage> held_;
};

/// Label maps from a frame source (OpenIGTLink IMAGE messages named for the label maps), each
/// paired with the frame of the same timestamp: waits up to `wait_s` for it, less when a later
/// label map shows that it will not come. Pixel values as acquisition::to_label_pixels.
class StreamLabelFeed final : public LabelMapFeed {
 public:
  /// `name` names the label maps in messages, e.g. "IMAGE 'LabelMap' of igtl:127.0.0.1:18944".
  StreamLabelFeed(std::unique_ptr<acquisition::FrameSource> source, std::string name,
                  int unknown_value, double wait_s);
  ~StreamLabelFeed() override;
  Status start() override;
  Result<LabelImage> label_map(const Frame& frame) override;
  std::string describe() const override;

 private:
  void take_available(double timeout_s);
  std::unique_ptr<acquisition::FrameSource> source_;
  std::string name_;
  int unknown_value_;
  double wait_s_;
  LabelMapMatcher matcher_;
};

#ifdef SONOSHAPE_WITH_OPENIGTLINK
/// `--labels igtl:DEVICE` (`igtl:DEVICE@HOST:PORT` for another server than `frames_endpoint`):
/// IMAGE messages named DEVICE, on a connection of their own.
Result<std::unique_ptr<LabelMapFeed>> igtl_label_feed(const std::string& spec,
                                                      const std::string& frames_endpoint,
                                                      int unknown_value, double wait_s);
#endif

/// The segmentation stage of `--labels`: each frame's label map from the feed through
/// segmentation::make_slice with the setup's sector and simplification, as SegmenterStage does with
/// its own. A frame without a label map gives no slice (the first such is logged as a warning, with
/// why), and its frame is counted as failed.
class LabelMapStage final : public SegmentationStage {
 public:
  /// Throws std::invalid_argument for a setup whose geometry is invalid or a missing feed.
  LabelMapStage(ScanSetup setup, std::unique_ptr<LabelMapFeed> feed);
  Result<LabeledSlice> segment(const TrackedFrame& frame) override;
  std::vector<Repair> take_repairs() override;

 private:
  ScanSetup setup_;
  std::unique_ptr<LabelMapFeed> feed_;
  std::vector<Repair> repairs_;
  bool warned_ = false;
};

/// The materials a scan or a segmentation declares for a site's label maps: each value of
/// `names` (the label maps' own names) with its name, else `fallback` (the configuration's).
std::vector<LabelInfo> declared_labels(const std::map<int, std::string>& names,
                                       const std::vector<LabelInfo>& fallback);

}  // namespace sonoshape::scan
