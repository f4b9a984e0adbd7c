#pragma once
// FrameSource: the stream of every image source (design.md data path), FrameBackend: what an
// image backend implements, and the replay of a PLUS sequence file. Hardware backends (v4l2,
// OpenIGTLink) are FrameBackends too.
#include <filesystem>
#include <memory>
#include <string>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/acquisition/stream_source.hpp"
#include "sonoshape/core/frame.hpp"

namespace sonoshape::acquisition {

/// A stream of ultrasound frames (timestamps on the frame source's clock, indices from 0).
/// See StreamSource for the threading and lifetime rules.
using FrameSource = StreamSource<Frame>;
/// What an image device, file or simulation implements (open / poll / close).
using FrameBackend = StreamBackend<Frame>;

/// Replays the frames of a PLUS sequence file in file order: `Frame::timestamp_s` is the
/// frame's `Timestamp` field (0 when absent), `Frame::index` its position in the file. Frames
/// whose `ImageStatus` is present and not OK are skipped (counted as lost). Plays in real time
/// or as fast as possible (SourceOptions::playback).
class ReplayFrames final : public FrameBackend {
 public:
  /// Replays `file`, shared with the pose replay of the same file, from frame `first_frame` (a
  /// resumed scan goes on after the last frame it journalled); `name` names it in messages
  /// (usually the path).
  ReplayFrames(std::shared_ptr<const SequenceFile> file, std::string name,
               std::size_t first_frame = 0);

  std::string describe() const override { return "replay:" + name_; }

 protected:
  Status open() override;
  Result<Polled> poll(Frame& frame) override;
  bool is_playback() const override { return true; }

 private:
  std::shared_ptr<const SequenceFile> file_;
  std::string name_;
  std::size_t first_frame_ = 0;
  std::size_t next_ = 0;
};
/// The stream of a ReplayFrames.
using ReplayFrameSource = SourceOf<ReplayFrames>;

/// The device time of the first frame of a file (its first valid `Timestamp`, else 0): the
/// device origin for real-time playback of the file.
double first_timestamp_s(const SequenceFile& file);

}  // namespace sonoshape::acquisition
