// Pose sources: the PLUS sweep's poses as the segmenter computes them, INVALID statuses, and
// a tracker that vanishes.
#include "sonoshape/tracking/pose_source.hpp"

#include <gtest/gtest.h>

#include <filesystem>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::tracking::pose_source_test {
namespace {

const std::filesystem::path kPlusSweep =
    std::filesystem::path(SONOSHAPE_DATA_DIR) / "plus" / "SpinePhantomFreehand.igs.mha";

std::vector<Pose> drain(PoseSource& source) {
  std::vector<Pose> poses;
  while (auto p = source.next(5.0)) poses.push_back(p->item);
  return poses;
}

TEST(ReplayPoseSource, RealSweepGivesReferenceFromProbe) {
  auto file = acquisition::read_sequence_file(kPlusSweep);
  ASSERT_TRUE(file) << file.message();
  auto shared = std::make_shared<const acquisition::SequenceFile>(std::move(*file));
  ReplayPoseSource source(shared, "spine");
  acquisition::SourceOptions options;
  options.wait_when_full = true;
  ASSERT_TRUE(source.start(options));
  const auto poses = drain(source);
  ASSERT_EQ(poses.size(), 21u);
  EXPECT_EQ(source.state(), acquisition::SourceState::kEnded);
  for (std::size_t k = 0; k < poses.size(); ++k) {
    EXPECT_DOUBLE_EQ(poses[k].timestamp_s, *shared->timestamp_s(k));
    ASSERT_EQ(poses[k].status, TrackingStatus::kValid) << k;
    const Eigen::Matrix4d expected = shared->transform("ReferenceToTracker", k)->inverse() *
                                     *shared->transform("ProbeToTracker", k);
    // Equal up to the rounding of the file's rotations (6 digits).
    EXPECT_LT((poses[k].T_reference_probe.matrix() - expected).cwiseAbs().maxCoeff(), 1e-4) << k;
    EXPECT_NEAR(poses[k].T_reference_probe.linear().determinant(), 1.0, 1e-12);
  }
}

TEST(ReplayPoseSource, InvalidStatusesAndMissingTransforms) {
  acquisition::SequenceFile file;
  const Eigen::Matrix4d identity = Eigen::Matrix4d::Identity();
  for (int k = 0; k < 3; ++k) {
    file.add_frame(GreyImage(2, 2), {{"Timestamp", std::to_string(k)}});
    file.set_transform("ProbeToTracker", static_cast<std::size_t>(k), identity,
                       k == 1 ? TrackingStatus::kInvalid : TrackingStatus::kValid);
  }
  EXPECT_EQ(replay_pose(file, 0).status, TrackingStatus::kValid);  // no reference: tracker
  EXPECT_EQ(replay_pose(file, 1).status, TrackingStatus::kInvalid);
  EXPECT_DOUBLE_EQ(replay_pose(file, 2).timestamp_s, 2.0);

  ReplayPoseSource wrong(std::make_shared<const acquisition::SequenceFile>(file), "x",
                         "StylusToTracker");
  ASSERT_TRUE(wrong.start());
  EXPECT_TRUE(drain(wrong).empty());
  EXPECT_EQ(wrong.state(), acquisition::SourceState::kFailed);
  EXPECT_NE(wrong.message().find("no StylusToTrackerTransform"), std::string::npos)
      << wrong.message();
}

TEST(RecordedPoseSource, PlaysSamplesThenVanishes) {
  std::vector<Pose> samples(5);
  for (int k = 0; k < 5; ++k) samples[static_cast<std::size_t>(k)].timestamp_s = 0.025 * k;
  RecordedPoseSource ok(samples, "sim tracker");
  ASSERT_TRUE(ok.start());
  EXPECT_EQ(drain(ok).size(), 5u);
  EXPECT_EQ(ok.state(), acquisition::SourceState::kEnded);

  RecordedPoseSource vanishing(samples, "sim tracker", 3);
  ASSERT_TRUE(vanishing.start());
  EXPECT_EQ(drain(vanishing).size(), 3u);
  EXPECT_EQ(vanishing.state(), acquisition::SourceState::kFailed);
  EXPECT_NE(vanishing.message().find("vanished"), std::string::npos);
}

TEST(NearestRigid, ProjectsRotationsWithRoundingErrors) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.7, Vec3(1, 1, 0).normalized()).toRotationMatrix();
  m(0, 1) += 1e-6;
  m.block<3, 1>(0, 3) = Vec3(1, 2, 3);
  const Eigen::Isometry3d T = nearest_rigid(m);
  EXPECT_NEAR((T.linear().transpose() * T.linear() - Eigen::Matrix3d::Identity()).norm(), 0.0,
              1e-12);
  EXPECT_LT((T.matrix() - m).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_EQ(T.translation(), Vec3(1, 2, 3));
}

}  // namespace
}  // namespace sonoshape::tracking::pose_source_test
