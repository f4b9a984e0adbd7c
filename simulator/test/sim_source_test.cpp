// The simulated probe as a frame source: the same frames as simulate_sweep, real-time skipping,
// and a probe that vanishes.
#include "sonoshape/simulator/sim_source.hpp"

#include <gtest/gtest.h>

#include "sonoshape/simulator/sweep.hpp"

namespace sonoshape::simulator::sim_source_test {
namespace {

struct SmallProbe {
  std::shared_ptr<const BModeSimulator> simulator;
  TrajectoryOptions motion;
};

SmallProbe small_setup() {
  Phantom phantom;
  Eigen::Affine3d place = Eigen::Affine3d::Identity();
  place.translation() = Vec3(0, 30, 0);
  phantom.add(1, "organ", make_sphere(15.0, 24, 12), place);
  SmallProbe s;
  s.simulator = std::make_shared<const BModeSimulator>(
      phantom, acquisition::Probe(acquisition::convex_probe_geometry(64, 48)));
  s.motion.duration_s = 0.5;
  s.motion.sweep_length_mm = 20.0;
  return s;
}

TEST(SimFrameSource, FastPlaybackGivesTheFramesOfSimulateSweep) {
  const SmallProbe s = small_setup();
  SimFrameOptions options;
  options.frame_rate_hz = 10.0;
  options.frame_count = 6;
  options.seed = 5;
  SimFrameSource source(s.simulator, Trajectory(s.motion), options);
  acquisition::SourceOptions play;
  play.wait_when_full = true;
  ASSERT_TRUE(source.start(play));
  std::vector<Frame> frames;
  while (auto f = source.next(10.0)) frames.push_back(f->item);
  EXPECT_EQ(source.state(), acquisition::SourceState::kEnded);
  ASSERT_EQ(frames.size(), 6u);

  TrackerOptions tracker;
  const auto acquisition = acquire(Trajectory(s.motion), tracker, 6, 10.0);
  const SimulatedSweep sweep = simulate_sweep(*s.simulator, acquisition, 5);
  for (std::size_t k = 0; k < 6; ++k) {
    EXPECT_EQ(frames[k].index, static_cast<std::int64_t>(k));
    EXPECT_DOUBLE_EQ(frames[k].timestamp_s, acquisition.frame_times_s[k]);
    EXPECT_EQ(frames[k].image, sweep.bmode.image(k)) << k;
  }
}

TEST(SimFrameSource, RealTimeSkipsFramesItCannotRenderInTime) {
  const SmallProbe s = small_setup();
  SimFrameOptions options;
  options.frame_rate_hz = 20000.0;  // far faster than any renderer: most frames are lost
  options.frame_count = 2000;       // 0.1 s of sweep
  SimFrameSource source(s.simulator, Trajectory(s.motion), options);
  acquisition::SourceOptions play;
  play.playback.real_time = true;
  ASSERT_TRUE(source.start(play));
  std::size_t delivered = 0;
  std::int64_t last_index = -1;
  while (auto f = source.next(10.0)) {
    EXPECT_GT(f->item.index, last_index);
    last_index = f->item.index;
    ++delivered;
  }
  EXPECT_EQ(source.state(), acquisition::SourceState::kEnded);
  EXPECT_LT(delivered, 2000u);
  EXPECT_EQ(delivered + source.dropped(), 2000u);  // every frame delivered or counted lost
}

TEST(SimFrameSource, VanishingProbeFailsAfterItsFrames) {
  const SmallProbe s = small_setup();
  SimFrameOptions options;
  options.frame_count = 10;
  options.fail_after_frames = 3;
  SimFrameSource source(s.simulator, Trajectory(s.motion), options);
  ASSERT_TRUE(source.start());
  std::size_t delivered = 0;
  while (source.next(10.0)) ++delivered;
  EXPECT_EQ(delivered, 3u);
  EXPECT_EQ(source.state(), acquisition::SourceState::kFailed);
  EXPECT_NE(source.message().find("probe vanished"), std::string::npos) << source.message();
  EXPECT_THROW(SimFrameSource(nullptr, Trajectory(s.motion), options), std::invalid_argument);
}

}  // namespace
}  // namespace sonoshape::simulator::sim_source_test
