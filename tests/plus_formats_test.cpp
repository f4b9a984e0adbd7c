// One PLUS recording saved as MetaImage and as NRRD (data/plus/NwirePhantomFreehand.igs.*) must
// segment to the same slice set through `sonoshape segment`; an image-only Slicer sequence is
// refused with a message that says why and what to record instead.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "sonoshape/core/mesh_components.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace plus_formats_test {
namespace {

namespace fs = std::filesystem;

const fs::path kPlus = fs::path(SONOSHAPE_DATA_DIR) / "plus";
// The spine recording's calibration: the same 820x616 PLUS setup (ImageToProbe with ~0.085 mm
// pixels); any calibration serves to compare the two copies.
const fs::path kCalibration = kPlus / "PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml";

sonoshape::testing::CommandResult run(const std::string& arguments, const fs::path& log) {
  return sonoshape::testing::run_command(SONOSHAPE_BINARY, arguments, log);
}

std::string bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(PlusFormats, MhaAndNrrdCopiesSegmentToTheSameSliceSet) {
  sonoshape::testing::TempDir dir;
  // The N-wire phantom: bright wire echoes in anechoic water. The defaults call the water "no
  // signal" and leave every slice unknown, which would compare nothing but the planes; with the
  // wires preset the wires are material regions.
  std::string outputs[2];
  int index = 0;
  for (const char* name : {"NwirePhantomFreehand.igs.mha", "NwirePhantomFreehand.igs.nrrd"}) {
    const fs::path out = dir.path() / (std::string(name) + ".slices.json");
    const auto result =
        run("segment " + (kPlus / name).string() + " --calibration " + kCalibration.string() +
                " --preset wires --every 4 -o " + out.string(),
            dir.path() / (std::string(name) + ".log"));
    ASSERT_EQ(result.exit_code, 0) << name << ":\n" << result.output;
    outputs[index++] = out.string();
  }
  const auto mha = sonoshape::read_slice_set(outputs[0]);
  ASSERT_TRUE(mha) << mha.message();
  const auto nrrd = sonoshape::read_slice_set(outputs[1]);
  ASSERT_TRUE(nrrd) << nrrd.message();
  // 97 frames, every 4th: 25 considered; each that segments gives a slice.
  EXPECT_GE(mha->slices.size(), 20u);
  ASSERT_EQ(mha->slices.size(), nrrd->slices.size());
  std::size_t wires = 0;
  for (const auto& slice : mha->slices)
    for (const auto& region : slice.regions) wires += region.label == 1 ? 1 : 0;
  EXPECT_GE(wires, 20u);  // the comparison covers segmented regions, not only planes
  for (std::size_t s = 0; s < mha->slices.size(); ++s) {
    const auto& a = mha->slices[s];
    const auto& b = nrrd->slices[s];
    EXPECT_EQ(a.origin_mm, b.origin_mm) << "slice " << s;
    EXPECT_EQ(a.u, b.u) << "slice " << s;
    EXPECT_EQ(a.v, b.v) << "slice " << s;
    EXPECT_EQ(a.timestamp_s, b.timestamp_s) << "slice " << s;
    EXPECT_EQ(a.fov, b.fov) << "slice " << s;
    ASSERT_EQ(a.regions.size(), b.regions.size()) << "slice " << s;
    for (std::size_t r = 0; r < a.regions.size(); ++r) {
      EXPECT_EQ(a.regions[r].label, b.regions[r].label);
      EXPECT_EQ(a.regions[r].outer, b.regions[r].outer) << "slice " << s << " region " << r;
      EXPECT_EQ(a.regions[r].holes, b.regions[r].holes) << "slice " << s << " region " << r;
    }
  }
  // And the files themselves, byte for byte.
  EXPECT_EQ(bytes(outputs[0]), bytes(outputs[1]));
}

// The water tank's floor (issue 39: "the water tank's floor one sheet") segmented with its preset
// and reconstructed with the default field is one surface, not one piece per frame: the paper's
// field breaks these six nearly parallel frames of a thin reflector into 22 parts.
TEST(PlusFormats, WaterTankFloorReconstructsAsOneSheet) {
  sonoshape::testing::TempDir dir;
  const fs::path slices = dir.path() / "slices.json";
  const auto segmented =
      run("segment " + (kPlus / "WaterTankBottomTranslationCombined_6frames.igs.mha").string() +
              " --calibration " + (kPlus / "PlusDeviceSet_Server_Sim_NwirePhantom.xml").string() +
              " --preset water-tank -o " + slices.string(),
          dir.path() / "segment.log");
  ASSERT_EQ(segmented.exit_code, 0) << segmented.output;
  const auto reconstructed =
      run("reconstruct " + slices.string() + " -o " + (dir.path() / "recon").string(),
          dir.path() / "reconstruct.log");
  ASSERT_EQ(reconstructed.exit_code, 0) << reconstructed.output;
  const auto floor = sonoshape::read_mesh(dir.path() / "recon" / "label_1.ply");
  ASSERT_TRUE(floor) << floor.message();
  EXPECT_EQ(sonoshape::mesh_parts(*floor).count, 1u);
  // As wide as the frames' floor (about 36 mm across the sweep), not a speck.
  EXPECT_GT(floor->bounds().diagonal(), 30.0);
}

// A NRRD sweep finds its calibration in <name>.plus.xml beside it, as a MetaImage one does.
TEST(PlusFormats, NrrdSweepFindsItsSidecarCalibration) {
  sonoshape::testing::TempDir dir;
  fs::copy_file(kPlus / "NwirePhantomFreehand.igs.nrrd", dir.path() / "sweep.igs.nrrd");
  fs::copy_file(kCalibration, dir.path() / "sweep.plus.xml");
  const auto result = run("segment " + (dir.path() / "sweep.igs.nrrd").string() +
                              " --every 24 -o " + (dir.path() / "s.json").string(),
                          dir.path() / "log");
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("calibration from " + (dir.path() / "sweep.plus.xml").string()),
            std::string::npos)
      << result.output;
}

TEST(PlusFormats, ImageOnlySlicerSequenceIsRefusedWithTheReason) {
  sonoshape::testing::TempDir dir;
  const fs::path path = dir.path() / "us.seq.nrrd";
  {
    std::ofstream out(path, std::ios::binary);
    out << "NRRD0004\n"
           "type: unsigned char\n"
           "dimension: 4\n"
           "space: left-posterior-superior\n"
           "sizes: 64 48 1 3\n"
           "space directions: (0.3,0,0) (0,0,-0.3) (0,0.3,0) none\n"
           "kinds: domain domain domain list\n"
           "labels: \"\" \"\" \"\" \"frame\"\n"
           "endian: little\n"
           "encoding: raw\n"
           "space origin: (0,0,0)\n"
           "DataNodeClassName:=vtkMRMLScalarVolumeNode\n"
           "axis 3 index type:=numeric\n"
           "axis 3 index values:=0 0.1 0.2\n"
           "\n"
        << std::string(64 * 48 * 3, '\x60');
  }
  const auto result = run("segment " + path.string() + " --calibration " + kCalibration.string() +
                              " -o " + (dir.path() / "s.json").string(),
                          dir.path() / "log");
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_NE(result.output.find("image-only sequence (3D Slicer .seq.nrrd)"), std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find(".igs.nrrd"), std::string::npos) << result.output;
  EXPECT_FALSE(fs::exists(dir.path() / "s.json"));
}

// Poses as PLUS names them (issue 39), through the commands.
std::size_t count(const std::string& text, const std::string& part) {
  std::size_t n = 0;
  for (auto at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
  return n;
}

// A nominal calibration (0.2 mm pixels) for the recordings PlusLibData has none for.
fs::path nominal_calibration(const fs::path& dir) {
  const fs::path path = dir / "nominal.json";
  std::ofstream(path) << R"({"ImageToProbe": [0.2,0,0,0, 0,0.2,0,0, 0,0,0.2,0, 0,0,0,1]})";
  return path;
}

// An older PLUS recording: ToolToTracker named by DefaultFrameTransformName, no Timestamp on any
// frame. `segment` and `scan --source replay:` must see the same frames (the replay used to put
// them all at one instant and made 1 slice), and say once that the timing is made up.
TEST(PlusFormats, ToolToTrackerWithoutTimestampsGivesTheSameSlicesThroughSegmentAndReplay) {
  sonoshape::testing::TempDir dir;
  const fs::path sweep = kPlus / "SegmentationTest_VLCUS_RandomStepperMotionData2_6frames.igs.mha";
  const fs::path calibration = nominal_calibration(dir.path());
  const auto segmented = run("segment " + sweep.string() + " --calibration " +
                                 calibration.string() + " -o " + (dir.path() / "s.json").string(),
                             dir.path() / "segment.log");
  ASSERT_EQ(segmented.exit_code, 0) << segmented.output;
  EXPECT_EQ(count(segmented.output, "no frame has a Timestamp"), 1u) << segmented.output;
  EXPECT_NE(segmented.output.find("pose ToolToTracker = ToolToTracker (per frame), chosen by "
                                  "the header's DefaultFrameTransformName"),
            std::string::npos)
      << segmented.output;
  const auto replayed =
      run("scan --source replay:" + sweep.string() + " --calibration " + calibration.string() +
              " --fast --keyframe-angle-deg 0 --keyframe-distance-mm 0 "
              "--depth 4 -o " +
              (dir.path() / "out").string(),
          dir.path() / "scan.log");
  ASSERT_EQ(replayed.exit_code, 0) << replayed.output;
  EXPECT_EQ(count(replayed.output, "no frame has a Timestamp"), 1u) << replayed.output;
  EXPECT_NE(replayed.output.find("pose ToolToTracker = ToolToTracker"), std::string::npos)
      << replayed.output;
  const auto from_segment = sonoshape::read_slice_set(dir.path() / "s.json");
  ASSERT_TRUE(from_segment) << from_segment.message();
  const auto from_replay = sonoshape::read_slice_set(dir.path() / "out" / "slices.json");
  ASSERT_TRUE(from_replay) << from_replay.message();
  EXPECT_GE(from_segment->slices.size(), 4u);
  EXPECT_EQ(from_replay->slices.size(), from_segment->slices.size());
}

const fs::path kStepper = kPlus / "USTC_3NWires_ProbeRotation_3frames.igs.mha";
const fs::path kFrameGrabber = kPlus / "USTC_FrameGrabber_ProbeRotationData_4frames.igs.mha";

// A TRUS stepper recording with its PLUS calibration result: ProbeToTemplate through the
// stepper's home, the calibration read from <ProbeCalibrationResult>.
TEST(PlusFormats, StepperRecordingWithItsCalibrationResultSegments) {
  sonoshape::testing::TempDir dir;
  const fs::path calibration = kPlus / "UsTemplateCalibration_3NWires.results.xml";
  const auto result = run("segment " + kStepper.string() + " --calibration " +
                              calibration.string() + " -o " + (dir.path() / "s.json").string(),
                          dir.path() / "log");
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("pose ProbeToTemplate = TemplateToStepperHome^-1 * "
                               "ProbeToStepperHome (per frame), chosen by default"),
            std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find("calibration from " + calibration.string()), std::string::npos)
      << result.output;
  // Asked for another chain that the file does not have: refused, naming what it has.
  const auto refused =
      run("segment " + kStepper.string() + " --calibration " + calibration.string() +
              " --pose-transform ProbeToTracker -o " + (dir.path() / "t.json").string(),
          dir.path() / "log2");
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.output.find("--pose-transform asks for the pose ProbeToTracker"),
            std::string::npos)
      << refused.output;
  EXPECT_NE(refused.output.find("frames reachable from Probe: StepperEncoderValues, StepperHome, "
                                "Template"),
            std::string::npos)
      << refused.output;
}

// A ProbeToReference recording with MN frames (a TRUS frame grabber): flipped to MF on reading.
TEST(PlusFormats, MnFramesAreFlippedAndProbeToReferenceUsed) {
  sonoshape::testing::TempDir dir;
  const auto result =
      run("segment " + kFrameGrabber.string() + " --calibration " +
              nominal_calibration(dir.path()).string() + " -o " + (dir.path() / "s.json").string(),
          dir.path() / "log");
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("UltrasoundImageOrientation = MN: frames flipped to MF"),
            std::string::npos)
      << result.output;
  EXPECT_NE(result.output.find("pose ProbeToReference = ProbeToReference (per frame)"),
            std::string::npos)
      << result.output;
}

// Presets through `scan --source replay:` (issue 39): with the defaults the N-wire phantom in
// water is nothing but unknown, which the scan says once after its first frames, naming the
// presets; with --preset wires its wires are material regions and nothing is warned.
TEST(PlusFormats, ScanReplayTakesAPresetAndWarnsWhenOneLabelFillsTheSectors) {
  sonoshape::testing::TempDir dir;
  const fs::path sweep = kPlus / "NwirePhantomFreehandCropped.igs.mha";
  const fs::path calibration = kPlus / "PlusDeviceSet_Server_Sim_NwirePhantom.xml";
  const std::string common = "scan --source replay:" + sweep.string() + " --calibration " +
                             calibration.string() +
                             " --fast --keyframe-angle-deg 0 --keyframe-distance-mm 0 --depth 4";
  const auto defaults =
      run(common + " -o " + (dir.path() / "defaults").string(), dir.path() / "defaults.log");
  ASSERT_EQ(defaults.exit_code, 0) << defaults.output;
  EXPECT_EQ(count(defaults.output, "scan: unknown (no signal"), 1u) << defaults.output;
  EXPECT_NE(defaults.output.find("--preset wires"), std::string::npos) << defaults.output;
  const auto wires =
      run(common + " --preset wires -o " + (dir.path() / "wires").string(), dir.path() / "w.log");
  ASSERT_EQ(wires.exit_code, 0) << wires.output;
  EXPECT_NE(wires.output.find("models from config (preset wires)"), std::string::npos)
      << wires.output;
  EXPECT_EQ(count(wires.output, "fills at least"), 0u) << wires.output;
  const auto slices = sonoshape::read_slice_set(dir.path() / "wires" / "slices.json");
  ASSERT_TRUE(slices) << slices.message();
  std::size_t regions = 0;
  for (const auto& slice : slices->slices)
    for (const auto& region : slice.regions) regions += region.label == 1 ? 1 : 0;
  EXPECT_GE(regions, slices->slices.size());
  const auto unknown =
      run(common + " --preset wire -o " + (dir.path() / "x").string(), dir.path() / "x.log");
  EXPECT_NE(unknown.exit_code, 0);
  EXPECT_NE(unknown.output.find("--preset"), std::string::npos) << unknown.output;
}

}  // namespace
}  // namespace plus_formats_test
