// Time sync with known poses: exact at samples and midpoints, slerp, the latency shift, and
// every reason a frame gets no pose.
#include "sonoshape/tracking/time_sync.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::tracking::time_sync_test {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Pose sample(double t_s, const Vec3& position, double angle_z_deg,
            TrackingStatus status = TrackingStatus::kValid) {
  Pose p;
  p.timestamp_s = t_s;
  p.T_reference_probe.translation() = position;
  p.T_reference_probe.linear() =
      Eigen::AngleAxisd(angle_z_deg * kDeg, Vec3::UnitZ()).toRotationMatrix();
  p.status = status;
  return p;
}

double angle_z_deg(const Eigen::Isometry3d& T) {
  return std::atan2(T.linear()(1, 0), T.linear()(0, 0)) / kDeg;
}

TEST(TimeSync, ExactAtSamplesAndMidpoints) {
  PoseBuffer buffer;
  ASSERT_TRUE(buffer.add(sample(1.00, Vec3(0, 0, 0), 0.0)));
  ASSERT_TRUE(buffer.add(sample(1.05, Vec3(10, -4, 2), 30.0)));
  ASSERT_TRUE(buffer.add(sample(1.10, Vec3(20, -8, 4), 60.0)));

  const SyncedPose at_sample = buffer.pose_at(1.05);
  ASSERT_TRUE(at_sample.ok());
  EXPECT_TRUE(at_sample.pose.T_reference_probe.isApprox(
      sample(1.05, Vec3(10, -4, 2), 30).T_reference_probe));
  EXPECT_EQ(at_sample.pose.timestamp_s, 1.05);
  EXPECT_EQ(at_sample.pose.status, TrackingStatus::kValid);

  const SyncedPose mid = buffer.pose_at(1.025);
  ASSERT_TRUE(mid.ok()) << to_string(mid.failure);
  EXPECT_NEAR((mid.pose.T_reference_probe.translation() - Vec3(5, -2, 1)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(angle_z_deg(mid.pose.T_reference_probe), 15.0, 1e-9);

  // A quarter of the way: linear in position, uniform in angle (slerp).
  const SyncedPose quarter = buffer.pose_at(1.0625);
  ASSERT_TRUE(quarter.ok());
  EXPECT_NEAR((quarter.pose.T_reference_probe.translation() - Vec3(12.5, -5, 2.5)).norm(), 0.0,
              1e-9);
  EXPECT_NEAR(angle_z_deg(quarter.pose.T_reference_probe), 37.5, 1e-9);
}

TEST(TimeSync, SlerpMatchesEigenOnAGeneralRotation) {
  Pose a, b;
  a.timestamp_s = 0.0;
  b.timestamp_s = 1.0;
  a.T_reference_probe.linear() =
      Eigen::AngleAxisd(0.3, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  b.T_reference_probe.linear() =
      Eigen::AngleAxisd(-1.1, Vec3(-2, 1, 0.5).normalized()).toRotationMatrix();
  for (const double t : {0.0, 0.2, 0.5, 0.9, 1.0}) {
    const Eigen::Quaterniond expected =
        Eigen::Quaterniond(a.T_reference_probe.linear())
            .slerp(t, Eigen::Quaterniond(b.T_reference_probe.linear()));
    EXPECT_TRUE(interpolate(a, b, t).linear().isApprox(expected.toRotationMatrix(), 1e-12)) << t;
  }
  // The short way round: 350 degrees to 10 degrees passes through 0, not 180.
  const Pose c = sample(0.0, Vec3::Zero(), 350.0), d = sample(1.0, Vec3::Zero(), 10.0);
  EXPECT_NEAR(angle_z_deg(interpolate(c, d, 0.5)), 0.0, 1e-9);
}

TEST(TimeSync, LatencyShiftsTheTrackerClock) {
  // The tracker stamps its samples 30 ms late: the sample stamped 0.13 is the pose at 0.10.
  SyncOptions options;
  options.tracker_latency_s = 0.03;
  PoseBuffer buffer(options);
  buffer.add(sample(0.13, Vec3(1, 0, 0), 0.0));
  buffer.add(sample(0.18, Vec3(2, 0, 0), 10.0));
  EXPECT_DOUBLE_EQ(buffer.latest_frame_time_s(), 0.15);
  const SyncedPose at = buffer.pose_at(0.10);
  ASSERT_TRUE(at.ok());
  EXPECT_NEAR(at.pose.T_reference_probe.translation().x(), 1.0, 1e-12);
  const SyncedPose mid = buffer.pose_at(0.125);
  ASSERT_TRUE(mid.ok());
  EXPECT_NEAR(mid.pose.T_reference_probe.translation().x(), 1.5, 1e-12);
  EXPECT_NEAR(angle_z_deg(mid.pose.T_reference_probe), 5.0, 1e-9);
  // Without the correction the same frame time would lie before the samples.
  PoseBuffer uncorrected;
  uncorrected.add(sample(0.13, Vec3(1, 0, 0), 0.0));
  uncorrected.add(sample(0.18, Vec3(2, 0, 0), 10.0));
  EXPECT_EQ(uncorrected.pose_at(0.10).failure, SyncFailure::kExtrapolation);
}

TEST(TimeSync, RefusesToExtrapolateUnlessAllowed) {
  PoseBuffer buffer;
  EXPECT_EQ(buffer.pose_at(1.0).failure, SyncFailure::kMissing);
  buffer.add(sample(1.0, Vec3(0, 0, 0), 0.0));
  buffer.add(sample(1.1, Vec3(1, 0, 0), 10.0));
  EXPECT_EQ(buffer.pose_at(1.15).failure, SyncFailure::kExtrapolation);
  EXPECT_EQ(buffer.pose_at(0.95).failure, SyncFailure::kExtrapolation);
  EXPECT_EQ(buffer.pose_at(1.15).pose.status, TrackingStatus::kInvalid);

  SyncOptions options;
  options.max_extrapolation_s = 0.06;
  PoseBuffer lenient(options);
  lenient.add(sample(1.0, Vec3(0, 0, 0), 0.0));
  lenient.add(sample(1.1, Vec3(1, 0, 0), 10.0));
  const SyncedPose ahead = lenient.pose_at(1.15);
  ASSERT_TRUE(ahead.ok());
  EXPECT_NEAR(ahead.pose.T_reference_probe.translation().x(), 1.5, 1e-12);  // same motion
  EXPECT_NEAR(angle_z_deg(ahead.pose.T_reference_probe), 15.0, 1e-9);
  EXPECT_EQ(lenient.pose_at(1.2).failure, SyncFailure::kExtrapolation);  // 0.1 s > 0.06 s
  EXPECT_TRUE(lenient.pose_at(0.95).ok());
}

TEST(TimeSync, InvalidNeighboursAndGapsGiveNoPose) {
  SyncOptions options;
  options.max_gap_s = 0.06;
  PoseBuffer buffer(options);
  buffer.add(sample(0.00, Vec3(0, 0, 0), 0));
  buffer.add(sample(0.05, Vec3(1, 0, 0), 0, TrackingStatus::kInvalid));
  buffer.add(sample(0.10, Vec3(2, 0, 0), 0));
  buffer.add(sample(0.25, Vec3(3, 0, 0), 0));  // 0.15 s after the previous one: lost samples
  buffer.add(sample(0.30, Vec3(4, 0, 0), 0));
  EXPECT_EQ(buffer.pose_at(0.02).failure, SyncFailure::kInvalid);
  EXPECT_EQ(buffer.pose_at(0.07).failure, SyncFailure::kInvalid);
  EXPECT_EQ(buffer.pose_at(0.05).failure, SyncFailure::kInvalid);  // the INVALID sample itself
  EXPECT_TRUE(buffer.pose_at(0.10).ok());
  EXPECT_EQ(buffer.pose_at(0.2).failure, SyncFailure::kGap);
  EXPECT_TRUE(buffer.pose_at(0.27).ok());
  EXPECT_STREQ(to_string(SyncFailure::kGap), "gap");
}

TEST(TimeSync, KeepsTimeOrderAndDiscardsWhatNoFrameNeeds) {
  PoseBuffer buffer;
  for (int k = 0; k < 10; ++k) ASSERT_TRUE(buffer.add(sample(0.1 * k, Vec3(k, 0, 0), 0)));
  EXPECT_FALSE(buffer.add(sample(0.5, Vec3::Zero(), 0)));  // out of order
  EXPECT_FALSE(buffer.add(sample(0.9, Vec3::Zero(), 0)));  // duplicate time
  buffer.discard_before(0.55);
  EXPECT_EQ(buffer.size(), 5u);  // 0.5 (the neighbour before 0.55) .. 0.9
  const SyncedPose p = buffer.pose_at(0.55);
  ASSERT_TRUE(p.ok());
  EXPECT_NEAR(p.pose.T_reference_probe.translation().x(), 5.5, 1e-9);
  EXPECT_THROW(PoseBuffer(SyncOptions{0.0, -1.0, 0.0}), std::invalid_argument);
}

}  // namespace
}  // namespace sonoshape::tracking::time_sync_test
