// `--source v4l2:` in the scan: the setup of a grabber source, and the simulator's sweep played
// through an emulated grabber (the MMAP path, driver timestamps) reconstructing as the same sweep
// through `sim:` does.
#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "sonoshape/acquisition/v4l2_source.hpp"
#include "sonoshape/scan/sources.hpp"
#include "sonoshape/simulator/evaluation.hpp"
#include "sonoshape/testing/fake_v4l2_driver.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::scan {
namespace {

namespace fs = std::filesystem;

// A grabber's calibration and label models, written where a user would keep them.
struct GrabberFiles {
  testing::TempDir dir;
  fs::path calibration = dir.path() / "calibration.json";
  fs::path segmentation = dir.path() / "probe.seg.json";
  explicit GrabberFiles(const std::string& sector = "\"full\"") {
    std::ofstream(calibration) << R"({"ImageToProbe": [0.2, 0, 0, -30, 0, 0.2, 0, 0,)"
                               << R"( 0, 0, 1, 0, 0, 0, 0, 1]})";
    std::ofstream(segmentation)
        << R"({"format": "sonoshape-segmentation", "version": 1, "labels": [)"
        << R"({"id": 3, "name": "vessel", "grey_mean": 20, "grey_std": 10}], "sector": )" << sector
        << "}";
  }
};

TEST(ScanV4l2, GrabberSourceIsTheCroppedImageWithTheGivenCalibrationAndModels) {
  GrabberFiles files;
  SourceRequest request;
  request.spec = "v4l2:/dev/video9?size=1280x720&format=YUYV&crop=100,50,300,200";
  request.calibration = files.calibration;
  request.segmentation = files.segmentation;
  auto source = open_scan_source(request);  // the device is opened when the scan starts
  ASSERT_TRUE(source) << source.message();
  EXPECT_EQ(source->frames->describe(), "v4l2:/dev/video9");
  EXPECT_FALSE(source->poses);  // the tracker's
  EXPECT_EQ(source->setup.geometry.width_px, 300);
  EXPECT_EQ(source->setup.geometry.height_px, 200);
  EXPECT_NEAR(source->setup.geometry.spacing_mm, 0.2, 1e-12);
  EXPECT_EQ(source->setup.sector_from, "full image");
  ASSERT_EQ(source->setup.labels.size(), 1u);
  EXPECT_EQ(source->setup.labels[0].name, "vessel");
  EXPECT_DOUBLE_EQ(source->setup.T_probe_image(0, 3), -30.0);
}

TEST(ScanV4l2, GrabberSourceSaysWhatItStillNeeds) {
  GrabberFiles files;
  SourceRequest request;
  request.spec = "v4l2:/dev/video0";
  EXPECT_TRUE(testing::contains(open_scan_source(request).message(), "give crop=X,Y,W,H"));
  request.spec = "v4l2:/dev/video0?crop=0,0,64,48";
  EXPECT_TRUE(testing::contains(open_scan_source(request).message(), "needs --calibration"));
  request.calibration = files.calibration;
  EXPECT_TRUE(testing::contains(open_scan_source(request).message(), "needs --segmentation"));
  request.spec = "v4l2:/dev/video0?crop=0,0,64";
  EXPECT_TRUE(testing::contains(open_scan_source(request).message(), "crop=0,0,64"));
  GrabberFiles automatic("\"auto\"");
  request.spec = "v4l2:/dev/video0?crop=0,0,64,48";
  request.segmentation = automatic.segmentation;
  EXPECT_TRUE(testing::contains(open_scan_source(request).message(), "cannot find the sector"));
}

// The small simulated sweep of scan_sources_test: 11 frames of 160x160 at 5 fps.
SourceRequest small_sim_request() {
  SourceRequest request;
  request.spec = "sim:default";
  request.models_dir = fs::path(SONOSHAPE_DATA_DIR) / "models";
  request.sim.width_px = 160;
  request.sim.height_px = 160;
  request.sim.frame_rate_hz = 5.0;
  request.sim_duration_s = 2.0;
  return request;
}

// Keeps the final meshes.
class FinalMeshes final : public ScanSink {
 public:
  Status on_slice(const LabeledSlice&, std::size_t) override { return Status::ok(); }
  Status on_meshes(const MeshSet&, const MeshUpdateInfo&) override { return Status::ok(); }
  Status on_status(const ScanStatus&) override { return Status::ok(); }
  Status on_finish(const MeshSet& meshes, const SliceSet&, const ScanSummary&) override {
    final = meshes;
    return Status::ok();
  }
  MeshSet final;
};

// Runs a scan as fast as it goes; a live source never ends, so the scan is stopped once
// `frames` frames are in (queued work is still finished).
ScanSummary run_fast(ScanSource source, const std::shared_ptr<ScanSink>& sink, std::size_t frames) {
  recon::ReconstructorOptions engine;
  engine.engine.max_depth = 5;
  engine.bounds = source.setup.bounds;
  engine.labels = source.setup.labels;
  ScanOptions options;
  options.real_time = false;
  options.drop_when_behind = false;
  options.sync.tracker_latency_s = source.tracker_latency_s.value_or(0.0);
  auto segmentation = std::make_unique<SegmenterStage>(source.setup);
  ScanPipeline pipeline(std::move(source), std::move(segmentation),
                        make_reconstructor_stage(engine), options);
  pipeline.add_sink(sink);
  EXPECT_TRUE(pipeline.start());
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (pipeline.counters().frames_received < frames &&
         std::chrono::steady_clock::now() < deadline && !pipeline.wait_for(0.01)) {
  }
  pipeline.request_stop();
  return pipeline.finish();
}

// The frames of a simulated source (rendered again: seeded) as a GREY grabber's MMAP buffers,
// stamped with the frames' times; the fake pads each 160-pixel row to 168 bytes.
std::vector<testing::FakeV4l2Driver::Filled> grabbed_frames(acq::FrameSource& frames) {
  acq::SourceOptions drain;
  drain.wait_when_full = true;
  EXPECT_TRUE(frames.start(drain));
  std::vector<testing::FakeV4l2Driver::Filled> buffers;
  while (auto frame = frames.next(30.0)) {
    const GreyImage& image = frame->item.image;
    std::vector<std::uint8_t> bytes(std::size_t(image.height) * 168, 0);
    for (int j = 0; j < image.height; ++j)
      std::copy_n(image.pixels.begin() + j * image.width, image.width, bytes.begin() + j * 168);
    buffers.push_back({std::move(bytes), static_cast<std::uint32_t>(buffers.size()),
                       frame->item.timestamp_s, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC});
  }
  return buffers;
}

// The final meshes of `got` are those of `want`: same labels and triangle counts, IoU >= 0.99
// for every label with a surface.
void expect_same_meshes(const MeshSet& got, const MeshSet& want, const Box3& box) {
  ASSERT_EQ(got.meshes.size(), want.meshes.size());
  MeshSet seen;
  for (std::size_t k = 0; k < want.meshes.size(); ++k) {
    EXPECT_EQ(got.meshes[k].label, want.meshes[k].label);
    EXPECT_EQ(got.meshes[k].mesh.triangles.size(), want.meshes[k].mesh.triangles.size())
        << "label " << want.meshes[k].label;
    if (!want.meshes[k].mesh.triangles.empty()) seen.meshes.push_back(want.meshes[k]);
  }
  ASSERT_GE(seen.meshes.size(), 2u);  // the two organs (the rib hides in its shadow)
  sim::EvaluationOptions evaluation;
  evaluation.grid_resolution = 80;
  evaluation.surface_samples = 2000;
  for (const auto& score : sim::evaluate(got, seen, nullptr, box, evaluation))
    EXPECT_GE(score.iou, 0.99) << "label " << score.label;
}

TEST(ScanV4l2, SimulatedSweepThroughAnEmulatedGrabberReconstructsAsThroughSim) {
  // The reference: the sweep as `sim:` delivers it.
  auto reference_source = open_scan_source(small_sim_request());
  ASSERT_TRUE(reference_source) << reference_source.message();
  const Box3 box = *reference_source->setup.bounds;
  auto reference = std::make_shared<FinalMeshes>();
  const ScanSummary expected = run_fast(std::move(*reference_source), reference, 11);
  ASSERT_EQ(expected.counters.frames_received, 11u);

  // The same frames as a grabber delivers them; poses and setup as before.
  auto source = open_scan_source(small_sim_request());
  ASSERT_TRUE(source) << source.message();
  auto driver = std::make_shared<testing::FakeV4l2Driver>("/dev/video3", 160, 160);
  driver->offered = {V4L2_PIX_FMT_GREY};
  auto buffers = grabbed_frames(*source->frames);
  ASSERT_EQ(buffers.size(), 11u);
  // Beside the sweep's frames, a buffer the driver flags broken (after frame 4) and a frame
  // the driver missed (its number is skipped before frame 8): both lost, counted by reason.
  std::uint32_t sequence = 0;
  for (std::size_t k = 0; k < buffers.size(); ++k) {
    if (k == 5)
      driver->push(testing::FakeV4l2Driver::Filled{
          buffers[0].bytes, sequence++, buffers[4].timestamp_s + 0.1,
          V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC | V4L2_BUF_FLAG_ERROR});
    if (k == 8) ++sequence;
    buffers[k].sequence = sequence++;
    driver->push(std::move(buffers[k]));
  }
  auto options = acq::parse_v4l2_spec("/dev/video3?format=GREY");
  ASSERT_TRUE(options);
  source->frames = std::make_unique<acq::V4l2FrameSource>(*options, driver);
  auto grabbed = std::make_shared<FinalMeshes>();
  const ScanSummary summary = run_fast(std::move(*source), grabbed, 11);

  EXPECT_EQ(summary.counters.frames_received, 11u);
  EXPECT_EQ(summary.counters.dropped.source, 2u);
  EXPECT_EQ(summary.counters.dropped.total(), 2u);
  EXPECT_EQ(summary.frame_source_losses,
            (std::map<std::string, std::size_t>{
                {"driver_dropped", 1}, {"error_frames", 1}, {"undecodable", 0}}));
  EXPECT_TRUE(testing::contains(summary.frame_source, "lost driver_dropped 1, error_frames 1"))
      << summary.frame_source;
  EXPECT_EQ(summary.counters.slices, expected.counters.slices);
  EXPECT_TRUE(summary.errors.empty()) << summary.errors.front();
  expect_same_meshes(grabbed->final, reference->final, box);
}

// Records statuses and the slice count of every mesh update, in order.
class Recorder final : public ScanSink {
 public:
  Status on_slice(const LabeledSlice&, std::size_t) override { return Status::ok(); }
  Status on_meshes(const MeshSet&, const MeshUpdateInfo& info) override {
    std::lock_guard lock(mutex);
    events.push_back("meshes " + std::to_string(info.slices));
    return Status::ok();
  }
  Status on_status(const ScanStatus& status) override {
    std::lock_guard lock(mutex);
    events.push_back(std::string(to_string(status.state)) + " " + status.message);
    return Status::ok();
  }
  Status on_finish(const MeshSet& meshes, const SliceSet&, const ScanSummary&) override {
    final = meshes;
    return Status::ok();
  }
  std::mutex mutex;
  std::vector<std::string> events;
  MeshSet final;
};

TEST(ScanV4l2, GrabberUnpluggedMidScanIsReportedAndTheScanGoesOnWithItsMeshes) {
  auto reference_source = open_scan_source(small_sim_request());
  ASSERT_TRUE(reference_source) << reference_source.message();
  const Box3 box = *reference_source->setup.bounds;
  auto reference = std::make_shared<FinalMeshes>();
  run_fast(std::move(*reference_source), reference, 11);

  auto source = open_scan_source(small_sim_request());
  ASSERT_TRUE(source) << source.message();
  auto driver = std::make_shared<testing::FakeV4l2Driver>("/dev/video3", 160, 160);
  driver->offered = {V4L2_PIX_FMT_GREY};
  auto buffers = grabbed_frames(*source->frames);
  ASSERT_EQ(buffers.size(), 11u);
  for (std::size_t k = 0; k < 6; ++k) driver->push(buffers[k]);
  auto options = acq::parse_v4l2_spec("/dev/video3?format=GREY");
  ASSERT_TRUE(options);
  options->reopen_first_s = 0.01;
  options->reopen_max_s = 0.05;
  auto grabber = std::make_unique<acq::V4l2FrameSource>(*options, driver);
  const acq::V4l2FrameSource* watched = grabber.get();  // owned by the pipeline below
  source->frames = std::move(grabber);

  recon::ReconstructorOptions engine;
  engine.engine.max_depth = 5;
  engine.bounds = source->setup.bounds;
  engine.labels = source->setup.labels;
  ScanOptions scan;
  scan.real_time = false;
  scan.drop_when_behind = false;
  scan.sync.tracker_latency_s = source->tracker_latency_s.value_or(0.0);
  auto segmentation = std::make_unique<SegmenterStage>(source->setup);
  ScanPipeline pipeline(std::move(*source), std::move(segmentation),
                        make_reconstructor_stage(engine), scan);
  auto recorder = std::make_shared<Recorder>();
  pipeline.add_sink(recorder);
  ASSERT_TRUE(pipeline.start());
  const auto wait = [&](auto done) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (!done() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    return done();
  };
  ASSERT_TRUE(wait([&] { return pipeline.counters().updates > 0; }));
  ASSERT_TRUE(wait([&] { return pipeline.counters().frames_received == 6; }));

  driver->set_present(false);  // unplugged mid-sweep
  ASSERT_TRUE(wait([&] { return !watched->condition().empty(); }));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // reopening fails meanwhile
  EXPECT_EQ(pipeline.counters().frames_received, 6u);
  const MeshSet during = pipeline.meshes();  // kept while the grabber is away

  driver->set_present(true);  // back: the rest of the sweep, numbered from 0 again
  for (std::size_t k = 6; k < 11; ++k) {
    buffers[k].sequence = static_cast<std::uint32_t>(k - 6);
    driver->push(buffers[k]);
  }
  ASSERT_TRUE(wait([&] { return pipeline.counters().frames_received == 11; }));
  pipeline.request_stop();
  const ScanSummary summary = pipeline.finish();

  EXPECT_EQ(summary.counters.dropped.total(), 0u);
  EXPECT_EQ(watched->counters().unplugs, 1u);
  EXPECT_EQ(watched->counters().reopens, 1u);
  ASSERT_EQ(summary.errors.size(), 1u);
  EXPECT_TRUE(testing::contains(summary.errors[0], "vanished")) << summary.errors[0];
  EXPECT_FALSE(during.meshes.empty());
  // The sinks heard the unplug, then the return; mesh updates never lost slices.
  std::size_t unplugged = 0, back = 0, last_slices = 0;
  for (std::size_t k = 0; k < recorder->events.size(); ++k) {
    const std::string& e = recorder->events[k];
    if (e.rfind("error frame source v4l2:/dev/video3: /dev/video3 vanished", 0) == 0) unplugged = k;
    if (e.rfind("scanning frame source v4l2:/dev/video3 is back", 0) == 0) back = k;
    if (e.rfind("meshes ", 0) == 0) {
      const std::size_t slices = std::stoul(e.substr(7));
      EXPECT_GE(slices, last_slices) << e;
      last_slices = slices;
    }
  }
  EXPECT_GT(unplugged, 0u);
  EXPECT_GT(back, unplugged);
  expect_same_meshes(recorder->final, reference->final, box);
}

}  // namespace
}  // namespace sonoshape::scan
