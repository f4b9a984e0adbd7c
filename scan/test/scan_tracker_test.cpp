// A live scan with the trakSTAR source (through the Bird emulator on a fake USB transport) and
// frames stamped with CLOCK_MONOTONIC, as a V4L2 grabber stamps them: the tracker is unplugged
// mid-scan and plugged back. The scan goes on, frames in the gap are dropped by reason, slices
// resume with the right poses, and the meshes built before the unplug are kept.
#include <gtest/gtest.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>

#include "bird_emulator.hpp"
#include "fake_reconstruction.hpp"
#include "sonoshape/apps/file_sink.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/scan/pipeline.hpp"
#include "sonoshape/scan/sink.hpp"
#include "sonoshape/testing/temp_dir.hpp"
#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::scan::scan_tracker_test {
namespace {

constexpr double kMmPerS = 30.0;  // the probe slides along z
constexpr double kStartZMm = 100.0;

double monotonic_now_s() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// A live probe: `count` tiny frames every `period_s`, stamped with CLOCK_MONOTONIC.
class MonotonicFrames final : public acquisition::FrameBackend {
 public:
  MonotonicFrames(int count, double period_s) : count_(count), period_s_(period_s) {}
  std::string describe() const override { return "monotonic probe"; }

 protected:
  Status open() override {
    next_due_s_ = monotonic_now_s();
    return Status::ok();
  }
  Result<acquisition::Polled> poll(Frame& frame) override {
    if (next_ == count_) return acquisition::Polled::kEnd;
    const double wait_s = next_due_s_ - monotonic_now_s();
    if (wait_s > 0.0) {
      std::this_thread::sleep_for(std::chrono::duration<double>(std::min(wait_s, 0.01)));
      return acquisition::Polled::kNothing;
    }
    frame.image = GreyImage(8, 8, 100);
    frame.index = next_++;
    frame.timestamp_s = monotonic_now_s();
    next_due_s_ += period_s_;
    return acquisition::Polled::kItem;
  }

 private:
  int count_;
  double period_s_;
  int next_ = 0;
  double next_due_s_ = 0.0;
};

// The slice of a frame is its image plane with one square region.
class SquareSegmentation final : public SegmentationStage {
 public:
  Result<LabeledSlice> segment(const TrackedFrame& frame) override {
    LabeledSlice slice;
    slice.origin_mm = frame.T_reference_probe.translation();
    slice.u = frame.T_reference_probe.linear().col(0);
    slice.v = frame.T_reference_probe.linear().col(1);
    slice.timestamp_s = frame.frame.timestamp_s;
    slice.regions.push_back(Region{1, {Vec2(1, 1), Vec2(4, 1), Vec2(4, 4), Vec2(1, 4)}, {}});
    return slice;
  }
};

class FinalMeshes final : public ScanSink {
 public:
  Status on_slice(const LabeledSlice&, std::size_t) override { return Status::ok(); }
  Status on_meshes(const MeshSet&, const MeshUpdateInfo&) override { return Status::ok(); }
  Status on_status(const ScanStatus& status) override {
    statuses.push_back(status);
    return Status::ok();
  }
  Status on_finish(const MeshSet& meshes, const SliceSet& slices, const ScanSummary&) override {
    triangles = meshes.meshes.empty() ? 0 : meshes.meshes[0].mesh.triangles.size();
    final_slices = slices;
    return Status::ok();
  }
  std::size_t triangles = 0;
  SliceSet final_slices;
  std::vector<ScanStatus> statuses;
};

TEST(ScanWithTrakstar, UnplugAndReplugMidScanKeepTheMeshesAndPosesResume) {
  tracking::test::FakeDevice device;
  const double start_s = monotonic_now_s();
  // The probe's pose at the moment the emulator answers a POINT.
  device.emulator.pose_of = [start_s](std::size_t) {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.translation() = Vec3(0, 0, kStartZMm + kMmPerS * (monotonic_now_s() - start_s));
    return t;
  };
  tracking::TrakstarOptions options;
  options.rate_hz = 100.0;
  options.reopen_interval_s = 0.02;
  auto tracker =
      std::make_unique<tracking::TrakstarPoseSource>(options, tracking::test::opener(device));
  tracking::TrakstarPoseSource* tracker_view = tracker.get();

  ScanSource source;
  source.frames =
      std::make_unique<acquisition::SourceOf<MonotonicFrames>>(100, 0.02);  // 2 s at 50 fps
  source.poses = std::move(tracker);
  source.setup.geometry = segmentation::full_image_geometry(8, 8, 1.0);
  source.setup.T_probe_image = Eigen::Matrix4d::Identity();
  ScanOptions scan_options;
  scan_options.drop_when_behind = false;
  scan_options.keyframes = {3.0, 1.0};
  testing::TempDir dir;
  ScanPipeline pipeline(std::move(source), std::make_unique<SquareSegmentation>(),
                        std::make_unique<test::FakeReconstruction>(), scan_options);
  auto final_meshes = std::make_shared<FinalMeshes>();
  pipeline.add_sink(final_meshes);
  pipeline.add_sink(std::make_shared<apps::FileSink>(dir.path() / "out", 5));
  ASSERT_TRUE(pipeline.start());

  std::this_thread::sleep_for(std::chrono::milliseconds(600));
  const double unplugged_s = monotonic_now_s();
  device.plugged = false;
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const double replugged_s = monotonic_now_s();
  device.plugged = true;
  const ScanSummary summary = pipeline.finish();

  EXPECT_EQ(summary.stop_reason, StopReason::kSourceEnded);
  const tracking::TrakstarCounts counts = tracker_view->backend().counts();
  EXPECT_EQ(counts.unplugged, 1u);
  EXPECT_EQ(counts.reopened, 1u);
  // Reported both ways in the scan's status.
  const auto said = [&](ScanState state, const std::string& text) {
    return std::any_of(final_meshes->statuses.begin(), final_meshes->statuses.end(),
                       [&](const ScanStatus& s) {
                         return s.state == state && s.message.find(text) != std::string::npos;
                       });
  };
  EXPECT_TRUE(said(ScanState::kError, "waiting for the tracker to come back"));
  EXPECT_TRUE(said(ScanState::kScanning, "is back; frames get poses again"));
  ASSERT_EQ(summary.errors.size(), 1u);
  EXPECT_NE(summary.errors[0].find("unplugged"), std::string::npos) << summary.errors[0];
  const DropCounts& dropped = summary.counters.dropped;
  EXPECT_GT(dropped.pose_gap + dropped.pose_extrapolation + dropped.pose_missing, 10u);

  std::size_t before = 0, after = 0;
  for (const LabeledSlice& s : final_meshes->final_slices.slices) {
    ASSERT_TRUE(s.timestamp_s);
    const double t_s = *s.timestamp_s;
    // No pose is interpolated across the gap, and every slice has the pose of its time.
    EXPECT_FALSE(t_s > unplugged_s && t_s < replugged_s) << t_s - start_s;
    EXPECT_NEAR(s.origin_mm.z(), kStartZMm + kMmPerS * (t_s - start_s), 1.5);
    before += t_s <= unplugged_s;
    after += t_s >= replugged_s;
  }
  EXPECT_GT(before, 5u);
  EXPECT_GT(after, 5u);
  EXPECT_EQ(final_meshes->final_slices.slices.size(), summary.counters.slices);
  const auto written = read_slice_set(dir.path() / "out" / "slices.json");
  ASSERT_TRUE(written) << written.message();
  EXPECT_EQ(written->slices.size(), summary.counters.slices);
  EXPECT_EQ(final_meshes->triangles, summary.counters.slices);  // nothing lost at the unplug
}

}  // namespace
}  // namespace sonoshape::scan::scan_tracker_test
