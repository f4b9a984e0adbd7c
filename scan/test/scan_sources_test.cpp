// The scan's sources chosen by a string, through the whole pipeline with the real segmenter and
// reconstruction: the real PLUS spine sweep with its poses and calibration, and a simulated
// probe that vanishes mid-scan.
#include "sonoshape/apps/scan_sources.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>

#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/apps/file_sink.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::scan::scan_sources_test {
namespace {

using apps::FileSink;
using apps::open_scan_source;

namespace fs = std::filesystem;

const fs::path kData(SONOSHAPE_DATA_DIR);
const fs::path kPlusSweep = kData / "plus" / "SpinePhantomFreehand.igs.mha";
const fs::path kPlusConfig =
    kData / "plus" / "PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml";

// Collects the slices without reconstructing: the segmentation and geometry of a source checked
// apart from the engine.
class CollectingStage final : public ReconstructionStage {
 public:
  int add_slice(LabeledSlice slice) override {
    SliceSet one;
    one.slices.push_back(slice);
    // The engine's own check of every slice it is given.
    if (const Status valid = validate_slice_set(one, "slice"); !valid)
      throw std::invalid_argument(valid.message());
    slices_.slices.push_back(std::move(slice));
    return static_cast<int>(slices_.slices.size()) - 1;
  }
  recon::UpdateStats update() override { return {}; }
  const MeshSet& meshes() const override { return meshes_; }
  SliceSet slice_set() const override { return slices_; }
  std::size_t slice_count() const override { return slices_.slices.size(); }

 private:
  SliceSet slices_;
  MeshSet meshes_;
};

// Runs a whole scan as fast as it goes (deterministic: nothing is dropped for being late), with
// the real reconstruction (coarse: these tests check the wiring, not the accuracy) or the given
// stage.
ScanSummary run_fast(ScanSource source, const std::shared_ptr<ScanSink>& sink,
                     std::unique_ptr<ReconstructionStage> stage = nullptr,
                     std::unique_ptr<SegmentationStage> segmentation = nullptr) {
  if (!stage) {
    recon::ReconstructorOptions engine;
    engine.engine.max_depth = 5;
    engine.bounds = source.setup.bounds;
    engine.labels = source.setup.labels;
    stage = make_reconstructor_stage(engine);
  }
  ScanOptions options;
  options.real_time = false;
  options.drop_when_behind = false;
  options.sync.tracker_latency_s = source.tracker_latency_s.value_or(0.0);
  if (!segmentation) segmentation = std::make_unique<SegmenterStage>(source.setup);
  ScanPipeline pipeline(std::move(source), std::move(segmentation), std::move(stage), options);
  pipeline.add_sink(sink);
  EXPECT_TRUE(pipeline.start());
  return pipeline.finish();
}

SourceRequest small_sim_request() {
  SourceRequest request;
  request.spec = "sim:default";
  return request;
}

// The simulated sweep of small_sim_request.
apps::SimSourceOptions small_sim() {
  apps::SimSourceOptions sim;
  sim.models_dir = kData / "models";
  // 160 px: the segmenter's smallest comfortable size; 5 fps: few slices, a quick engine.
  sim.scenario.width_px = 160;
  sim.scenario.height_px = 160;
  sim.scenario.frame_rate_hz = 5.0;
  sim.duration_s = 2.0;
  return sim;
}

TEST(ScanSources, UnknownPrefixAndMissingFilesSayWhatToDo) {
  SourceRequest request;
  request.spec = "v4l3:/dev/video0";
  auto source = open_scan_source(request);
  ASSERT_FALSE(source);
  EXPECT_TRUE(testing::contains(source.message(), "sim:PHANTOM_SPEC"));
  request.spec = "replay:/nonexistent/sweep.igs.mha";
  EXPECT_FALSE(open_scan_source(request));
  request.spec = "replay:";
  EXPECT_FALSE(open_scan_source(request));
  EXPECT_EQ(apps::parse_phantom_spec("1:a.obj:liver,2:b.obj"),
            (std::vector<std::string>{"1:a.obj:liver", "2:b.obj"}));
  EXPECT_TRUE(apps::parse_phantom_spec("default").empty());
}

// A kind opens by its prefix with the rest of the spec; the program's registry has every kind
// and says which are playbacks (resumed at the frame after the journal's last).
TEST(ScanSources, RegistryOpensByPrefixAndKnowsThePlaybacks) {
  SourceRegistry registry;
  std::string rest_seen;
  SourceKind fake;
  fake.prefix = "fake";
  fake.usage = "fake:NAME";
  fake.open = [&](const SourceRequest&, const std::string& rest) -> Result<ScanSource> {
    rest_seen = rest;
    return Status::error("fake: opened");
  };
  registry.add(fake);
  SourceRequest request;
  request.spec = "fake:a:b";
  EXPECT_EQ(registry.open(request).message(), "fake: opened");
  EXPECT_EQ(rest_seen, "a:b");
  request.spec = "fak:a";
  EXPECT_TRUE(testing::contains(registry.open(request).message(), "unknown source; use fake:NAME"));
  SourceKind missing;
  missing.prefix = "fake";
  missing.not_built = "built without it";
  registry.add(missing);  // the same prefix: replaces the first
  EXPECT_EQ(registry.kinds().size(), 1u);
  request.spec = "fake:a";
  EXPECT_EQ(registry.open(request).message(), "--source fake: built without it");
  request.labels = "maps.seq.nrrd";  // a kind without label maps refuses them
  EXPECT_TRUE(testing::contains(registry.open(request).message(), "--labels with --source"));

  const SourceRegistry program = apps::scan_sources();
  for (const std::string prefix : {"sim", "replay", "igtl", "v4l2"})
    ASSERT_NE(program.find(prefix + ":x"), nullptr) << prefix;
  EXPECT_TRUE(program.find("sim:default")->playback);
  EXPECT_TRUE(program.find("replay:sweep.igs.mha")->playback);
  EXPECT_FALSE(program.find("igtl:127.0.0.1:18944")->playback);
  EXPECT_FALSE(program.find("v4l2:/dev/video0")->playback);
  EXPECT_TRUE(program.find("v4l2:/dev/video0")->monotonic_clock);
  EXPECT_EQ(program.find("v4l3:/dev/video0"), nullptr);
}

// Opens the real PLUS sweep with its calibration and checks the setup.
ScanSource open_plus_sweep() {
  SourceRequest request;
  request.spec = "replay:" + kPlusSweep.string();
  request.calibration = kPlusConfig;
  auto source = open_scan_source(request);
  EXPECT_TRUE(source) << source.message();
  EXPECT_TRUE(testing::contains(source->setup.calibration_from, "PlusDeviceSet"));
  const double spacing_mm = source->setup.T_probe_image.block<3, 1>(0, 0).norm();
  EXPECT_NEAR(spacing_mm, 0.085, 0.002);
  EXPECT_DOUBLE_EQ(source->device_origin_s, 215.102186);
  return std::move(*source);
}

// Checks a finished replay of the PLUS sweep and the placement of its first slice.
void check_plus_scan(const ScanSummary& summary, const fs::path& out) {
  const ScanCounters& c = summary.counters;
  EXPECT_EQ(summary.stop_reason, StopReason::kSourceEnded) << summary.frame_source;
  EXPECT_EQ(c.frames_received, 21u);
  // Every frame has OK poses: none is dropped for its pose.
  EXPECT_EQ(c.dropped.pose_missing + c.dropped.pose_invalid + c.dropped.pose_gap +
                c.dropped.pose_extrapolation,
            0u);
  EXPECT_EQ(c.dropped.reconstruction_rejected, 0u);
  EXPECT_GT(c.slices, 1u);
  EXPECT_EQ(c.frames_received, c.keyframes_skipped + c.slices + c.dropped.total());
  EXPECT_TRUE(summary.errors.empty()) << summary.errors.front();
  // The slices lie where PLUS puts the images: pixel (0, 0) of frame k is
  // ReferenceToTracker^-1 * ProbeToTracker * ImageToProbe * [0 0 0 1].
  const auto slices = read_slice_set(out / "slices.json");
  ASSERT_TRUE(slices) << slices.message();
  ASSERT_FALSE(slices->slices.empty());
  auto file = acquisition::read_sequence_file(kPlusSweep);
  ASSERT_TRUE(file);
  for (const LabeledSlice& slice : slices->slices) {
    ASSERT_TRUE(slice.timestamp_s);
    std::size_t k = 0;
    while (k < file->frame_count() && file->timestamp_s(k) != slice.timestamp_s) ++k;
    ASSERT_LT(k, file->frame_count());
    const Eigen::Matrix4d image_to_reference = file->transform("ReferenceToTracker", k)->inverse() *
                                               *file->transform("ProbeToTracker", k) *
                                               *acquisition::read_image_to_probe(kPlusConfig);
    for (const Eigen::Vector4d& pixel :
         {Eigen::Vector4d(0, 0, 0, 1), Eigen::Vector4d(819, 615, 0, 1)}) {
      const Vec3 p = (image_to_reference * pixel).head<3>();
      EXPECT_LT(std::abs(slice.normal().dot(p - slice.origin_mm)), 0.05) << k;  // in its plane
    }
  }
  EXPECT_TRUE(fs::exists(out / "scan.json"));
}

TEST(ScanSources, RealPlusSweepReplaysWithItsPosesAndCalibration) {
  testing::TempDir dir;
  const ScanSummary summary = run_fast(open_plus_sweep(), std::make_shared<FileSink>(dir.path()),
                                       std::make_unique<CollectingStage>());
  check_plus_scan(summary, dir.path());
}

// The same with the real engine: the segmented outlines of real frames (near-touching vertices,
// hairline spikes, unknown regions covering most of the sector) once crashed the triangulation
// of the unknown regions. The reconstruction must give a closed manifold surface.
TEST(ScanSources, RealPlusSweepReconstructs) {
  testing::TempDir dir;
  const ScanSummary summary = run_fast(open_plus_sweep(), std::make_shared<FileSink>(dir.path()));
  check_plus_scan(summary, dir.path());
  ASSERT_TRUE(fs::exists(dir.path() / "label_1.ply"));
  const auto mesh = read_mesh(dir.path() / "label_1.ply");
  ASSERT_TRUE(mesh) << mesh.message();
  EXPECT_GT(mesh->triangles.size(), 100u);
  EXPECT_TRUE(check_mesh_health(*mesh).closed_manifold_oriented());
}

// The real engine, updated after every slice it takes (so that the count of updates does not
// depend on how the machine's load batches the slices), behind a counter of the updates and of
// those that rebuilt every cell.
class RebuildCountingStage final : public ReconstructionStage {
 public:
  struct Counts {
    std::size_t updates = 0;
    std::size_t full_rebuilds = 0;
  };
  RebuildCountingStage(std::unique_ptr<ReconstructionStage> engine, Counts* counts)
      : engine_(std::move(engine)), counts_(counts) {}
  int add_slice(LabeledSlice slice) override {
    const int id = engine_->add_slice(std::move(slice));
    count(engine_->update());
    return id;
  }
  // The slices are in the meshes already: the pipeline's update has nothing left to do.
  recon::UpdateStats update() override { return count(engine_->update()); }
  const MeshSet& meshes() const override { return engine_->meshes(); }
  SliceSet slice_set() const override { return engine_->slice_set(); }
  std::size_t slice_count() const override { return engine_->slice_count(); }

 private:
  recon::UpdateStats count(recon::UpdateStats stats) {
    if (stats.slices_added > 0) ++counts_->updates;
    if (stats.full_rebuild) ++counts_->full_rebuilds;
    return stats;
  }
  std::unique_ptr<ReconstructionStage> engine_;
  Counts* counts_;
};

// A replay knows the volume its sectors sweep before the first frame: that box holds every
// frame's sector, so it never grows and the updates after the first stay incremental. Grown
// from the slices, it rebuilt every cell at nearly every update of a real recording (each new
// slice widened it).
TEST(ScanSources, ReplayBoxHoldsEverySectorSoUpdatesStayIncremental) {
  ScanSource source = open_plus_sweep();
  ASSERT_TRUE(source.setup.bounds);
  const Box3 box = *source.setup.bounds;
  auto file = acquisition::read_sequence_file(kPlusSweep);
  ASSERT_TRUE(file);
  const Eigen::Matrix4d image_to_probe = *acquisition::read_image_to_probe(kPlusConfig);
  for (std::size_t k = 0; k < file->frame_count(); ++k) {
    const Eigen::Matrix4d image_to_reference = file->transform("ReferenceToTracker", k)->inverse() *
                                               *file->transform("ProbeToTracker", k) *
                                               image_to_probe;
    for (const Vec2& pixel : source.setup.geometry.sector_px)
      EXPECT_TRUE(box.contains(
          (image_to_reference * Eigen::Vector4d(pixel.x(), pixel.y(), 0, 1)).head<3>()))
          << "frame " << k;
  }
  recon::ReconstructorOptions engine;
  engine.engine.max_depth = 5;
  engine.bounds = source.setup.bounds;
  engine.labels = source.setup.labels;
  RebuildCountingStage::Counts counts;
  testing::TempDir dir;
  run_fast(std::move(source), std::make_shared<FileSink>(dir.path()),
           std::make_unique<RebuildCountingStage>(make_reconstructor_stage(engine), &counts));
  ASSERT_GT(counts.updates, 3u);
  // The first update builds everything; a material first seen later rebuilds once more.
  EXPECT_LE(counts.full_rebuilds, 2u) << "of " << counts.updates << " updates";
}

// The NRRD copy of a PLUS recording replays with the setup of its MetaImage copy; an image-only
// Slicer sequence has no poses to replay and is refused with the reason.
TEST(ScanSources, ReplayReadsPlusNrrdAndRefusesImageOnlySlicerSequences) {
  ScanSetup setups[2];
  double origins_s[2] = {0.0, 0.0};
  int index = 0;
  for (const char* name : {"NwirePhantomFreehand.igs.mha", "NwirePhantomFreehand.igs.nrrd"}) {
    SourceRequest request;
    request.spec = "replay:" + (kData / "plus" / name).string();
    request.calibration = kPlusConfig;
    auto source = open_scan_source(request);
    ASSERT_TRUE(source) << name << ": " << source.message();
    EXPECT_TRUE(testing::contains(source->description, "97 frames of 820x616")) << name;
    origins_s[index] = source->device_origin_s;
    setups[index++] = source->setup;
  }
  EXPECT_EQ(origins_s[0], 345.627957);
  EXPECT_EQ(origins_s[1], origins_s[0]);
  EXPECT_EQ(setups[1].T_probe_image, setups[0].T_probe_image);
  EXPECT_EQ(setups[1].geometry.sector, setups[0].geometry.sector);  // found from the pixels
  EXPECT_EQ(setups[1].geometry.sector_px, setups[0].geometry.sector_px);
  ASSERT_EQ(setups[1].segmentation.materials.size(), setups[0].segmentation.materials.size());
  for (std::size_t m = 0; m < setups[0].segmentation.materials.size(); ++m)  // two-class k-means
    EXPECT_EQ(setups[1].segmentation.materials[m].grey_mean,
              setups[0].segmentation.materials[m].grey_mean);

  testing::TempDir dir;
  const fs::path slicer = dir.path() / "us.seq.nrrd";
  {
    std::ofstream out(slicer, std::ios::binary);
    out << "NRRD0004\ntype: uint8\ndimension: 4\nspace: right-anterior-superior\n"
           "sizes: 32 24 1 2\nspace directions: (0.5,0,0) (0,0.5,0) (0,0,0.5) none\n"
           "kinds: domain domain domain list\nendian: little\nencoding: raw\n"
           "space origin: (1,2,3)\naxis 3 index type:=numeric\naxis 3 index values:=0 0.1\n\n"
        << std::string(32 * 24 * 2, '\x50');
  }
  SourceRequest request;
  request.spec = "replay:" + slicer.string();
  request.calibration = kPlusConfig;
  const auto refused = open_scan_source(request);
  ASSERT_FALSE(refused);
  EXPECT_TRUE(testing::contains(refused.message(), "image-only sequence")) << refused.message();
}

TEST(ScanSources, SimulatedScanReconstructsTheTwoOrgans) {
  auto source = open_scan_source(small_sim_request(), small_sim());
  ASSERT_TRUE(source) << source.message();
  ASSERT_EQ(source->setup.labels.size(), 3u);  // spot, cheburashka, rib
  // The rib, a bone, casts a shadow (its section's edge along it is its surface); the others not.
  for (const LabelInfo& label : source->setup.labels)
    EXPECT_EQ(label.casts_shadow, label.name == "rib") << label.name;
  // Models for the organs (the rib hides in its own shadow: unknown in the ground truth).
  EXPECT_GE(source->setup.segmentation.materials.size(), 2u);
  ASSERT_TRUE(source->setup.bounds);
  testing::TempDir dir;
  auto files = std::make_shared<FileSink>(dir.path());
  const ScanSummary summary = run_fast(std::move(*source), files);
  EXPECT_EQ(summary.stop_reason, StopReason::kSourceEnded);
  EXPECT_EQ(summary.counters.frames_received, 11u);
  EXPECT_EQ(summary.counters.dropped.total(), 0u);
  EXPECT_GT(summary.counters.slices, 5u);
  EXPECT_TRUE(summary.errors.empty()) << summary.errors.front();
  EXPECT_TRUE(fs::exists(dir.path() / "label_1.ply"));
  EXPECT_TRUE(fs::exists(dir.path() / "label_2.ply"));
  // The scan's slice set keeps the labels' shadows for a later reconstruction.
  const auto slices = read_slice_set(dir.path() / "slices.json");
  ASSERT_TRUE(slices) << slices.message();
  ASSERT_EQ(slices->labels.size(), 3u);
  for (const LabelInfo& label : slices->labels)
    EXPECT_EQ(label.casts_shadow, label.name == "rib") << label.name;
}

// Counts the meshes the pipeline hands to the segmentation stage it wraps.
class CountingSegmenter final : public SegmentationStage {
 public:
  explicit CountingSegmenter(ScanSetup setup) : inner_(std::move(setup)) {}
  Result<LabeledSlice> segment(const TrackedFrame& frame) override { return inner_.segment(frame); }
  void on_meshes(const MeshSet& meshes) override {
    inner_.on_meshes(meshes);
    if (!meshes.meshes.empty()) ++*meshes_seen;
  }
  std::optional<segmentation::LabelComparison> scores() const override { return inner_.scores(); }
  SegmenterStage& inner() { return inner_; }
  // Shared: the pipeline owns (and destroys) the stage.
  std::shared_ptr<std::atomic<int>> meshes_seen = std::make_shared<std::atomic<int>>(0);

 private:
  SegmenterStage inner_;
};

TEST(ScanSources, GraphCutScanTakesTheReconstructionAsItsPrior) {
  auto source = open_scan_source(small_sim_request(), small_sim());
  ASSERT_TRUE(source) << source.message();
  source->setup.segmentation.method = segmentation::LabellingMethod::kGraphCut;
  auto segmenter = std::make_unique<CountingSegmenter>(source->setup);
  ASSERT_TRUE(source->truth_of_frame);
  segmenter->inner().score_against(source->truth_of_frame);
  const auto meshes_seen = segmenter->meshes_seen;
  testing::TempDir dir;
  const ScanSummary summary = run_fast(std::move(*source), std::make_shared<FileSink>(dir.path()),
                                       nullptr, std::move(segmenter));
  EXPECT_EQ(summary.counters.dropped.total(), 0u);
  EXPECT_GT(summary.counters.slices, 5u);
  EXPECT_GT(meshes_seen->load(), 0);  // later frames had a prior
  EXPECT_TRUE(fs::exists(dir.path() / "label_1.ply"));
  // Every keyframe was scored against the simulator's truth, and the scores reached scan.json.
  ASSERT_TRUE(summary.segmentation_scores);
  EXPECT_GT(summary.segmentation_scores->labels.at(0).dice(), 0.9);
  EXPECT_GT(summary.segmentation_scores->labels.at(1).dice(), 0.7);
  std::ifstream json(dir.path() / "scan.json");
  const std::string text((std::istreambuf_iterator<char>(json)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(testing::contains(text, "segmentation_scores")) << text;
}

TEST(ScanSources, SimulatedProbeVanishingMidScanKeepsTheMeshesSoFar) {
  apps::SimSourceOptions sim = small_sim();
  sim.fail_after_s = 1.0;  // 5 of 11 frames, then the cable is pulled
  auto source = open_scan_source(small_sim_request(), sim);
  ASSERT_TRUE(source) << source.message();
  testing::TempDir dir;
  auto files = std::make_shared<FileSink>(dir.path());
  const ScanSummary summary = run_fast(std::move(*source), files);
  EXPECT_EQ(summary.stop_reason, StopReason::kSourceFailed);
  EXPECT_EQ(summary.counters.frames_received, 5u);
  ASSERT_FALSE(summary.errors.empty());
  EXPECT_TRUE(testing::contains(summary.errors.front(), "probe vanished"));
  EXPECT_GT(summary.counters.slices, 2u);
  const auto slices = read_slice_set(dir.path() / "slices.json");
  ASSERT_TRUE(slices) << slices.message();
  EXPECT_EQ(slices->slices.size(), summary.counters.slices);
  EXPECT_TRUE(fs::exists(dir.path() / "label_1.ply"));
}

}  // namespace
}  // namespace sonoshape::scan::scan_sources_test
