#include "sonoshape/simulator/trajectory.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace sonoshape::simulator::trajectory_test {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

TEST(Trajectory, DeterministicForASeed) {
  TrajectoryOptions options;
  options.speed = SpeedProfile::kIrregular;
  options.seed = 11;
  const Trajectory a(options), b(options);
  options.seed = 12;
  const Trajectory c(options);
  double max_difference = 0.0;
  for (double t = -0.5; t <= 10.5; t += 0.37) {
    EXPECT_EQ(a.T_reference_probe(t).matrix(), b.T_reference_probe(t).matrix());
    max_difference = std::max(
        max_difference,
        (a.T_reference_probe(t).translation() - c.T_reference_probe(t).translation()).norm());
  }
  EXPECT_GT(max_difference, 0.1);
}

TEST(Trajectory, PassesGoBackAndForthOverTheSameExtent) {
  TrajectoryOptions options;
  options.speed = SpeedProfile::kConstant;
  options.duration_s = 12.0;
  options.passes = 3;
  const Trajectory trajectory(options);
  EXPECT_DOUBLE_EQ(trajectory.progress(0.0), 0.0);
  EXPECT_DOUBLE_EQ(trajectory.progress(2.0), 0.5);    // half of the first pass, going out
  EXPECT_NEAR(trajectory.progress(4.0), 1.0, 1e-12);  // turns at the far end
  EXPECT_DOUBLE_EQ(trajectory.progress(6.0), 0.5);    // coming back
  EXPECT_NEAR(trajectory.progress(8.0), 0.0, 1e-12);  // back at the start
  EXPECT_DOUBLE_EQ(trajectory.progress(12.0), 1.0);   // the third pass ends at the far end
  options.passes = 0;
  EXPECT_THROW(Trajectory{options}, std::invalid_argument);
}

TEST(Trajectory, SweepsCoverTheirExtentWithMonotoneProgress) {
  for (const SpeedProfile speed :
       {SpeedProfile::kConstant, SpeedProfile::kSmooth, SpeedProfile::kIrregular}) {
    TrajectoryOptions options;
    options.speed = speed;
    options.seed = 3;
    const Trajectory trajectory(options);
    EXPECT_DOUBLE_EQ(trajectory.progress(0.0), 0.0);
    EXPECT_DOUBLE_EQ(trajectory.progress(options.duration_s), 1.0);
    for (double t = 0.01; t <= options.duration_s; t += 0.01)
      ASSERT_GE(trajectory.progress(t), trajectory.progress(t - 0.01));
    // Translation along the image normal: 80 mm give or take the hand's drift.
    const Vec3 travel = trajectory.T_reference_probe(options.duration_s).translation() -
                        trajectory.T_reference_probe(0.0).translation();
    EXPECT_NEAR(travel.z(), 80.0, 6.0);
    EXPECT_LT(travel.head<2>().norm(), 6.0);
  }
  TrajectoryOptions fan;
  fan.motion = SweepMotion::kFan;
  fan.tremor_deg = fan.drift_deg = 0.0;
  const Trajectory trajectory(fan);
  const Eigen::Matrix3d turn = trajectory.T_reference_probe(0.0).linear().transpose() *
                               trajectory.T_reference_probe(fan.duration_s).linear();
  EXPECT_NEAR(Eigen::AngleAxisd(turn).angle() * kRadToDeg, 60.0, 1e-9);
  EXPECT_NEAR(std::abs(Eigen::AngleAxisd(turn).axis().x()), 1.0, 1e-9);  // about the array
}

TEST(Tracker, NoiseDropsAndInvalidBurstsHaveTheRequestedStatistics) {
  TrajectoryOptions motion;
  motion.duration_s = 60.0;
  const Trajectory trajectory(motion);
  TrackerOptions options;
  options.rate_hz = 100.0;
  options.latency_s = 0.04;
  options.position_noise_mm = 0.2;
  options.angle_noise_deg = 0.1;
  options.drop_probability = 0.05;
  options.invalid_probability = 0.002;
  options.invalid_burst_s = 0.3;
  const auto samples = track(trajectory, options, 0.0, 60.0);
  const double ticks = 6001;
  const double dropped = 1.0 - samples.size() / ticks;
  EXPECT_NEAR(dropped, 0.05, 4.0 * std::sqrt(0.05 * 0.95 / ticks));
  Vec3 position_sum = Vec3::Zero(), position_sq = Vec3::Zero(), angle_sq = Vec3::Zero();
  double valid = 0, invalid = 0;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const Pose& p = samples[k];
    if (k > 0) {
      ASSERT_GT(p.timestamp_s, samples[k - 1].timestamp_s);
    }
    if (p.status == TrackingStatus::kInvalid) {
      ++invalid;
      continue;
    }
    ++valid;
    // Stamped `latency` after the true time of the measurement.
    const Eigen::Isometry3d truth = trajectory.T_reference_probe(p.timestamp_s - 0.04);
    const Vec3 error = p.T_reference_probe.translation() - truth.translation();
    position_sum += error;
    position_sq += error.cwiseProduct(error);
    const Eigen::AngleAxisd rotation(p.T_reference_probe.linear() * truth.linear().transpose());
    const Vec3 angle = rotation.angle() * rotation.axis() * kRadToDeg;
    angle_sq += angle.cwiseProduct(angle);
  }
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_NEAR(position_sum[axis] / valid, 0.0, 0.01);
    EXPECT_NEAR(std::sqrt(position_sq[axis] / valid), 0.2, 0.2 * 0.05);
    EXPECT_NEAR(std::sqrt(angle_sq[axis] / valid), 0.1, 0.1 * 0.05);
  }
  // About 0.002 * 6000 = 12 bursts of 30 samples.
  EXPECT_GT(invalid, 100);
  EXPECT_LT(invalid, 1000);
}

TEST(Tracker, FramesGetInterpolatedPosesDelayedByTheLatency) {
  TrajectoryOptions motion;
  motion.duration_s = 5.0;
  motion.tremor_mm = motion.tremor_deg = 0.0;  // smooth: interpolation error stays tiny
  const Trajectory trajectory(motion);
  TrackerOptions options;
  options.position_noise_mm = options.angle_noise_deg = 0.0;
  options.drop_probability = options.invalid_probability = 0.0;
  options.latency_s = 0.1;
  const SimulatedAcquisition acquisition = acquire(trajectory, options, 101, 20.0);
  ASSERT_EQ(acquisition.tracked_poses.size(), 101u);
  double lagged = 0.0, error_to_lagged = 0.0;
  for (std::size_t k = 0; k < 101; ++k) {
    const double t = acquisition.frame_times_s[k];
    const Pose& pose = acquisition.tracked_poses[k];
    ASSERT_EQ(pose.status, TrackingStatus::kValid);
    lagged = std::max(
        lagged,
        (pose.T_reference_probe.translation() - acquisition.true_poses[k].translation()).norm());
    error_to_lagged = std::max(
        error_to_lagged,
        (pose.T_reference_probe.translation() - trajectory.T_reference_probe(t - 0.1).translation())
            .norm());
  }
  EXPECT_GT(lagged, 1.0);  // 80 mm in 5 s: latency shows as mm-scale errors
  EXPECT_LT(error_to_lagged, 0.02);

  // Gaps and INVALID neighbours make frames invalid.
  std::vector<Pose> samples(3);
  samples[0].timestamp_s = 0.0;
  samples[1].timestamp_s = 0.025;
  samples[2].timestamp_s = 0.2;
  samples[1].T_reference_probe.translation() = Vec3(1, 0, 0);
  const Pose half = interpolate_pose(samples, 0.0125, 0.0625);
  EXPECT_EQ(half.status, TrackingStatus::kValid);
  EXPECT_NEAR(half.T_reference_probe.translation().x(), 0.5, 1e-12);
  EXPECT_EQ(interpolate_pose(samples, 0.1, 0.0625).status, TrackingStatus::kInvalid);  // gap
  EXPECT_EQ(interpolate_pose(samples, 0.3, 0.0625).status, TrackingStatus::kInvalid);  // after
  samples[1].status = TrackingStatus::kInvalid;
  EXPECT_EQ(interpolate_pose(samples, 0.0125, 0.0625).status, TrackingStatus::kInvalid);
}

}  // namespace
}  // namespace sonoshape::simulator::trajectory_test
