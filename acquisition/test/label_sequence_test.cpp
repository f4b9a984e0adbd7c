// A site's own label maps (`--labels`): a 3D Slicer segmentation sequence (.seq.nrrd, written
// here as Slicer lays it out) or a PLUS .mha read for a recording, frame k for frame k, with
// their organ names, the unknown value, and the checks of counts, sizes and times.
#include "sonoshape/acquisition/label_sequence.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include "sonoshape/testing/slicer_labels.hpp"

namespace sonoshape::acquisition::label_sequence_test {
namespace {

constexpr int kW = 40, kH = 30, kFrames = 4;

std::filesystem::path temp_path(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("sonoshape_label_sequence_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir / name;
}

void expect_contains(const std::string& message, const std::string& part) {
  EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
}

std::vector<double> frame_times(double start_s = 100.25) {
  std::vector<double> times;
  for (int k = 0; k < kFrames; ++k) times.push_back(start_s + 0.05 * k);
  return times;
}

// A recording of kFrames grey frames (kW x kH) with those times (none when empty).
SequenceFile recording(const std::vector<double>& times_s, int frames = kFrames) {
  SequenceFile file;
  for (int k = 0; k < frames; ++k) {
    FieldList fields;
    if (!times_s.empty()) fields.push_back({"Timestamp", std::to_string(times_s[k])});
    file.add_frame(GreyImage(kW, kH, static_cast<std::uint8_t>(10 * k)), fields);
  }
  return file;
}

std::vector<LabelImage> maps(int unknown = 255, int frames = kFrames) {
  std::vector<LabelImage> out;
  for (int k = 0; k < frames; ++k)
    out.push_back(
        testing::label_rectangles(kW, kH, testing::fixture_rectangles(k, kW, kH, 3, 7, unknown)));
  return out;
}

TEST(LabelSequence, SlicerSegmentationSequenceGivesTheMapsTheirNamesAndMatchingTimes) {
  const auto path = temp_path("labels.seq.nrrd");
  testing::write_slicer_label_sequence(path, maps(), frame_times(), {{3, "liver"}, {7, "kidney"}});
  const auto read = read_label_sequence(path, recording(frame_times()), "rec.igs.mha");
  ASSERT_TRUE(read) << read.message();
  ASSERT_EQ(read->maps.frame_count(), static_cast<std::size_t>(kFrames));
  const auto expected = maps();
  for (int k = 0; k < kFrames; ++k)
    EXPECT_EQ(read->maps.image(static_cast<std::size_t>(k)), expected[static_cast<std::size_t>(k)])
        << "frame " << k;
  EXPECT_EQ(read->names, (std::map<int, std::string>{{3, "liver"}, {7, "kidney"}}));
  EXPECT_EQ(read->timing, "times agree");
}

TEST(LabelSequence, AnotherUnknownValueBecomesSonoshapesAndA255IsThenRefusedNamingThePixel) {
  const auto path = temp_path("unknown9.seq.nrrd");
  testing::write_slicer_label_sequence(path, maps(9), frame_times(), {{3, "liver"}}, false);
  const auto read = read_label_sequence(path, recording(frame_times()), "rec.igs.mha", 9);
  ASSERT_TRUE(read) << read.message();
  EXPECT_EQ(read->maps.image(0), maps(255)[0]);

  const auto seven = read_label_sequence(path, recording(frame_times()), "rec.igs.mha", 7);
  ASSERT_TRUE(seven);  // no 255 in these maps: 7 is simply taken as unknown
  EXPECT_EQ(seven->maps.image(0).at(kW / 2 + 1, kH / 6 + 1), kLabelPixelUnknown);
  LabelImage with_255 = maps(9)[0];
  with_255.at(5, 2) = 255;
  const Status status = to_label_pixels(with_255, 9, "labels.seq.nrrd, frame 0");
  ASSERT_FALSE(status);
  expect_contains(status.message(), "labels.seq.nrrd, frame 0: pixel (5, 2) is 255");
  expect_contains(status.message(), "--labels-unknown");
}

TEST(LabelSequence, TimesOnAnotherClockOriginAgreeUpToTheirOffset) {
  const auto path = temp_path("offset.seq.nrrd");
  testing::write_slicer_label_sequence(path, maps(), frame_times(0.0), {});
  const auto read = read_label_sequence(path, recording(frame_times()), "rec.igs.mha");
  ASSERT_TRUE(read) << read.message();
  expect_contains(read->timing, "offset of -100.25 s");
  EXPECT_TRUE(read->names.empty());

  const auto untimed = temp_path("untimed.seq.nrrd");
  testing::write_slicer_label_sequence(untimed, maps(), {}, {});
  const auto by_index = read_label_sequence(untimed, recording(frame_times()), "rec.igs.mha");
  ASSERT_TRUE(by_index) << by_index.message();
  expect_contains(by_index->timing, "paired by index only");
}

TEST(LabelSequence, CountsSizesAndTimesThatDisagreeAreRefusedNamingFileFrameAndFix) {
  const auto path = temp_path("three.seq.nrrd");
  testing::write_slicer_label_sequence(path, maps(255, 3), {}, {});
  const auto few = read_label_sequence(path, recording(frame_times()), "rec.igs.mha");
  ASSERT_FALSE(few);
  expect_contains(few.message(), path.string() + " has 3 label maps but rec.igs.mha has 4 frames");
  expect_contains(few.message(), "one label map per frame");

  const auto small = temp_path("small.seq.nrrd");
  std::vector<LabelImage> cropped(kFrames, LabelImage(kW - 2, kH, 0));
  testing::write_slicer_label_sequence(small, cropped, {}, {});
  const auto sized = read_label_sequence(small, recording(frame_times()), "rec.igs.mha");
  ASSERT_FALSE(sized);
  expect_contains(sized.message(), small.string() + ", frame 0: the label map is 38x30 pixels");
  expect_contains(sized.message(), "40x30");

  // Frame 2's label map belongs to another instant: a frame skipped in the export.
  std::vector<double> times = frame_times();
  times[2] += 0.05;
  times[3] += 0.05;
  const auto shifted = temp_path("shifted.seq.nrrd");
  testing::write_slicer_label_sequence(shifted, maps(), times, {});
  const auto timed = read_label_sequence(shifted, recording(frame_times()), "rec.igs.mha");
  ASSERT_FALSE(timed);
  expect_contains(timed.message(), shifted.string() + ", frame 2: the label map is at 100.4 s");
  expect_contains(timed.message(), "frame 2 of rec.igs.mha is at 100.35 s");
}

TEST(LabelSequence, SegmentKeysThatOneLabelMapCannotHoldAreRefusedNamingTheKey) {
  FieldList fields = {{"Segment0_Name", "liver"},
                      {"Segment0_LabelValue", "1"},
                      {"Segment1_Name", "kidney"},
                      {"Segment1_LabelValue", "1"}};
  auto shared = label_names(fields, "seg.seq.nrrd");
  ASSERT_FALSE(shared);
  expect_contains(shared.message(), "Segment1_LabelValue = 1 is also the label value of 'liver'");
  fields[3].second = "300";
  auto wide = label_names(fields, "seg.seq.nrrd");
  ASSERT_FALSE(wide);
  expect_contains(wide.message(), "Segment1_LabelValue = 300");
  fields[3].second = "2";
  fields.push_back({"Segment1_Layer", "1"});
  auto layered = label_names(fields, "seg.seq.nrrd");
  ASSERT_FALSE(layered);
  expect_contains(layered.message(), "another layer");
  // Older Slicer files without label values: segment i has value i + 1.
  auto implied = label_names({{"Segment0_Name", "a"}, {"Segment1_Name", "b"}}, "old.seg.nrrd");
  ASSERT_TRUE(implied) << implied.message();
  EXPECT_EQ(*implied, (std::map<int, std::string>{{1, "a"}, {2, "b"}}));
  auto simulated = label_names({{"SonoshapeLabels", "1:spot 2:cheburashka"}}, "labels.mha");
  ASSERT_TRUE(simulated);
  EXPECT_EQ(simulated->at(2), "cheburashka");
}

TEST(LabelSequence, LabelsOfAnMnRecordingAreFlippedWithItsFrames) {
  SequenceFile rec = recording(frame_times());
  rec.set_field("UltrasoundImageOrientation", "MN");
  const auto path = temp_path("mn.seq.nrrd");
  testing::write_slicer_label_sequence(path, maps(), frame_times(), {});
  const auto read = read_label_sequence(path, rec, "rec.igs.mha");
  ASSERT_TRUE(read) << read.message();
  // MN: rows from the near field; MF stores them from the far one (a vertical flip).
  const LabelImage& flipped = read->maps.image(1);
  const LabelImage original = maps()[1];
  for (int j = 0; j < kH; ++j)
    for (int i = 0; i < kW; ++i)
      ASSERT_EQ(flipped.at(i, j), original.at(i, kH - 1 - j)) << i << "," << j;
}

}  // namespace
}  // namespace sonoshape::acquisition::label_sequence_test
