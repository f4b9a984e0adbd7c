// Bring your own labels (issue 39, point 3): `segment --labels` and `scan --source replay:
// --labels` with a site's label maps saved as 3D Slicer saves a segmentation sequence, for a
// simulated recording. The label maps are rectangles that change from frame to frame, so the
// slices must hold exactly those rectangles (area and place, within the contour tracer's
// precision) of the right frame, named as the Slicer header names them; with the simulator's
// truth as the site's labels, `--labels` must give the slices `--perfect-labels` gives.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/simulator/trajectory.hpp"
#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/slicer_labels.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::labels_command_test {
namespace {

using testing::contains;
using testing::TempDir;

constexpr int kFrames = 8;
constexpr int kPx = 160;
constexpr int kLiver = 3, kKidney = 7;

// A 12 mm sphere seen by a 160 px linear probe sliding 8 mm: frames, poses, truth.
simulator::SimulatedSweep simulated_sweep() {
  simulator::Phantom phantom;
  Eigen::Affine3d place = Eigen::Affine3d::Identity();
  place.translation() = Vec3(-5, 25, 0);
  phantom.add(1, "organ", simulator::make_sphere(12.0), place);
  const acquisition::Probe probe(acquisition::linear_probe_geometry(kPx, kPx));
  const simulator::BModeSimulator simulator(phantom, probe);
  simulator::TrajectoryOptions motion;
  motion.duration_s = 0.45;
  motion.sweep_length_mm = 8.0;
  simulator::TrackerOptions tracker;
  tracker.position_noise_mm = 0.0;
  tracker.angle_noise_deg = 0.0;
  tracker.drop_probability = 0.0;
  tracker.invalid_probability = 0.0;
  const auto acquisition =
      simulator::acquire(simulator::Trajectory(motion), tracker, kFrames, 20.0);
  return simulator::simulate_sweep(simulator, acquisition, 3);
}

// The sweep written as a PLUS recording, and the fixture's label maps of its frames.
struct Fixture {
  TempDir dir;
  simulator::SimulatedSweep sweep = simulated_sweep();
  std::filesystem::path recording = dir.path() / "sweep.igs.mha";
  std::filesystem::path config = dir.path() / "exact.json";
  std::vector<double> times_s;
  std::vector<LabelImage> maps;
  double pixel_mm = 0.0;

  Fixture() {
    EXPECT_TRUE(acquisition::write_sequence_file(sweep.bmode, recording));
    // The exact outlines (no simplification) so that areas can be checked to a pixel's edge.
    std::ofstream(config)
        << R"({"format": "sonoshape-segmentation", "version": 1, "simplify_mm": 0})";
    for (std::size_t k = 0; k < sweep.bmode.frame_count(); ++k) {
      times_s.push_back(*sweep.bmode.timestamp_s(k));
      maps.push_back(testing::label_rectangles(
          kPx, kPx,
          testing::fixture_rectangles(static_cast<int>(k), kPx, kPx, kLiver, kKidney, 255)));
    }
    pixel_mm = std::stod(*sweep.bmode.field("SonoshapePixelSpacingMm"));
  }
  std::string run(const std::string& arguments, int* code = nullptr) const {
    const auto result =
        testing::run_command(SONOSHAPE_BINARY, arguments, dir.path() / "command.log");
    if (code) *code = result.exit_code;
    return result.output;
  }
};

// The frame a slice was made from, by its timestamp.
std::size_t frame_of(const LabeledSlice& slice, const std::vector<double>& times_s) {
  const double t_s = slice.timestamp_s.value_or(-1.0);
  std::size_t best = 0;
  for (std::size_t k = 1; k < times_s.size(); ++k)
    if (std::abs(times_s[k] - t_s) < std::abs(times_s[best] - t_s)) best = k;
  EXPECT_NEAR(times_s[best], t_s, 1e-6);
  return best;
}

// Each slice holds its frame's rectangles: per label the rectangle's area, within the tracer's
// precision (the outline runs on the pixel edges or a quarter pixel inside them: at most half a
// pixel times the perimeter), and in its place: each centroid where the rectangle's centre is
// relative to the first organ's (to half a pixel).
void expect_rectangles(const SliceSet& slices, const Fixture& f) {
  ASSERT_FALSE(slices.slices.empty());
  const double px2 = f.pixel_mm * f.pixel_mm;
  for (const LabeledSlice& slice : slices.slices) {
    const std::size_t k = frame_of(slice, f.times_s);
    const auto found = testing::label_shapes(slice);
    const auto rects =
        testing::fixture_rectangles(static_cast<int>(k), kPx, kPx, kLiver, kKidney, 255);
    ASSERT_EQ(found.size(), 3u) << "frame " << k;
    ASSERT_TRUE(found.count(kLiver)) << "frame " << k;
    for (const testing::LabelRect& r : rects) {
      const int label = r.label == 255 ? kUnknownLabel : r.label;
      ASSERT_TRUE(found.count(label)) << "frame " << k << ": no region of label " << label;
      const testing::LabelShape& shape = found.at(label);
      EXPECT_NEAR(shape.area_mm2, r.w * r.h * px2, (r.w + r.h) * px2)
          << "frame " << k << ", label " << label;
      const Vec2 offset_mm = shape.centroid_mm - found.at(kLiver).centroid_mm;
      const Vec2 expected_mm =
          (testing::rect_centre_px(r) - testing::rect_centre_px(rects[0])) * f.pixel_mm;
      EXPECT_LT((offset_mm - expected_mm).norm(), 0.5 * f.pixel_mm)
          << "frame " << k << ", label " << label << ": " << offset_mm.transpose() << " vs "
          << expected_mm.transpose();
    }
  }
}

std::string name_of(const SliceSet& slices, int id) {
  for (const LabelInfo& l : slices.labels)
    if (l.id == id) return l.name;
  return "";
}

TEST(LabelsCommand, SegmentWithASlicerLabelSequenceGivesItsRectanglesNamedByItsSegments) {
  Fixture f;
  const auto labels = f.dir.path() / "labels.seq.nrrd";
  testing::write_slicer_label_sequence(labels, f.maps, f.times_s,
                                       {{kLiver, "liver"}, {kKidney, "kidney"}});
  const auto out = f.dir.path() / "out.slices.json";
  int code = -1;
  const std::string log = f.run("segment " + f.recording.string() + " --labels " + labels.string() +
                                    " --config " + f.config.string() + " -o " + out.string(),
                                &code);
  ASSERT_EQ(code, 0) << log;
  EXPECT_TRUE(contains(log, "times agree"));
  const auto slices = read_slice_set(out);
  ASSERT_TRUE(slices) << slices.message();
  EXPECT_EQ(slices->slices.size(), static_cast<std::size_t>(kFrames));
  EXPECT_EQ(name_of(*slices, kLiver), "liver");
  EXPECT_EQ(name_of(*slices, kKidney), "kidney");
  expect_rectangles(*slices, f);
}

TEST(LabelsCommand, ScanReplayWithTheLabelSequenceGivesTheSameRectangles) {
  Fixture f;
  const auto labels = f.dir.path() / "labels.seq.nrrd";
  testing::write_slicer_label_sequence(labels, f.maps, f.times_s,
                                       {{kLiver, "liver"}, {kKidney, "kidney"}});
  const auto out = f.dir.path() / "scan";
  int code = -1;
  const std::string log =
      f.run("scan --source replay:" + f.recording.string() + " --labels " + labels.string() +
                " --segmentation " + f.config.string() + " --fast --keyframe-distance-mm 0.1 " +
                "--depth 5 --out " + out.string(),
            &code);
  ASSERT_EQ(code, 0) << log;
  EXPECT_TRUE(contains(log, "instead of the segmenter"));
  const auto slices = read_slice_set(out / "slices.json");
  ASSERT_TRUE(slices) << slices.message();
  EXPECT_GE(slices->slices.size(), static_cast<std::size_t>(kFrames / 2)) << log;
  EXPECT_EQ(name_of(*slices, kLiver), "liver");
  expect_rectangles(*slices, f);
}

TEST(LabelsCommand, TheTruthAsASlicerSequenceGivesTheSlicesOfPerfectLabels) {
  Fixture f;
  const auto truth = f.dir.path() / "labels.mha";
  ASSERT_TRUE(acquisition::write_sequence_file(f.sweep.truth, truth));
  std::vector<LabelImage> maps;
  for (std::size_t k = 0; k < f.sweep.truth.frame_count(); ++k)
    maps.push_back(f.sweep.truth.image(k));
  const auto slicer = f.dir.path() / "truth.seq.nrrd";
  testing::write_slicer_label_sequence(slicer, maps, f.times_s, {{1, "organ"}});
  const auto perfect = f.dir.path() / "perfect.slices.json";
  const auto own = f.dir.path() / "own.slices.json";
  int code = -1;
  std::string log = f.run("segment " + f.recording.string() + " --perfect-labels " +
                              truth.string() + " -o " + perfect.string(),
                          &code);
  ASSERT_EQ(code, 0) << log;
  log = f.run(
      "segment " + f.recording.string() + " --labels " + slicer.string() + " -o " + own.string(),
      &code);
  ASSERT_EQ(code, 0) << log;
  const auto a = read_slice_set(perfect);
  const auto b = read_slice_set(own);
  ASSERT_TRUE(a && b);
  ASSERT_EQ(a->slices.size(), b->slices.size());
  for (std::size_t s = 0; s < a->slices.size(); ++s) {
    ASSERT_EQ(a->slices[s].regions.size(), b->slices[s].regions.size()) << "slice " << s;
    for (std::size_t r = 0; r < a->slices[s].regions.size(); ++r) {
      EXPECT_EQ(a->slices[s].regions[r].label, b->slices[s].regions[r].label);
      EXPECT_EQ(a->slices[s].regions[r].outer, b->slices[s].regions[r].outer);
    }
  }
}

TEST(LabelsCommand, LabelMapsThatDoNotFitTheRecordingAreRefusedNamingFileFrameAndFix) {
  Fixture f;
  const auto out = f.dir.path() / "out.slices.json";
  const auto few = f.dir.path() / "few.seq.nrrd";
  std::vector<LabelImage> maps(f.maps.begin(), f.maps.end() - 1);
  testing::write_slicer_label_sequence(few, maps, {}, {});
  int code = -1;
  std::string log =
      f.run("segment " + f.recording.string() + " --labels " + few.string() + " -o " + out.string(),
            &code);
  EXPECT_EQ(code, 1);
  EXPECT_TRUE(contains(
      log, few.string() + " has 7 label maps but " + f.recording.string() + " has 8 frames"));
  EXPECT_FALSE(std::filesystem::exists(out));

  // Another sweep's times: frame 3 on is one frame late.
  std::vector<double> times = f.times_s;
  for (std::size_t k = 3; k < times.size(); ++k) times[k] += 0.05;
  const auto late = f.dir.path() / "late.seq.nrrd";
  testing::write_slicer_label_sequence(late, f.maps, times, {});
  log = f.run(
      "scan --source replay:" + f.recording.string() + " --labels " + late.string() + " --fast",
      &code);
  EXPECT_EQ(code, 1);
  EXPECT_TRUE(contains(log, late.string() + ", frame 3: the label map is at"));

  log = f.run("segment " + f.recording.string() + " --labels " + few.string() +
                  " --method graph-cut -o " + out.string(),
              &code);
  EXPECT_EQ(code, 1);
  EXPECT_TRUE(contains(log, "--labels replaces sonoshape's segmenter, so --method"));
  log = f.run("scan --source sim:default --labels " + few.string(), &code);
  EXPECT_EQ(code, 1);
  EXPECT_TRUE(contains(log, "label maps come from a file beside a recording"));
}

}  // namespace
}  // namespace sonoshape::labels_command_test
