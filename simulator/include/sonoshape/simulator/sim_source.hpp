#pragma once
// The simulated probe as a live frame source (`sonoshape scan --source sim:...`): frames are
// rendered on demand at the trajectory's true pose, at the probe's frame rate in real time or
// as fast as they render. Its tracker is a tracking::RecordedPoseSource playing simulator::track().
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "sonoshape/acquisition/frame_source.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace sonoshape::simulator {

/// The truth label frames of a simulated source's latest frames, by frame index, for scoring
/// the segmentation live. Thread-safe; keeps the newest `capacity` frames.
class FrameTruthStore {
 public:
  explicit FrameTruthStore(std::size_t capacity = 64) : capacity_(capacity) {}
  void put(std::int64_t index, LabelImage truth);
  /// The truth of frame `index` (removed from the store); none when it was never stored or is
  /// older than the newest `capacity` frames.
  std::optional<LabelImage> take(std::int64_t index);

 private:
  std::mutex mutex_;
  std::size_t capacity_;
  std::deque<std::pair<std::int64_t, LabelImage>> frames_;
};

/// What the simulated probe delivers.
struct SimFrameOptions {
  double frame_rate_hz = 30.0;  ///< frame k has timestamp k / frame_rate_hz (s)
  int frame_count = 600;        ///< frames of the whole sweep
  std::uint64_t seed = 1;       ///< speckle seed (frame k as in simulate_sweep with this seed)
  /// Fault injection: poll() fails with "probe vanished" once this many frames were delivered
  /// (< 0: never), as when a cable is pulled mid-scan.
  long fail_after_frames = -1;
  /// The first frame delivered (a resumed scan goes on after the last frame it journalled);
  /// real-time playback then starts at its time (Playback::device_origin_s).
  long first_frame = 0;
  /// When set, every frame's truth label map (SimulatedFrame::truth) is put there.
  std::shared_ptr<FrameTruthStore> truth;
};

/// A simulated probe. In real-time playback a frame that could not be rendered in time is
/// skipped (counted by dropped()), as a real probe's frames are lost when nobody takes them.
class SimFrames final : public acquisition::FrameBackend {
 public:
  /// Throws std::invalid_argument for a null simulator, a non-positive frame rate or no frames.
  SimFrames(std::shared_ptr<const BModeSimulator> simulator, Trajectory trajectory,
            const SimFrameOptions& options, std::string name = "sim");

  std::string describe() const override { return name_; }
  const SimFrameOptions& options() const { return options_; }

 protected:
  Status open() override;
  Result<acquisition::Polled> poll(Frame& frame) override;
  bool is_playback() const override { return true; }

 private:
  std::shared_ptr<const BModeSimulator> simulator_;
  Trajectory trajectory_;
  SimFrameOptions options_;
  std::string name_;
  long next_ = 0;
  long delivered_ = 0;
};
/// The stream of a SimFrames.
using SimFrameSource = acquisition::SourceOf<SimFrames>;

/// The speckle seed of frame k of a sweep simulated with `seed` (as simulate_sweep uses it).
std::uint64_t frame_seed(std::uint64_t seed, std::size_t k);

}  // namespace sonoshape::simulator
