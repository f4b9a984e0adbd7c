#pragma once
// Time synchronisation of frames and tracker samples: every frame gets the probe pose at its
// timestamp, interpolated between the tracker samples around it (linear position, spherical
// rotation), after shifting the tracker's clock by its latency. Frames whose pose would be
// made up (no samples, an INVALID neighbour, lost samples between the neighbours, a time
// outside the samples) get none, with the reason, so the pipeline can drop and count them.
#include <cstddef>
#include <deque>
#include <string>

#include "sonoshape/core/frame.hpp"

namespace sonoshape::tracking {

/// Parameters of the synchronisation.
struct SyncOptions {
  /// How late the tracker's timestamps are on the frames' clock (s): a sample stamped t
  /// measured the pose at frame time t - tracker_latency_s. Measure it with a temporal
  /// calibration (PLUS: LocalTimeOffsetSec, with the opposite sign).
  double tracker_latency_s = 0.0;
  /// Neighbouring samples further apart than this (s) do not interpolate: samples were lost
  /// between them. 0.1 s covers a 40 Hz tracker losing three samples in a row.
  double max_gap_s = 0.1;
  /// How far (s) before the first or after the last sample a pose may be extrapolated (from
  /// the two samples at that end); 0: never.
  double max_extrapolation_s = 0.0;
};

/// Why a frame got no pose.
enum class SyncFailure {
  kNone,           ///< it got one
  kMissing,        ///< no tracker sample at all
  kInvalid,        ///< a neighbouring sample is INVALID (sensor out of range, occluded)
  kGap,            ///< the neighbouring samples are more than max_gap_s apart
  kExtrapolation,  ///< the frame is outside the samples by more than max_extrapolation_s
};

/// "ok", "missing", "invalid", "gap", "extrapolation".
const char* to_string(SyncFailure failure);

/// The pose at a frame's time, or why there is none.
struct SyncedPose {
  /// On success: T_reference_probe at the frame's time, timestamp_s = the frame's time,
  /// status kValid. On failure: status kInvalid (and a pose no one should use).
  Pose pose;
  SyncFailure failure = SyncFailure::kNone;
  bool ok() const { return failure == SyncFailure::kNone; }
};

/// The rigid motion of `a` and `b` at time t_s: linear in position, along the shortest great
/// arc in rotation (slerp); t_s outside [a, b] extrapolates the same motion. Uses only the
/// poses and timestamps (statuses are the caller's business). Returns `a`'s transform when the
/// two timestamps are equal.
Eigen::Isometry3d interpolate(const Pose& a, const Pose& b, double t_s);

/// The tracker samples of the recent past and the pose of a frame from them. Not thread-safe
/// (the acquisition thread owns it).
class PoseBuffer {
 public:
  /// Throws std::invalid_argument for a negative max_gap_s or max_extrapolation_s.
  explicit PoseBuffer(const SyncOptions& options = {});

  const SyncOptions& options() const { return options_; }

  /// Appends a tracker sample (its own clock). Samples must come in time order: one not later
  /// than the last is ignored and false is returned.
  bool add(const Pose& sample);

  /// The pose at `frame_timestamp_s` (frames' clock), see SyncOptions. A sample exactly at the
  /// frame's time is used as it is (its own status decides).
  SyncedPose pose_at(double frame_timestamp_s) const;

  /// Latest sample time on the frames' clock (its stamp minus the latency); -infinity when
  /// empty. Whether a frame can be interpolated yet: latest_frame_time_s() >= its time.
  double latest_frame_time_s() const;

  /// Forgets samples no frame at or after `frame_timestamp_s` needs (keeps the last one
  /// before it, which interpolation still uses).
  void discard_before(double frame_timestamp_s);

  /// Samples held.
  std::size_t size() const { return samples_.size(); }

 private:
  SyncOptions options_;
  std::deque<Pose> samples_;  // stamps on the tracker's clock, increasing
};

}  // namespace sonoshape::tracking
