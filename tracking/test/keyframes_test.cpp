// Keyframe selection: thresholds in degrees and mm, near-duplicates skipped, withdrawal.
#include "sonoshape/tracking/keyframes.hpp"

#include <gtest/gtest.h>

#include <numbers>

#include "sonoshape/core/errors.hpp"

namespace sonoshape::tracking::keyframes_test {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// A 100 x 100 pixel image of 0.5 mm pixels (50 mm square) whose top edge is the probe face:
// the pose moves it.
FramePlane plane_at(const Eigen::Isometry3d& T_reference_probe) {
  Eigen::Matrix4d T_probe_image = Eigen::Matrix4d::Identity();
  T_probe_image(0, 0) = T_probe_image(1, 1) = T_probe_image(2, 2) = 0.5;
  T_probe_image(0, 3) = -25.0;
  return frame_plane(T_reference_probe.matrix() * T_probe_image,
                     bounding_corners({Vec2(0, 0), Vec2(100, 100)}));
}

Eigen::Isometry3d slide(double z_mm) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Vec3(0, 0, z_mm);
  return T;
}

Eigen::Isometry3d tilt(double angle_deg) {  // fan about the array axis at the face
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(angle_deg * kDeg, Vec3::UnitX()).toRotationMatrix();
  return T;
}

TEST(Keyframes, PlaneDifferenceInDegreesAndMillimetres) {
  const PlaneDifference parallel = plane_difference(plane_at(slide(0)), plane_at(slide(2.5)));
  EXPECT_NEAR(parallel.angle_deg, 0.0, 1e-9);
  EXPECT_NEAR(parallel.distance_mm, 2.5, 1e-9);
  // Tilting by 10 degrees about the face moves the deep corners by 50 mm * sin(10 deg).
  const PlaneDifference tilted = plane_difference(plane_at(tilt(0)), plane_at(tilt(10)));
  EXPECT_NEAR(tilted.angle_deg, 10.0, 1e-9);
  EXPECT_NEAR(tilted.distance_mm, 50.0 * std::sin(10 * kDeg), 1e-9);
  // Moving within the plane changes nothing: the plane is the same.
  Eigen::Isometry3d in_plane = Eigen::Isometry3d::Identity();
  in_plane.translation() = Vec3(7, 3, 0);
  in_plane.linear() = Eigen::AngleAxisd(0.4, Vec3::UnitZ()).toRotationMatrix();
  const PlaneDifference same = plane_difference(plane_at(slide(0)), plane_at(in_plane));
  EXPECT_NEAR(same.angle_deg, 0.0, 1e-9);
  EXPECT_NEAR(same.distance_mm, 0.0, 1e-9);
}

TEST(Keyframes, SkipsNearDuplicatesOfEveryAcceptedPlane) {
  KeyframeSelector selector(KeyframeOptions{5.0, 2.0});
  EXPECT_EQ(selector.offer(plane_at(slide(0.0))), 0);
  EXPECT_FALSE(selector.offer(plane_at(slide(1.0))));  // 1 mm < 2 mm and 0 deg < 5 deg
  EXPECT_FALSE(selector.offer(plane_at(slide(1.9))));
  EXPECT_EQ(selector.offer(plane_at(slide(2.0))), 1);  // far enough from 0
  EXPECT_FALSE(selector.offer(plane_at(slide(0.5))));  // back near 0: still a duplicate
  EXPECT_EQ(selector.offer(plane_at(slide(-2.5))), 2);
  // A tilt of 1 degree moves the deep corners by 0.87 mm: a duplicate; 3 degrees by 2.6 mm.
  EXPECT_FALSE(selector.offer(plane_at(tilt(1.0))));
  EXPECT_EQ(selector.offer(plane_at(tilt(3.0))), 3);
  EXPECT_EQ(selector.accepted(), 4u);
  EXPECT_EQ(selector.skipped(), 4u);
}

TEST(Keyframes, AngleAloneMakesAPlaneNew) {
  // A tiny image (corners barely move) rotated by more than the angle threshold is new.
  KeyframeSelector selector(KeyframeOptions{5.0, 100.0});
  EXPECT_TRUE(selector.offer(plane_at(tilt(0))));
  EXPECT_FALSE(selector.offer(plane_at(tilt(4.9))));
  EXPECT_TRUE(selector.offer(plane_at(tilt(5.1))));
}

TEST(Keyframes, WithdrawnPlanesCanBeTakenAgain) {
  KeyframeSelector selector(KeyframeOptions{5.0, 2.0});
  const auto key = selector.offer(plane_at(slide(0.0)));
  ASSERT_TRUE(key);
  EXPECT_FALSE(selector.offer(plane_at(slide(0.5))));
  EXPECT_TRUE(selector.withdraw(*key));
  EXPECT_FALSE(selector.withdraw(*key));
  EXPECT_EQ(selector.offer(plane_at(slide(0.5))), 1);  // the frame that failed is replaced
  EXPECT_EQ(selector.accepted(), 1u);
}

TEST(Keyframes, PastTheSliceBudgetOnlyPlanesBeyondTwiceTheThresholdsAreNew) {
  KeyframeOptions options{5.0, 2.0};
  options.slice_budget = 3;
  KeyframeSelector selector(options);
  // Within the budget: slices 2 mm apart, as without one.
  EXPECT_EQ(selector.offer(plane_at(slide(0.0))), 0);
  EXPECT_EQ(selector.offer(plane_at(slide(2.0))), 1);
  EXPECT_EQ(selector.offer(plane_at(slide(4.0))), 2);
  // Three accepted: a plane must now lie 4 mm (or 10 degrees and 4 mm at a corner) from all.
  EXPECT_FALSE(selector.offer(plane_at(slide(7.0))));  // 3 mm from slice 2
  EXPECT_FALSE(selector.offer(plane_at(slide(-3.0))));
  EXPECT_EQ(selector.offer(plane_at(slide(8.0))), 3);  // new anatomy still gets a slice
  EXPECT_EQ(selector.offer(plane_at(slide(-4.0))), 4);
  // A tilt of 3.5 degrees (3.1 mm at the deep corners) is new under the thresholds, not past
  // them.
  EXPECT_FALSE(selector.offer(plane_at(tilt(3.5))));
  EXPECT_EQ(selector.accepted(), 5u);
  EXPECT_EQ(selector.skipped(), 3u);
  // Withdrawing below the budget brings the thresholds back.
  KeyframeSelector small(options);
  ASSERT_TRUE(small.offer(plane_at(slide(0.0))));
  ASSERT_TRUE(small.offer(plane_at(slide(2.0))));
  const auto third = small.offer(plane_at(slide(4.0)));
  ASSERT_TRUE(third);
  EXPECT_FALSE(small.offer(plane_at(slide(7.0))));
  EXPECT_TRUE(small.withdraw(*third));
  EXPECT_TRUE(small.offer(plane_at(slide(7.0))));
}

TEST(Keyframes, RejectsBadInput) {
  EXPECT_THROW(KeyframeSelector(KeyframeOptions{-1.0, 1.0}), std::invalid_argument);
  EXPECT_THROW(bounding_corners({}), std::invalid_argument);
  EXPECT_THROW(frame_plane(Eigen::Matrix4d::Zero(), bounding_corners({Vec2(0, 0)})), GeometryError);
}

}  // namespace
}  // namespace sonoshape::tracking::keyframes_test
