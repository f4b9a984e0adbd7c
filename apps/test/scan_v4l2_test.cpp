// `--source v4l2:` in the scan: the setup of a grabber source, and the simulator's sweep played
// through an emulated grabber (the MMAP path, driver timestamps) reconstructing as the same sweep
// through `sim:` does.
#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

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

TEST(ScanV4l2, SimulatedSweepThroughAnEmulatedGrabberReconstructsAsThroughSim) {
  // The reference: the sweep as `sim:` delivers it.
  auto reference_source = open_scan_source(small_sim_request());
  ASSERT_TRUE(reference_source) << reference_source.message();
  const Box3 box = *reference_source->setup.bounds;
  auto reference = std::make_shared<FinalMeshes>();
  const ScanSummary expected = run_fast(std::move(*reference_source), reference, 11);
  ASSERT_EQ(expected.counters.frames_received, 11u);

  // The same frames, rendered again (seeded), as a GREY grabber's MMAP buffers stamped with the
  // frames' times; poses and setup as before.
  auto source = open_scan_source(small_sim_request());
  ASSERT_TRUE(source) << source.message();
  acq::SourceOptions drain;
  drain.wait_when_full = true;
  ASSERT_TRUE(source->frames->start(drain));
  auto driver = std::make_shared<testing::FakeV4l2Driver>("/dev/video3", 160, 160);
  driver->offered = {V4L2_PIX_FMT_GREY};
  std::uint32_t sequence = 0;
  while (auto frame = source->frames->next(30.0)) {
    const GreyImage& image = frame->item.image;
    std::vector<std::uint8_t> bytes(160 * 168, 0);  // the fake pads rows to 168 bytes
    for (int j = 0; j < image.height; ++j)
      std::copy_n(image.pixels.begin() + j * image.width, image.width, bytes.begin() + j * 168);
    driver->push(testing::FakeV4l2Driver::Filled{
        std::move(bytes), sequence++, frame->item.timestamp_s, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC});
  }
  ASSERT_EQ(sequence, 11u);
  auto options = acq::parse_v4l2_spec("/dev/video3?format=GREY");
  ASSERT_TRUE(options);
  source->frames = std::make_unique<acq::V4l2FrameSource>(*options, driver);
  auto grabbed = std::make_shared<FinalMeshes>();
  const ScanSummary summary = run_fast(std::move(*source), grabbed, 11);

  EXPECT_EQ(summary.counters.frames_received, 11u);
  EXPECT_EQ(summary.counters.dropped.total(), 0u);
  EXPECT_EQ(summary.counters.slices, expected.counters.slices);
  EXPECT_TRUE(summary.errors.empty()) << summary.errors.front();
  // Every label alike: the same triangle count (none for the rib, hidden in its shadow), and
  // the same volume where there is one.
  ASSERT_EQ(grabbed->final.meshes.size(), reference->final.meshes.size());
  MeshSet seen;
  for (std::size_t k = 0; k < reference->final.meshes.size(); ++k) {
    const auto& want = reference->final.meshes[k];
    const auto& got = grabbed->final.meshes[k];
    EXPECT_EQ(got.label, want.label);
    EXPECT_EQ(got.mesh.triangles.size(), want.mesh.triangles.size()) << "label " << want.label;
    if (!want.mesh.triangles.empty()) seen.meshes.push_back(want);
  }
  ASSERT_GE(seen.meshes.size(), 2u);  // the two organs
  sim::EvaluationOptions evaluation;
  evaluation.grid_resolution = 80;
  evaluation.surface_samples = 2000;
  for (const auto& score : sim::evaluate(grabbed->final, seen, nullptr, box, evaluation))
    EXPECT_GE(score.iou, 0.99) << "label " << score.label;
}

}  // namespace
}  // namespace sonoshape::scan
