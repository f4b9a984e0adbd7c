#include "sonoshape/tracking/pose_source.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <utility>

namespace sonoshape::tracking {

RecordedPoses::RecordedPoses(std::vector<Pose> samples, std::string name, long fail_after)
    : samples_(std::move(samples)), name_(std::move(name)), fail_after_(fail_after) {}

Status RecordedPoses::open() {
  next_ = 0;
  return Status::ok();
}

Result<acquisition::Polled> RecordedPoses::poll(Pose& pose) {
  if (fail_after_ >= 0 && next_ >= static_cast<std::size_t>(fail_after_))
    return Status::error(name_ + ": tracker vanished after " + std::to_string(next_) +
                         " samples (check the tracker's cable and power)");
  if (next_ >= samples_.size()) return acquisition::Polled::kEnd;
  pose = samples_[next_++];
  return acquisition::Polled::kItem;
}

Eigen::Isometry3d nearest_rigid(const Eigen::Matrix4d& matrix) {
  const Eigen::Matrix3d m = matrix.block<3, 3>(0, 0);
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d r = svd.matrixU() * svd.matrixV().transpose();
  if (r.determinant() < 0.0) {
    // A reflection is no pose; flip the axis of the smallest singular value.
    Eigen::Matrix3d u = svd.matrixU();
    u.col(2) = -u.col(2);
    r = u * svd.matrixV().transpose();
  }
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = r;
  out.translation() = matrix.block<3, 1>(0, 3);
  return out;
}

namespace {

bool has_transform(const acquisition::SequenceFile& file, const std::string& name) {
  const auto names = file.transform_names();
  return std::find(names.begin(), names.end(), name) != names.end();
}

// replay_pose with the (whole-file) check for a reference transform done once by the caller.
Pose pose_of_frame(const acquisition::SequenceFile& file, std::size_t k,
                   const std::string& probe_transform, const std::string& reference_transform,
                   bool has_reference) {
  Pose pose;
  pose.timestamp_s = file.timestamp_s(k).value_or(0.0);
  pose.status = TrackingStatus::kInvalid;
  if (file.transform_status(probe_transform, k) != TrackingStatus::kValid) return pose;
  const auto probe = file.transform(probe_transform, k);
  if (!probe) return pose;
  Eigen::Matrix4d reference_from_probe = *probe;
  if (has_reference) {
    if (file.transform_status(reference_transform, k) != TrackingStatus::kValid) return pose;
    const auto reference = file.transform(reference_transform, k);
    if (!reference) return pose;
    reference_from_probe = reference->inverse() * *probe;
  }
  if (!reference_from_probe.allFinite()) return pose;
  pose.T_reference_probe = nearest_rigid(reference_from_probe);
  pose.status = TrackingStatus::kValid;
  return pose;
}

}  // namespace

Pose replay_pose(const acquisition::SequenceFile& file, std::size_t k,
                 const std::string& probe_transform, const std::string& reference_transform) {
  return pose_of_frame(file, k, probe_transform, reference_transform,
                       has_transform(file, reference_transform));
}

ReplayPoses::ReplayPoses(std::shared_ptr<const acquisition::SequenceFile> file, std::string name,
                         std::string probe_transform, std::string reference_transform)
    : file_(std::move(file)),
      name_(std::move(name)),
      probe_(std::move(probe_transform)),
      reference_(std::move(reference_transform)) {}

ReplayPoses::ReplayPoses(std::shared_ptr<const acquisition::SequenceFile> file, std::string name,
                         acquisition::PoseChain chain)
    : file_(std::move(file)), name_(std::move(name)), chain_(std::move(chain)) {}

Pose replay_pose(const acquisition::SequenceFile& file, std::size_t k,
                 const acquisition::PoseChain& chain) {
  Pose pose;
  pose.timestamp_s = file.timestamp_s(k).value_or(0.0);
  pose.status = TrackingStatus::kInvalid;
  if (const auto T_to_from = chain.pose(file, k)) {
    pose.T_reference_probe = nearest_rigid(*T_to_from);
    pose.status = TrackingStatus::kValid;
  }
  return pose;
}

Status ReplayPoses::open() {
  if (!file_ || file_->frame_count() == 0)
    return Status::error(describe() + ": the sequence has no frames");
  next_ = 0;
  if (chain_) return Status::ok();
  if (!has_transform(*file_, probe_)) {
    const auto names = file_->transform_names();
    std::string known;
    for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
    return Status::error(describe() + ": no " + probe_ +
                         "Transform field (the file has: " + (known.empty() ? "none" : known) +
                         "); record the probe with the tracker or name another transform");
  }
  has_reference_ = has_transform(*file_, reference_);
  next_ = 0;
  return Status::ok();
}

Result<acquisition::Polled> ReplayPoses::poll(Pose& pose) {
  if (next_ >= file_->frame_count()) return acquisition::Polled::kEnd;
  pose = chain_ ? replay_pose(*file_, next_++, *chain_)
                : pose_of_frame(*file_, next_++, probe_, reference_, has_reference_);
  return acquisition::Polled::kItem;
}

}  // namespace sonoshape::tracking
