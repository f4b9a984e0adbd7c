#include "sonoshape/simulator/sweep.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace sonoshape::simulator::sweep_test {
namespace {

TEST(Sweep, SimulatedSweepRoundTripsThroughSequenceFiles) {
  Phantom phantom;
  Eigen::Affine3d place = Eigen::Affine3d::Identity();
  place.translation() = Vec3(0, 30, 0);
  phantom.add(1, "liver lobe", make_sphere(15.0), place);
  phantom.add(2, "lesion", make_sphere(5.0), place);
  const acquisition::Probe probe(acquisition::convex_probe_geometry(96, 80));
  const BModeSimulator simulator(phantom, probe);
  TrajectoryOptions motion;
  motion.duration_s = 0.45;
  motion.sweep_length_mm = 20.0;
  TrackerOptions tracker;
  tracker.drop_probability = 0.2;
  tracker.invalid_probability = 0.1;
  const auto acquisition = acquire(Trajectory(motion), tracker, 10, 20.0);
  std::size_t reported = 0;
  const SimulatedSweep sweep =
      simulate_sweep(simulator, acquisition, 9, [&](std::size_t done) { reported = done; });
  EXPECT_EQ(reported, 10u);
  ASSERT_EQ(sweep.bmode.frame_count(), 10u);
  ASSERT_EQ(sweep.truth.frame_count(), 10u);
  ASSERT_EQ(sweep.slices.size(), 10u);

  // Grey levels recorded per label: dark organ, brighter background, bright lesion.
  const auto means = sweep.bmode.field("SonoshapeLabelGreyMean");
  ASSERT_TRUE(means);
  EXPECT_EQ(sweep.bmode.field("SonoshapeLabels"), "1:liver_lobe 2:lesion");

  const auto dir = std::filesystem::temp_directory_path() /
                   ("sonoshape_sweep_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  for (const auto& [file, name] :
       {std::pair{&sweep.bmode, "sweep.igs.mha"}, std::pair{&sweep.truth, "labels.mha"}}) {
    ASSERT_TRUE(acquisition::write_sequence_file(*file, dir / name));
    const auto reread = acquisition::read_sequence_file(dir / name);
    ASSERT_TRUE(reread) << reread.message();
    ASSERT_EQ(reread->frame_count(), 10u);
    for (const auto& [key, value] : file->fields()) EXPECT_EQ(reread->field(key), value) << key;
    for (std::size_t k = 0; k < 10; ++k) {
      EXPECT_EQ(reread->image(k), file->image(k));
      EXPECT_EQ(reread->frame_fields(k), file->frame_fields(k));
      const auto tracked = reread->transform("ProbeToTracker", k);
      ASSERT_TRUE(tracked);
      EXPECT_TRUE(tracked->isApprox(acquisition.tracked_poses[k].T_reference_probe.matrix(), 0));
      EXPECT_EQ(reread->transform_status("ProbeToTracker", k), acquisition.tracked_poses[k].status);
      EXPECT_DOUBLE_EQ(*reread->timestamp_s(k), acquisition.frame_times_s[k]);
    }
    // The header alone rebuilds the probe: calibration and sector.
    const auto rebuilt = acquisition::probe_from_fields(reread->fields());
    ASSERT_TRUE(rebuilt) << rebuilt.message();
    EXPECT_EQ(rebuilt->sector_mask(), probe.sector_mask());
    const auto image_to_probe = acquisition::parse_matrix(*reread->field("ImageToProbeTransform"));
    ASSERT_TRUE(image_to_probe);
    EXPECT_TRUE(image_to_probe->isApprox(probe.T_probe_image().matrix(), 1e-15));
  }
  // Ground truth pixels: inside the sector exactly the labels of the exact slice.
  const LabelImage& truth = sweep.truth.image(4);
  std::size_t lesion = 0;
  for (const auto v : truth.pixels) lesion += v == 2 ? 1 : 0;
  EXPECT_GT(lesion, 0u);
}

}  // namespace
}  // namespace sonoshape::simulator::sweep_test
