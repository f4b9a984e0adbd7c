#include "sonoshape/tracking/time_sync.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace sonoshape::tracking {
namespace {

// Timestamps are decimal numbers in binary doubles: samples 0.1 s apart may differ by
// 0.10000000000000009. A microsecond is far below any tracker's resolution.
constexpr double kTimeToleranceS = 1e-6;

}  // namespace

const char* to_string(SyncFailure failure) {
  switch (failure) {
    case SyncFailure::kNone:
      return "ok";
    case SyncFailure::kMissing:
      return "missing";
    case SyncFailure::kInvalid:
      return "invalid";
    case SyncFailure::kGap:
      return "gap";
    case SyncFailure::kExtrapolation:
      return "extrapolation";
  }
  return "unknown";
}

Eigen::Isometry3d interpolate(const Pose& a, const Pose& b, double t_s) {
  const double span_s = b.timestamp_s - a.timestamp_s;
  if (span_s == 0.0) return a.T_reference_probe;
  const double alpha = (t_s - a.timestamp_s) / span_s;
  const Eigen::Quaterniond qa(a.T_reference_probe.linear());
  Eigen::Quaterniond delta = qa.conjugate() * Eigen::Quaterniond(b.T_reference_probe.linear());
  // q and -q are the same rotation: take the short way round, as slerp does.
  if (delta.w() < 0.0) delta.coeffs() = -delta.coeffs();
  const Eigen::AngleAxisd step(delta.normalized());
  // qa * delta^alpha: exact slerp for alpha in [0, 1], the same rotation rate beyond.
  const Eigen::Quaterniond q =
      qa * Eigen::Quaterniond(Eigen::AngleAxisd(alpha * step.angle(), step.axis()));
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = q.normalized().toRotationMatrix();
  out.translation() =
      (1.0 - alpha) * a.T_reference_probe.translation() + alpha * b.T_reference_probe.translation();
  return out;
}

PoseBuffer::PoseBuffer(const SyncOptions& options) : options_(options) {
  if (!(options.max_gap_s >= 0.0) || !(options.max_extrapolation_s >= 0.0))
    throw std::invalid_argument("PoseBuffer: max_gap_s and max_extrapolation_s must be >= 0");
}

bool PoseBuffer::add(const Pose& sample) {
  if (!std::isfinite(sample.timestamp_s)) return false;
  if (!samples_.empty() && sample.timestamp_s <= samples_.back().timestamp_s) return false;
  samples_.push_back(sample);
  return true;
}

double PoseBuffer::latest_frame_time_s() const {
  if (samples_.empty()) return -std::numeric_limits<double>::infinity();
  return samples_.back().timestamp_s - options_.tracker_latency_s;
}

void PoseBuffer::discard_before(double frame_timestamp_s) {
  const double t = frame_timestamp_s + options_.tracker_latency_s;
  // Keep samples_[1] once it is at or before t: samples_[0] is then no neighbour of any frame
  // at or after t.
  while (samples_.size() >= 2 && samples_[1].timestamp_s <= t) samples_.pop_front();
}

SyncedPose PoseBuffer::pose_at(double frame_timestamp_s) const {
  SyncedPose out;
  out.pose.timestamp_s = frame_timestamp_s;
  out.pose.status = TrackingStatus::kInvalid;
  if (samples_.empty()) {
    out.failure = SyncFailure::kMissing;
    return out;
  }
  // On the tracker's clock.
  const double t = frame_timestamp_s + options_.tracker_latency_s;
  const auto after =
      std::lower_bound(samples_.begin(), samples_.end(), t,
                       [](const Pose& p, double time) { return p.timestamp_s < time; });
  if (after != samples_.end() && after->timestamp_s == t) {
    out.pose.T_reference_probe = after->T_reference_probe;
    if (after->status != TrackingStatus::kValid) {
      out.failure = SyncFailure::kInvalid;
      return out;
    }
    out.pose.status = TrackingStatus::kValid;
    return out;
  }
  const Pose* a = nullptr;
  const Pose* b = nullptr;
  if (after == samples_.begin() || after == samples_.end()) {
    // Outside the samples: extrapolate from the two at that end, when allowed.
    const bool before_first = after == samples_.begin();
    const double outside_s =
        before_first ? samples_.front().timestamp_s - t : t - samples_.back().timestamp_s;
    if (samples_.size() < 2 || outside_s > options_.max_extrapolation_s + kTimeToleranceS) {
      out.failure = SyncFailure::kExtrapolation;
      return out;
    }
    a = before_first ? &samples_[0] : &samples_[samples_.size() - 2];
    b = before_first ? &samples_[1] : &samples_.back();
  } else {
    a = &*(after - 1);
    b = &*after;
  }
  if (a->status != TrackingStatus::kValid || b->status != TrackingStatus::kValid) {
    out.failure = SyncFailure::kInvalid;
    return out;
  }
  if (b->timestamp_s - a->timestamp_s > options_.max_gap_s + kTimeToleranceS) {
    out.failure = SyncFailure::kGap;
    return out;
  }
  out.pose.T_reference_probe = interpolate(*a, *b, t);
  out.pose.status = TrackingStatus::kValid;
  return out;
}

}  // namespace sonoshape::tracking
