// `sonoshape simulate` end to end: the built-in demo and a user phantom, written and read back.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/segmentation/config.hpp"
#include "sonoshape/testing/command.hpp"

namespace simulate_command_test {
namespace {

namespace fs = std::filesystem;

sonoshape::testing::CommandResult run(const std::string& arguments, const fs::path& log) {
  return sonoshape::testing::run_command(SONOSHAPE_BINARY, arguments, log);
}

std::string bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

class SimulateCommand : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sonoshape_simulate_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
            std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(SimulateCommand, DefaultPhantomWritesSweepCalibrationAndTruth) {
  const std::string common = "simulate --frames 12 --width-px 160 --height-px 128 --seed 4 ";
  const auto first =
      run(common + "-o " + (dir_ / "a.igs.mha").string() + " --truth " + (dir_ / "truth").string(),
          dir_ / "log1");
  ASSERT_EQ(first.exit_code, 0) << first.output;
  const auto sweep = sonoshape::acquisition::read_sequence_file(dir_ / "a.igs.mha");
  ASSERT_TRUE(sweep) << sweep.message();
  EXPECT_EQ(sweep->frame_count(), 12u);
  EXPECT_EQ(sweep->width(), 160);
  EXPECT_EQ(sweep->height(), 128);
  EXPECT_EQ(sweep->field("SonoshapeLabels"), "1:spot 2:cheburashka 3:rib");
  ASSERT_TRUE(sweep->transform("ProbeToTracker", 11));
  // The sidecar PLUS configuration holds the same calibration as the header.
  const auto image_to_probe = sonoshape::acquisition::read_image_to_probe(dir_ / "a.plus.xml");
  ASSERT_TRUE(image_to_probe) << image_to_probe.message();
  EXPECT_EQ(*image_to_probe,
            *sonoshape::acquisition::parse_matrix(*sweep->field("ImageToProbeTransform")));
  for (const char* name : {"label_1.ply", "label_2.ply", "label_3.ply"})
    EXPECT_TRUE(fs::exists(dir_ / "truth" / name)) << name;
  const auto labels = sonoshape::acquisition::read_sequence_file(dir_ / "truth" / "labels.mha");
  ASSERT_TRUE(labels) << labels.message();
  EXPECT_EQ(labels->frame_count(), 12u);

  // Deterministic for a seed: the same bytes again.
  const auto second = run(common + "-o " + (dir_ / "b.igs.mha").string(), dir_ / "log2");
  ASSERT_EQ(second.exit_code, 0) << second.output;
  EXPECT_EQ(bytes(dir_ / "a.igs.mha"), bytes(dir_ / "b.igs.mha"));
}

TEST_F(SimulateCommand, UserPhantomAndBadArguments) {
  const std::string model = std::string(SONOSHAPE_DATA_DIR) + "/models/spot.obj";
  const auto ok = run("simulate --phantom 1:" + model +
                          ":organ --tissue 1:cyst --probe linear "
                          "--trajectory fan --frames 5 --width-px 96 --height-px 96 --raw -o " +
                          (dir_ / "s.seq.mha").string(),
                      dir_ / "log");
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  const auto sweep = sonoshape::acquisition::read_sequence_file(dir_ / "s.seq.mha");
  ASSERT_TRUE(sweep) << sweep.message();
  EXPECT_EQ(sweep->field("CompressedData"), "False");
  EXPECT_EQ(sweep->field("SonoshapeProbeType"), "linear");
  EXPECT_EQ(sweep->field("SonoshapeTrajectory"), "fan");

  const auto missing =
      run("simulate --phantom 1:/no/such/file.obj -o " + (dir_ / "x.igs.mha").string(),
          dir_ / "log_missing");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("/no/such/file.obj"), std::string::npos) << missing.output;
  const auto bad_tissue =
      run("simulate --tissue 1:granite -o " + (dir_ / "x.igs.mha").string(), dir_ / "log_tissue");
  EXPECT_EQ(bad_tissue.exit_code, 1);
  EXPECT_NE(bad_tissue.output.find("granite"), std::string::npos) << bad_tissue.output;
}

}  // namespace
}  // namespace simulate_command_test

namespace simulate_command_test {
namespace {

// Whether the default phantom's rib is declared in `set` and is its only label that casts a
// shadow (docs/formats/slices.md, casts_shadow).
::testing::AssertionResult only_the_rib_casts_a_shadow(const sonoshape::SliceSet& set) {
  bool rib = false;
  for (const sonoshape::LabelInfo& label : set.labels) {
    if (label.casts_shadow != (label.name == "rib"))
      return ::testing::AssertionFailure()
             << label.name << (label.casts_shadow ? " casts" : " does not cast") << " a shadow";
    rib = rib || label.name == "rib";
  }
  if (!rib) return ::testing::AssertionFailure() << "no label named rib";
  return ::testing::AssertionSuccess();
}

// simulate -> segment -> reconstruct: the offline path from a virtual patient to meshes.
TEST_F(SimulateCommand, SegmentTurnsASimulatedSweepIntoAValidSliceSet) {
  const auto simulated = run("simulate --frames 16 --width-px 256 --height-px 256 --seed 7 -o " +
                                 (dir_ / "s.igs.mha").string(),
                             dir_ / "log_sim");
  ASSERT_EQ(simulated.exit_code, 0) << simulated.output;
  const auto segmented =
      run("segment " + (dir_ / "s.igs.mha").string() + " -o " + (dir_ / "s.slices.json").string(),
          dir_ / "log_seg");
  ASSERT_EQ(segmented.exit_code, 0) << segmented.output;
  // The reader validates every rule of the format (simple polygons, no overlaps, labels).
  const auto slices = sonoshape::read_slice_set(dir_ / "s.slices.json");
  ASSERT_TRUE(slices) << slices.message();
  ASSERT_GE(slices->slices.size(), 12u);  // a few frames may have an INVALID pose
  std::size_t materials = 0, unknowns = 0;
  for (const auto& s : slices->slices) {
    EXPECT_TRUE(s.fov.has_value());  // the image sector
    for (const auto& r : s.regions) (r.label == sonoshape::kUnknownLabel ? unknowns : materials)++;
  }
  EXPECT_GT(materials, 0u);
  EXPECT_GT(unknowns, 0u);  // the rib's shadow
  const auto reconstructed = run("reconstruct " + (dir_ / "s.slices.json").string() +
                                     " --depth 5 -o " + (dir_ / "out").string(),
                                 dir_ / "log_recon");
  ASSERT_EQ(reconstructed.exit_code, 0) << reconstructed.output;
  EXPECT_TRUE(fs::exists(dir_ / "out" / "label_1.ply"));
  // The rib, a bone the segmenter draws to its thickness, is declared to cast a shadow.
  EXPECT_TRUE(only_the_rib_casts_a_shadow(*slices));

  // An organ the models name but the cleaning removes everywhere is reported, with the reason.
  {
    std::ofstream config(dir_ / "big_regions.json");
    config << R"({"format": "sonoshape-segmentation", "version": 1, "min_region_mm2": 5000})";
  }
  const auto lost =
      run("segment " + (dir_ / "s.igs.mha").string() + " --config " +
              (dir_ / "big_regions.json").string() + " -o " + (dir_ / "lost.slices.json").string(),
          dir_ / "log_lost");
  EXPECT_NE(lost.output.find("label 2 (cheburashka) is in no slice: no frame's pixels"),
            std::string::npos)
      << lost.output;
}

// Frames of 96 px and a real PLUS recording (820x616) used to fail with self-intersecting
// polygons; --strict proves nothing had to be dropped.
TEST_F(SimulateCommand, SegmentStrictlyHandlesSmallFramesAndARealRecording) {
  const auto simulated =
      run("simulate --frames 8 --width-px 96 --height-px 96 --probe linear "
          "--seed 3 -o " +
              (dir_ / "small.igs.mha").string(),
          dir_ / "log_sim");
  ASSERT_EQ(simulated.exit_code, 0) << simulated.output;
  const auto small = run("segment " + (dir_ / "small.igs.mha").string() + " --strict -o " +
                             (dir_ / "small.slices.json").string(),
                         dir_ / "log_small");
  ASSERT_EQ(small.exit_code, 0) << small.output;
  EXPECT_NE(small.output.find(" 0 failed, 0 repairs"), std::string::npos) << small.output;
  const auto small_slices = sonoshape::read_slice_set(dir_ / "small.slices.json");
  ASSERT_TRUE(small_slices) << small_slices.message();

  const fs::path plus = fs::path(SONOSHAPE_DATA_DIR) / "plus";
  const auto real =
      run("segment " + (plus / "fCal_Test_Calibration_3NWires.igs.mha").string() +
              " --calibration " + (plus / "PlusDeviceSet_Server_Sim_NwirePhantom.xml").string() +
              " --every 20 --strict -o " + (dir_ / "fcal.slices.json").string(),
          dir_ / "log_fcal");
  ASSERT_EQ(real.exit_code, 0) << real.output;
  const auto real_slices = sonoshape::read_slice_set(dir_ / "fcal.slices.json");
  ASSERT_TRUE(real_slices) << real_slices.message();
  EXPECT_EQ(real_slices->slices.size(), 10u);  // frames 0, 20, ..., 180
}

// --truth-labels scores the segmenter against the simulator's truth frames; --perfect-labels
// puts those frames through the same contours and placement, the upper bound of the sweep.
TEST_F(SimulateCommand, SegmentScoresAgainstTheTruthAndPerfectLabelsReconstruct) {
  const auto simulated =
      run("simulate --frames 8 --width-px 160 --height-px 128 --seed 4 -o " +
              (dir_ / "s.igs.mha").string() + " --truth " + (dir_ / "truth").string(),
          dir_ / "log_sim");
  ASSERT_EQ(simulated.exit_code, 0) << simulated.output;
  const std::string sweep = (dir_ / "s.igs.mha").string();
  const std::string truth = (dir_ / "truth" / "labels.mha").string();
  auto read_json = [](const fs::path& path) { return nlohmann::json::parse(bytes(path)); };

  const auto perfect = run("segment " + sweep + " --perfect-labels " + truth + " --truth-labels " +
                               truth + " --report " + (dir_ / "perfect.json").string() + " -o " +
                               (dir_ / "perfect.slices.json").string(),
                           dir_ / "log_perfect");
  ASSERT_EQ(perfect.exit_code, 0) << perfect.output;
  const auto perfect_report = read_json(dir_ / "perfect.json");
  ASSERT_GE(perfect_report["total"]["labels"].size(), 2u) << perfect_report.dump();
  for (const auto& [label, score] : perfect_report["total"]["labels"].items())
    EXPECT_EQ(score["dice"], 1.0) << "label " << label;
  EXPECT_EQ(perfect_report["total"]["unknown"]["recall"], 1.0);
  const auto reconstructed = run("reconstruct " + (dir_ / "perfect.slices.json").string() +
                                     " --depth 5 -o " + (dir_ / "out").string(),
                                 dir_ / "log_recon");
  ASSERT_EQ(reconstructed.exit_code, 0) << reconstructed.output;
  EXPECT_TRUE(fs::exists(dir_ / "out" / "label_1.ply"));
  // Perfect labels are taken as drawn (interpolated), ...
  const auto perfect_slices = sonoshape::read_slice_set(dir_ / "perfect.slices.json");
  ASSERT_TRUE(perfect_slices) << perfect_slices.message();
  // ... on their pixels' edges: every edge runs along one of the image's axes (the segmenter's
  // own outlines are smoothed).
  std::size_t slanted = 0;
  for (const sonoshape::LabeledSlice& s : perfect_slices->slices) {
    EXPECT_EQ(s.outline_sd_mm, 0.0);
    for (const sonoshape::Region& r : s.regions)
      for (std::size_t k = 0; k < r.outer.size(); ++k) {
        const sonoshape::Vec2 d = r.outer[(k + 1) % r.outer.size()] - r.outer[k];
        slanted += std::min(std::abs(d.x()), std::abs(d.y())) > 1e-6 * d.norm();
      }
  }
  EXPECT_EQ(slanted, 0u);
  // The rib, a bone drawn whole in the truth, is declared to cast a shadow.
  EXPECT_TRUE(only_the_rib_casts_a_shadow(*perfect_slices));

  const auto ours =
      run("segment " + sweep + " --truth-labels " + truth + " --report " +
              (dir_ / "ours.json").string() + " -o " + (dir_ / "ours.slices.json").string(),
          dir_ / "log_ours");
  ASSERT_EQ(ours.exit_code, 0) << ours.output;
  EXPECT_NE(ours.output.find("Dice"), std::string::npos) << ours.output;
  const auto report = read_json(dir_ / "ours.json");
  const auto slices = sonoshape::read_slice_set(dir_ / "ours.slices.json");
  ASSERT_TRUE(slices) << slices.message();
  EXPECT_GE(report["frames"].size(), slices->slices.size());  // every segmented frame
  for (const sonoshape::LabeledSlice& s : slices->slices)
    EXPECT_EQ(s.outline_sd_mm, sonoshape::segmentation::SegmentationConfig{}.outline_sd_mm);
  const double spot = report["total"]["labels"]["1"]["dice"].get<double>();
  EXPECT_GT(spot, 0.0);
  EXPECT_LT(spot, 1.0);

  const auto missing =
      run("segment " + sweep + " --truth-labels " + (dir_ / "nowhere.mha").string() + " -o " +
              (dir_ / "x.slices.json").string(),
          dir_ / "log_missing");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("nowhere.mha: no such file"), std::string::npos) << missing.output;
  const auto other =
      run("simulate --frames 5 --width-px 160 --height-px 128 -o " + (dir_ / "o.igs.mha").string() +
              " --truth " + (dir_ / "other").string(),
          dir_ / "log_other");
  ASSERT_EQ(other.exit_code, 0) << other.output;
  const auto mismatched =
      run("segment " + sweep + " --perfect-labels " + (dir_ / "other" / "labels.mha").string() +
              " -o " + (dir_ / "x.slices.json").string(),
          dir_ / "log_mismatched");
  EXPECT_EQ(mismatched.exit_code, 1);
  EXPECT_NE(mismatched.output.find("has 5 label frames but " + sweep + " has 8 frames"),
            std::string::npos)
      << mismatched.output;
  EXPECT_FALSE(fs::exists(dir_ / "x.slices.json"));

  // --seed names a material of the models in effect and three numbers.
  const auto seeded = run("segment " + sweep +
                              " --method graph-cut --prior none --seed "
                              "1:-8,0.2,0.1 --seed 2:23,11.6,0.1 -o " +
                              (dir_ / "seeded.slices.json").string(),
                          dir_ / "log_seeded");
  EXPECT_EQ(seeded.exit_code, 0) << seeded.output;
  const auto unknown_label =
      run("segment " + sweep + " --seed 9:1,2,3 -o " + (dir_ / "x.slices.json").string(),
          dir_ / "log_seed9");
  EXPECT_EQ(unknown_label.exit_code, 1);
  EXPECT_NE(unknown_label.output.find("--organ-seed '9:1,2,3': label 9 is not among the "
                                      "segmentation's materials (1:spot"),
            std::string::npos)
      << unknown_label.output;
  const auto two_numbers =
      run("segment " + sweep + " --seed 1:1,2 -o " + (dir_ / "x.slices.json").string(),
          dir_ / "log_seed2");
  EXPECT_EQ(two_numbers.exit_code, 1);
  EXPECT_NE(two_numbers.output.find("three finite numbers"), std::string::npos)
      << two_numbers.output;
  EXPECT_FALSE(fs::exists(dir_ / "x.slices.json"));
}

}  // namespace
}  // namespace simulate_command_test
