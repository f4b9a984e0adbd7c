#pragma once
// PoseSource: the stream of every tracker (design.md data path), PoseBackend: what a tracker
// backend implements, a player of recorded samples (simulated trackers, tests) and the replay
// of the poses of a PLUS sequence file. Hardware backends (trakSTAR, OpenIGTLink) are
// PoseBackends too.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/acquisition/pose_chain.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/acquisition/stream_source.hpp"
#include "sonoshape/core/frame.hpp"

namespace sonoshape::tracking {

/// A stream of tracker samples, T_reference_probe with status, in time order on the tracker's
/// clock. See acquisition::StreamSource for the threading and lifetime rules.
using PoseSource = acquisition::StreamSource<Pose>;
/// What a tracker, a file or a simulation of poses implements (open / poll / close).
using PoseBackend = acquisition::StreamBackend<Pose>;

/// Plays a list of samples (time order) as a tracker would: the simulated tracker of a `sim:`
/// source, and tests. Optionally fails after `fail_after` samples (a tracker unplugged).
class RecordedPoses final : public PoseBackend {
 public:
  /// `name` names the source in messages; `fail_after` (< 0: never) makes poll() fail with
  /// "tracker vanished" once that many samples were delivered.
  RecordedPoses(std::vector<Pose> samples, std::string name, long fail_after = -1);

  std::string describe() const override { return name_; }

 protected:
  Status open() override;
  Result<acquisition::Polled> poll(Pose& pose) override;
  bool is_playback() const override { return true; }

 private:
  std::vector<Pose> samples_;
  std::string name_;
  long fail_after_;
  std::size_t next_ = 0;
};
/// The stream of a RecordedPoses.
using RecordedPoseSource = acquisition::SourceOf<RecordedPoses>;

/// The probe poses of a PLUS sequence file, one sample per frame at the frame's `Timestamp`:
/// T_reference_probe = ReferenceToTracker^-1 * ProbeToTracker (ProbeToTracker alone when the
/// file has no ReferenceToTracker: the tracker is the reference). A sample is kInvalid when a
/// transform's status is not OK or a transform is missing or unreadable. PLUS already
/// interpolated the tracker at each frame's time, so replay with tracker_latency_s = 0.
class ReplayPoses final : public PoseBackend {
 public:
  /// Replays `file` (shared with the frame replay); `name` names it in messages.
  ReplayPoses(std::shared_ptr<const acquisition::SequenceFile> file, std::string name,
              std::string probe_transform = "ProbeToTracker",
              std::string reference_transform = "ReferenceToTracker");
  /// Replays the poses `chain` composes (acquisition::find_pose_chain): T_reference_probe is the
  /// chain's T_to_from, kInvalid when a per-frame transform of it is not OK.
  ReplayPoses(std::shared_ptr<const acquisition::SequenceFile> file, std::string name,
              acquisition::PoseChain chain);

  std::string describe() const override { return "replay:" + name_ + " (poses)"; }

 protected:
  Status open() override;
  Result<acquisition::Polled> poll(Pose& pose) override;
  bool is_playback() const override { return true; }

 private:
  std::shared_ptr<const acquisition::SequenceFile> file_;
  std::string name_;
  std::string probe_;
  std::string reference_;
  bool has_reference_ = false;
  std::optional<acquisition::PoseChain> chain_;
  std::size_t next_ = 0;
};
/// The stream of a ReplayPoses.
using ReplayPoseSource = acquisition::SourceOf<ReplayPoses>;

/// The pose sample of frame k along `chain`, as ReplayPoseSource delivers it.
Pose replay_pose(const acquisition::SequenceFile& file, std::size_t k,
                 const acquisition::PoseChain& chain);

/// The pose sample of frame k of a sequence file as ReplayPoseSource delivers it.
Pose replay_pose(const acquisition::SequenceFile& file, std::size_t k,
                 const std::string& probe_transform = "ProbeToTracker",
                 const std::string& reference_transform = "ReferenceToTracker");

/// The nearest rigid transform to a 4x4 matrix (rotation projected by SVD, translation kept):
/// tracker files store rotations with rounding errors, and slerp needs exact rotations.
Eigen::Isometry3d nearest_rigid(const Eigen::Matrix4d& matrix);

}  // namespace sonoshape::tracking
