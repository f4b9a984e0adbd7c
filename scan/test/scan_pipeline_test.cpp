// The scan pipeline with fake stages: nothing lost when played fast, bounded queues that drop
// (and count) when the reconstruction falls behind in real time, pose drops by reason, a
// source that vanishes, and a stop request. Frames are tiny and the fake stages instant (or
// deliberately slow), so each test takes well under a second or two.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <mutex>
#include <set>
#include <thread>
#include <utility>

#include "fake_reconstruction.hpp"
#include "sonoshape/apps/file_sink.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/scan/pipeline.hpp"
#include "sonoshape/scan/sink.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::scan::scan_pipeline_test {
namespace {

using namespace std::chrono_literals;

// The next of `count` tiny grey frames, one every `period_ms` from t = 0 (timestamps from integer
// milliseconds, so they equal the pose samples' exactly); `next` counts the frames given.
acquisition::Polled next_fake_frame(Frame& frame, int& next, int count, int period_ms) {
  if (next == count) return acquisition::Polled::kEnd;
  frame.image = GreyImage(8, 8, 100);
  frame.index = next;
  frame.timestamp_s = (next * period_ms) / 1000.0;
  ++next;
  return acquisition::Polled::kItem;
}

// Frames as next_fake_frame gives them, failing or throwing after `fail_after` frames when asked.
class FakeFrames final : public acquisition::FrameBackend {
 public:
  enum class Failure { kNone, kError, kThrow };
  FakeFrames(int count, int period_ms, Failure failure = Failure::kNone, int fail_after = 0)
      : count_(count), period_ms_(period_ms), failure_(failure), fail_after_(fail_after) {}
  std::string describe() const override { return "fake probe"; }

 protected:
  Status open() override { return Status::ok(); }
  Result<acquisition::Polled> poll(Frame& frame) override {
    if (failure_ != Failure::kNone && next_ == fail_after_) {
      if (failure_ == Failure::kThrow) throw std::runtime_error("USB device disconnected");
      return Status::error("fake probe: device vanished");
    }
    return next_fake_frame(frame, next_, count_, period_ms_);
  }
  bool is_playback() const override { return true; }

 private:
  int count_, period_ms_;
  Failure failure_;
  int fail_after_;
  int next_ = 0;
};

// Frames like FakeFrames, but after `unplug_at` frames the device is gone for `gap_s` of wall
// time: the source stays running and says so in condition(), as the V4L2 grabber does.
class UnpluggingFrames final : public acquisition::FrameBackend {
 public:
  UnpluggingFrames(int count, int period_ms, int unplug_at, double gap_s)
      : count_(count), period_ms_(period_ms), unplug_at_(unplug_at), gap_s_(gap_s) {}
  std::string describe() const override { return "fake grabber"; }

 protected:
  Status open() override { return Status::ok(); }
  Result<acquisition::Polled> poll(Frame& frame) override {
    if (next_ == unplug_at_ && !replugged_) {
      if (unplugged_at_s_ < 0.0) {
        unplugged_at_s_ = acquisition::monotonic_s();
        set_condition("/dev/video0 vanished (ENODEV); reopening it when it comes back");
      }
      if (acquisition::monotonic_s() - unplugged_at_s_ < gap_s_) {
        std::this_thread::sleep_for(5ms);
        return acquisition::Polled::kNothing;
      }
      replugged_ = true;
      set_condition("");
    }
    return next_fake_frame(frame, next_, count_, period_ms_);
  }
  bool is_playback() const override { return true; }

 private:
  int count_, period_ms_, unplug_at_;
  double gap_s_;
  double unplugged_at_s_ = -1.0;
  bool replugged_ = false;
  int next_ = 0;
};

// The probe slides along z at `mm_per_s`, sampled every `period_ms` over [first_ms, last_ms].
std::vector<Pose> sliding_poses(double mm_per_s, int first_ms, int last_ms, int period_ms) {
  std::vector<Pose> samples;
  for (int ms = first_ms; ms <= last_ms; ms += period_ms) {
    Pose p;
    p.timestamp_s = ms / 1000.0;
    p.T_reference_probe.translation() = Vec3(0, 0, mm_per_s * p.timestamp_s);
    samples.push_back(p);
  }
  return samples;
}

// The slice of a frame is its image plane (x, y of the probe) with one square region.
// Frames in `repaired` report one dropped region each (as segmentation::make_slice would).
class FakeSegmentation final : public SegmentationStage {
 public:
  explicit FakeSegmentation(std::set<std::int64_t> failing = {},
                            std::set<std::int64_t> repaired = {})
      : failing_(std::move(failing)), repaired_(std::move(repaired)) {}
  std::vector<Repair> take_repairs() override { return std::exchange(repairs_, {}); }
  Result<LabeledSlice> segment(const TrackedFrame& frame) override {
    if (repaired_.count(frame.frame.index))
      repairs_.push_back(Repair{frame.frame.index % 2 ? "invalid_region" : "degenerate_region",
                                "label 1", "dropped: a sliver", 0.25});
    if (failing_.count(frame.frame.index)) return Status::error("nothing found");
    LabeledSlice slice;
    slice.origin_mm = frame.T_reference_probe.translation();
    slice.u = frame.T_reference_probe.linear().col(0);
    slice.v = frame.T_reference_probe.linear().col(1);
    slice.timestamp_s = frame.frame.timestamp_s;
    slice.regions.push_back(Region{1, {Vec2(1, 1), Vec2(4, 1), Vec2(4, 4), Vec2(1, 4)}, {}});
    return slice;
  }

 private:
  std::set<std::int64_t> failing_, repaired_;
  std::vector<Repair> repairs_;
};

// Records what the pipeline sends.
class RecordingSink final : public ScanSink {
 public:
  Status on_slice(const LabeledSlice&, std::size_t index) override {
    slice_indices.push_back(index);
    return Status::ok();
  }
  Status on_meshes(const MeshSet& meshes, const MeshUpdateInfo& info) override {
    ++mesh_updates;
    last_mesh_slices = info.slices;
    last_triangles = meshes.meshes.empty() ? 0 : meshes.meshes[0].mesh.triangles.size();
    return Status::ok();
  }
  Status on_status(const ScanStatus& status) override {
    statuses.push_back(status);
    return Status::ok();
  }
  Status on_finish(const MeshSet& meshes, const SliceSet& slices,
                   const ScanSummary& summary) override {
    ++finishes;
    final_triangles = meshes.meshes.empty() ? 0 : meshes.meshes[0].mesh.triangles.size();
    final_slices = slices.slices.size();
    final_slice_set = slices;
    final_summary = summary;
    return Status::ok();
  }
  std::vector<std::size_t> slice_indices;
  std::size_t mesh_updates = 0, last_mesh_slices = 0, last_triangles = 0;
  std::vector<ScanStatus> statuses;
  int finishes = 0;
  std::size_t final_triangles = 0, final_slices = 0;
  SliceSet final_slice_set;
  ScanSummary final_summary;
};

ScanSetup tiny_setup() {
  ScanSetup setup;
  setup.geometry = segmentation::full_image_geometry(8, 8, 1.0);
  setup.T_probe_image = Eigen::Matrix4d::Identity();  // 1 mm pixels
  return setup;
}

ScanSource fake_source(std::unique_ptr<acquisition::FrameSource> frames, std::vector<Pose> poses) {
  ScanSource source;
  source.frames = std::move(frames);
  source.poses = std::make_unique<tracking::RecordedPoseSource>(std::move(poses), "fake tracker");
  source.setup = tiny_setup();
  return source;
}

ScanOptions fast_options() {
  ScanOptions options;
  options.real_time = false;
  options.drop_when_behind = false;
  options.keyframes = {3.0, 1.0};
  options.sync.max_gap_s = 0.08;
  return options;
}

// Every frame received ends in exactly one place.
void expect_accounted(const ScanCounters& c) {
  EXPECT_EQ(c.frames_received,
            c.keyframes_skipped + c.slices + c.dropped.total() - c.dropped.source);
}

TEST(ScanPipeline, FastPlaybackLosesNothingAndBatchesBehindASlowReconstruction) {
  // 60 frames at 30 fps sliding 18 mm/s: 0.6 mm per frame, 1 mm keyframe distance: every
  // other frame is a keyframe.
  auto reconstruction = std::make_unique<test::FakeReconstruction>(20);
  test::FakeReconstruction* recon = reconstruction.get();
  ScanOptions options = fast_options();
  options.reconstruction_queue = 3;
  ScanPipeline pipeline(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(60, 33),
                                    sliding_poses(18.0 * 33.0 / 33.333, -100, 2100, 25)),
                        std::make_unique<FakeSegmentation>(), std::move(reconstruction), options);
  auto sink = std::make_shared<RecordingSink>();
  pipeline.add_sink(sink);
  ASSERT_TRUE(pipeline.start());
  const ScanSummary summary = pipeline.finish();
  const ScanCounters& c = summary.counters;
  EXPECT_EQ(summary.stop_reason, StopReason::kSourceEnded);
  EXPECT_EQ(c.frames_received, 60u);
  EXPECT_EQ(c.dropped.total(), 0u);
  EXPECT_EQ(c.slices, 30u);
  EXPECT_EQ(c.keyframes_skipped, 30u);
  expect_accounted(c);
  // Sinks: every slice once, in order; the final meshes hold them all.
  ASSERT_EQ(sink->slice_indices.size(), 30u);
  for (std::size_t k = 0; k < 30; ++k) EXPECT_EQ(sink->slice_indices[k], k);
  EXPECT_EQ(sink->finishes, 1);
  EXPECT_EQ(sink->final_triangles, 30u);
  EXPECT_EQ(sink->final_slices, 30u);
  EXPECT_EQ(sink->mesh_updates, c.updates);
  ASSERT_FALSE(sink->statuses.empty());
  EXPECT_EQ(sink->statuses.back().state, ScanState::kIdle);
  // A slow update takes what queued meanwhile, never more than the queue holds (+ the one it
  // waited for), and fewer updates than slices.
  const auto batches = recon->batches();
  EXPECT_LT(batches.size(), 30u);
  EXPECT_LE(*std::max_element(batches.begin(), batches.end()), options.reconstruction_queue + 1);
  EXPECT_EQ(summary.latency.count, 30u);
  EXPECT_GT(summary.latency.max_s, 0.0);
  EXPECT_GE(summary.latency.max_s, summary.latency.p95_s);
  EXPECT_GE(summary.latency.p95_s, summary.latency.p50_s);
  EXPECT_GE(summary.update_ms_median, 15.0);
  EXPECT_TRUE(summary.errors.empty());
  EXPECT_TRUE(summary.labels_without_mesh.empty());
  EXPECT_EQ(pipeline.finish().counters.slices, 30u);  // idempotent
}

// A stage that settles (the thin-plate field's final solve from all the slices): its meshes are
// published once more after the last update and are the finished scan's, and the settle is not
// counted as an update.
TEST(ScanPipeline, SettledMeshesArePublishedLastAndFinishTheScan) {
  ScanPipeline pipeline(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(20, 33),
                                    sliding_poses(18.0, -100, 800, 25)),
                        std::make_unique<FakeSegmentation>(),
                        std::make_unique<test::FakeReconstruction>(0, /*settles=*/true),
                        fast_options());
  auto sink = std::make_shared<RecordingSink>();
  pipeline.add_sink(sink);
  ASSERT_TRUE(pipeline.start());
  const ScanSummary summary = pipeline.finish();
  const std::size_t slices = summary.counters.slices;
  ASSERT_GT(slices, 0u);
  EXPECT_EQ(sink->mesh_updates, summary.counters.updates + 1);
  EXPECT_EQ(sink->last_triangles, 2 * slices);
  EXPECT_EQ(sink->last_mesh_slices, slices);
  EXPECT_EQ(sink->final_triangles, 2 * slices);
}

TEST(ScanPipeline, TheSummarySaysWhyAMaterialOfTheSetupHasNoMesh) {
  ScanSource source = fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(20, 33),
                                  sliding_poses(18.0, -100, 800, 25));
  source.setup.labels = {{1, "organ"}, {2, "lesion"}};  // the segmentation only finds the organ
  ScanPipeline pipeline(std::move(source), std::make_unique<FakeSegmentation>(),
                        std::make_unique<test::FakeReconstruction>(0), fast_options());
  ASSERT_TRUE(pipeline.start());
  const ScanSummary summary = pipeline.finish();
  ASSERT_GT(summary.counters.slices, 0u);
  ASSERT_EQ(summary.labels_without_mesh.size(), 1u);
  EXPECT_NE(summary.labels_without_mesh[0].find("label 2 (lesion): no mesh: no slice holds it"),
            std::string::npos)
      << summary.labels_without_mesh[0];
}

TEST(ScanPipeline, RealTimeDropsAndCountsWhenTheReconstructionFallsBehind) {
  // 150 frames at 200 fps (0.75 s), each a keyframe (5 mm apart), and 80 ms updates: the
  // queues must drop, not grow.
  auto reconstruction = std::make_unique<test::FakeReconstruction>(80);
  test::FakeReconstruction* recon = reconstruction.get();
  ScanOptions options;
  options.real_time = true;
  options.drop_when_behind = true;
  options.keyframes = {3.0, 1.0};
  options.segmentation_queue = 2;
  options.reconstruction_queue = 2;
  ScanPipeline pipeline(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(150, 5),
                                    sliding_poses(1000.0, -100, 1000, 5)),
                        std::make_unique<FakeSegmentation>(), std::move(reconstruction), options);
  auto sink = std::make_shared<RecordingSink>();
  pipeline.add_sink(sink);
  ASSERT_TRUE(pipeline.start());
  const ScanSummary summary = pipeline.finish();
  const ScanCounters& c = summary.counters;
  EXPECT_EQ(c.frames_received + c.dropped.source, 150u);
  EXPECT_GT(c.dropped.segmentation_behind + c.dropped.reconstruction_behind, 0u);
  EXPECT_LT(c.slices, 60u);
  EXPECT_GT(c.slices, 0u);
  expect_accounted(c);
  for (const std::size_t batch : recon->batches())
    EXPECT_LE(batch, options.reconstruction_queue + 1);
  // Dropping keeps the latency bounded: about a couple of updates, not the whole backlog.
  EXPECT_LT(summary.latency.max_s, 1.0);
  EXPECT_EQ(sink->finishes, 1);
}

TEST(ScanPipeline, FramesWithoutAPoseAreDroppedByReason) {
  // Frames every 100 ms from 0 to 1.9 s. Tracker every 50 ms from 0.2 to 1.5 s, INVALID at
  // 0.5 s, samples 1.05-1.15 lost (a 200 ms gap). Each frame moves 10 mm: all are keyframes.
  std::vector<Pose> poses;
  for (const Pose& p : sliding_poses(100.0, 200, 1500, 50)) {
    const int ms = static_cast<int>(std::lround(p.timestamp_s * 1000));
    if (ms > 1000 && ms < 1200) continue;
    poses.push_back(p);
    if (ms == 500) poses.back().status = TrackingStatus::kInvalid;
  }
  ScanPipeline pipeline(
      fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(20, 100), poses),
      std::make_unique<FakeSegmentation>(std::set<std::int64_t>{3}),
      std::make_unique<test::FakeReconstruction>(), fast_options());
  ASSERT_TRUE(pipeline.start());
  const ScanCounters c = pipeline.finish().counters;
  EXPECT_EQ(c.frames_received, 20u);
  EXPECT_EQ(c.dropped.pose_extrapolation, 6u);  // 0, 0.1 (before) and 1.6-1.9 (after)
  EXPECT_EQ(c.dropped.pose_invalid, 1u);        // 0.5
  EXPECT_EQ(c.dropped.pose_gap, 1u);            // 1.1
  EXPECT_EQ(c.dropped.pose_missing, 0u);
  EXPECT_EQ(c.dropped.segmentation_failed, 1u);  // frame 3 (0.3 s) found nothing
  EXPECT_EQ(c.slices, 11u);
  expect_accounted(c);

  // No tracker at all: every frame's pose is missing.
  ScanPipeline blind(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(5, 100), {}),
                     std::make_unique<FakeSegmentation>(),
                     std::make_unique<test::FakeReconstruction>(), fast_options());
  ASSERT_TRUE(blind.start());
  EXPECT_EQ(blind.finish().counters.dropped.pose_missing, 5u);
}

TEST(ScanPipeline, AVanishingSourceIsReportedAndTheMeshesSoFarAreKept) {
  for (const auto failure : {FakeFrames::Failure::kError, FakeFrames::Failure::kThrow}) {
    testing::TempDir dir;
    ScanPipeline pipeline(
        fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(100, 33, failure, 20),
                    sliding_poses(60.0, -100, 4000, 25)),
        std::make_unique<FakeSegmentation>(), std::make_unique<test::FakeReconstruction>(),
        fast_options());
    auto sink = std::make_shared<RecordingSink>();
    pipeline.add_sink(sink);
    pipeline.add_sink(std::make_shared<apps::FileSink>(dir.path() / "out", 5));
    ASSERT_TRUE(pipeline.start());
    const ScanSummary summary = pipeline.finish();
    EXPECT_EQ(summary.stop_reason, StopReason::kSourceFailed);
    EXPECT_EQ(summary.counters.frames_received, 20u);
    EXPECT_EQ(summary.counters.slices, 20u);  // 2 mm per frame: all keyframes
    ASSERT_FALSE(summary.errors.empty());
    const std::string expected =
        failure == FakeFrames::Failure::kThrow ? "USB device disconnected" : "device vanished";
    EXPECT_TRUE(testing::contains(summary.errors.front(), expected));
    EXPECT_TRUE(testing::contains(summary.frame_source, "failed"));
    // The sinks heard it as an error status, and still got the meshes at the end.
    EXPECT_TRUE(std::any_of(sink->statuses.begin(), sink->statuses.end(), [&](const ScanStatus& s) {
      return s.state == ScanState::kError && s.message.find(expected) != std::string::npos;
    }));
    EXPECT_EQ(sink->finishes, 1);
    EXPECT_EQ(sink->final_triangles, 20u);
    EXPECT_TRUE(std::filesystem::exists(dir.path() / "out" / "label_1.ply"));
    EXPECT_TRUE(std::filesystem::exists(dir.path() / "out" / "scan.json"));
    const auto slices = read_slice_set(dir.path() / "out" / "slices.json");
    ASSERT_TRUE(slices) << slices.message();
    EXPECT_EQ(slices->slices.size(), 20u);
  }
}

TEST(ScanPipeline, AnUnpluggedGrabberIsReportedAndTheScanGoesOnWhenItIsBack) {
  ScanPipeline pipeline(
      fake_source(std::make_unique<acquisition::SourceOf<UnpluggingFrames>>(40, 33, 15, 0.3),
                  sliding_poses(60.0, -100, 2000, 25)),
      std::make_unique<FakeSegmentation>(), std::make_unique<test::FakeReconstruction>(),
      fast_options());
  auto sink = std::make_shared<RecordingSink>();
  pipeline.add_sink(sink);
  ASSERT_TRUE(pipeline.start());
  const ScanSummary summary = pipeline.finish();
  EXPECT_EQ(summary.stop_reason, StopReason::kSourceEnded);
  EXPECT_EQ(summary.counters.frames_received, 40u);
  EXPECT_EQ(summary.counters.slices, 40u);
  const auto unplugged =
      std::find_if(sink->statuses.begin(), sink->statuses.end(), [](const ScanStatus& s) {
        return s.state == ScanState::kError &&
               s.message.find("vanished (ENODEV)") != std::string::npos;
      });
  ASSERT_NE(unplugged, sink->statuses.end());
  EXPECT_TRUE(testing::contains(unplugged->message, "the meshes so far are kept"));
  const auto back = std::find_if(unplugged, sink->statuses.end(), [](const ScanStatus& s) {
    return s.state == ScanState::kScanning && s.message.find("is back") != std::string::npos;
  });
  ASSERT_NE(back, sink->statuses.end());
  ASSERT_EQ(summary.errors.size(), 1u);  // the unplug, reported once
  EXPECT_EQ(sink->finishes, 1);
  EXPECT_EQ(sink->final_triangles, 40u);
}

TEST(ScanPipeline, StopRequestFinishesCleanly) {
  ScanOptions options;
  options.real_time = true;
  options.keyframes = {3.0, 1.0};
  ScanPipeline pipeline(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(1000, 10),
                                    sliding_poses(300.0, -100, 11000, 10)),
                        std::make_unique<FakeSegmentation>(),
                        std::make_unique<test::FakeReconstruction>(5), options);
  auto sink = std::make_shared<RecordingSink>();
  pipeline.add_sink(sink);
  ASSERT_TRUE(pipeline.start());
  EXPECT_FALSE(pipeline.wait_for(0.3));  // 10 s of frames: still running
  EXPECT_GT(pipeline.counters().frames_received, 5u);
  pipeline.request_stop();
  EXPECT_TRUE(pipeline.wait_for(5.0));
  const ScanSummary summary = pipeline.finish();
  EXPECT_EQ(summary.stop_reason, StopReason::kStopRequested);
  EXPECT_LT(summary.counters.frames_received, 500u);
  EXPECT_GT(summary.counters.slices, 0u);
  EXPECT_EQ(sink->finishes, 1);
  EXPECT_EQ(sink->final_slices, summary.counters.slices);
  EXPECT_FALSE(pipeline.start());  // one scan per pipeline
}

TEST(ScanPipeline, MaxSlicesAndDurationStopTheScan) {
  ScanOptions options = fast_options();
  options.max_slices = 7;
  ScanPipeline capped(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(100, 33),
                                  sliding_poses(60.0, -100, 4000, 25)),
                      std::make_unique<FakeSegmentation>(),
                      std::make_unique<test::FakeReconstruction>(), options);
  ASSERT_TRUE(capped.start());
  const ScanSummary summary = capped.finish();
  EXPECT_EQ(summary.stop_reason, StopReason::kMaxSlices);
  EXPECT_EQ(summary.counters.slices, 7u);

  ScanOptions timed;
  timed.real_time = true;
  timed.duration_s = 0.2;
  ScanPipeline limited(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(1000, 10),
                                   sliding_poses(60.0, -100, 11000, 10)),
                       std::make_unique<FakeSegmentation>(),
                       std::make_unique<test::FakeReconstruction>(), timed);
  ASSERT_TRUE(limited.start());
  const ScanSummary ended = limited.finish();
  EXPECT_EQ(ended.stop_reason, StopReason::kDuration);
  EXPECT_LT(ended.duration_s, 2.0);
}

TEST(ScanPipeline, PastTheSliceBudgetKeyframesComeAtHalfTheDensity) {
  // 60 frames 1.18 mm apart, keyframe distance 1 mm: every frame is a slice. With a budget of
  // 10, the frames after the tenth slice must lie 2 mm from every slice: every other one.
  const double mm_per_s = 36.0 * 33.0 / 33.333, frame_mm = mm_per_s * 0.033;
  auto scan = [&](std::size_t budget) {
    ScanOptions options = fast_options();
    options.keyframes.slice_budget = budget;
    ScanPipeline pipeline(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(60, 33),
                                      sliding_poses(mm_per_s, -100, 2100, 25)),
                          std::make_unique<FakeSegmentation>(),
                          std::make_unique<test::FakeReconstruction>(), options);
    auto sink = std::make_shared<RecordingSink>();
    pipeline.add_sink(sink);
    EXPECT_TRUE(pipeline.start());
    const ScanSummary summary = pipeline.finish();
    EXPECT_EQ(summary.counters.dropped.total(), 0u);
    return sink;
  };
  EXPECT_EQ(scan(0)->final_slices, 60u);
  const auto budgeted = scan(10);
  ASSERT_EQ(budgeted->final_slices, 35u);  // 10, then frames 11, 13, ..., 59
  const std::vector<LabeledSlice>& slices = budgeted->final_slice_set.slices;
  for (std::size_t k = 1; k < slices.size(); ++k) {
    const double step_mm = slices[k].origin_mm.z() - slices[k - 1].origin_mm.z();
    EXPECT_NEAR(step_mm, k < 10 ? frame_mm : 2.0 * frame_mm, 1e-9) << k;
  }
}

TEST(ScanPipeline, RejectsMissingParts) {
  EXPECT_THROW(ScanPipeline(ScanSource{}, std::make_unique<FakeSegmentation>(),
                            std::make_unique<test::FakeReconstruction>(), ScanOptions{}),
               std::invalid_argument);
  ScanOptions zero;
  zero.segmentation_queue = 0;
  EXPECT_THROW(
      ScanPipeline(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(1, 10), {}),
                   std::make_unique<FakeSegmentation>(),
                   std::make_unique<test::FakeReconstruction>(), zero),
      std::invalid_argument);
}

TEST(ScanPipeline, SegmentationRepairsAreCountedAndListedWithTheirFrame) {
  // Every frame a keyframe (1.2 mm apart); 25 of them report a repair: all are counted by kind,
  // the first 20 listed with their frame index, and scan.json carries them.
  std::set<std::int64_t> repaired;
  for (std::int64_t k = 4; k < 29; ++k) repaired.insert(k);
  ScanPipeline pipeline(fake_source(std::make_unique<acquisition::SourceOf<FakeFrames>>(40, 33),
                                    sliding_poses(36.0 * 33.0 / 33.333, -100, 1500, 25)),
                        std::make_unique<FakeSegmentation>(std::set<std::int64_t>{}, repaired),
                        std::make_unique<test::FakeReconstruction>(), fast_options());
  ASSERT_TRUE(pipeline.start());
  const ScanSummary summary = pipeline.finish();
  EXPECT_EQ(summary.counters.slices, 40u);
  EXPECT_EQ(summary.repairs.total(), 25u);
  EXPECT_EQ(summary.repairs.counts.at("invalid_region"), 12u);
  EXPECT_EQ(summary.repairs.counts.at("degenerate_region"), 13u);
  ASSERT_EQ(summary.repairs.first.size(), RepairReport::kMaxListed);
  EXPECT_EQ(summary.repairs.first.front().frame, 4u);
  EXPECT_EQ(summary.repairs.first.back().frame, 23u);
  const std::string json = summary_json(summary);
  EXPECT_NE(json.find("\"repairs\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"invalid_region\": 12"), std::string::npos) << json;
  EXPECT_NE(json.find("\"frame\": 23"), std::string::npos) << json;
}

TEST(ScanReport, LatencyPercentilesByNearestRank) {
  std::vector<double> samples;
  for (int k = 1; k <= 100; ++k) samples.push_back(0.001 * k);
  const LatencyStats stats = latency_stats(samples);
  EXPECT_EQ(stats.count, 100u);
  EXPECT_DOUBLE_EQ(stats.p50_s, 0.050);
  EXPECT_DOUBLE_EQ(stats.p95_s, 0.095);
  EXPECT_DOUBLE_EQ(stats.max_s, 0.100);
  EXPECT_EQ(latency_stats({}).count, 0u);
  EXPECT_DOUBLE_EQ(latency_stats({0.3}).p95_s, 0.3);
}

}  // namespace
}  // namespace sonoshape::scan::scan_pipeline_test
