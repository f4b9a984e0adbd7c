// Label maps against the truth: exact counts on synthetic maps, and whole simulated sweeps with
// the truth frames as "perfect labels" and with the segmenter.
#include "sonoshape/segmentation/scoring.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "small_sweep.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace sonoshape::segmentation::scoring_test {
namespace {

void fill(LabelImage& image, int i0, int i1, int j0, int j1, std::uint8_t value) {
  for (int j = j0; j < j1; ++j)
    for (int i = i0; i < i1; ++i) image.at(i, j) = value;
}

// 10x10: truth square of label 1 at columns 0-3, ours at columns 2-5 (rows 0-3: 8 px shared);
// the truth's unknown is row 9, ours half of row 9 and half of row 8; pixel (9, 0) is label 2
// in both but outside the sector.
struct SquaresPair {
  LabelImage truth{10, 10, kLabelPixelOutside};
  LabelImage ours{10, 10, kLabelPixelOutside};
  ImageU8 sector{10, 10, 255};
  SquaresPair() {
    fill(truth, 0, 4, 0, 4, 1);
    fill(ours, 2, 6, 0, 4, 1);
    fill(truth, 0, 10, 9, 10, kLabelPixelUnknown);
    fill(ours, 0, 5, 9, 10, kLabelPixelUnknown);
    fill(ours, 0, 5, 8, 9, kLabelPixelUnknown);
    truth.at(9, 0) = ours.at(9, 0) = 2;
    sector.at(9, 0) = 0;
  }
};

TEST(CompareLabels, TwoOverlappingSquaresGiveExactDiceAndUnknownPrecisionRecall) {
  const SquaresPair pair;
  const LabelComparison c = compare_labels(pair.truth, pair.ours, pair.sector);
  EXPECT_EQ(c.sector_px, 99u);
  ASSERT_EQ(c.labels.size(), 2u);  // background and 1; label 2 lies outside the sector
  const PixelCounts& square = c.labels.at(1);
  EXPECT_EQ(square.truth_px, 16u);
  EXPECT_EQ(square.ours_px, 16u);
  EXPECT_EQ(square.both_px, 8u);
  EXPECT_DOUBLE_EQ(square.dice(), 0.5);
  // Background where the truth is known (rows 0-8, less (9, 0)): truth 89 - 16 = 73; ours
  // also loses its unknown half row 8 (5 px): 68; shared: 89 - 24 (the squares) - 5 = 60.
  const PixelCounts& background = c.labels.at(0);
  EXPECT_EQ(background.truth_px, 73u);
  EXPECT_EQ(background.ours_px, 68u);
  EXPECT_EQ(background.both_px, 60u);
  EXPECT_DOUBLE_EQ(background.dice(), 120.0 / 141.0);
  EXPECT_EQ(c.unknown.truth_px, 10u);
  EXPECT_EQ(c.unknown.ours_px, 10u);
  EXPECT_EQ(c.unknown.both_px, 5u);
  EXPECT_DOUBLE_EQ(c.unknown.precision(), 0.5);
  EXPECT_DOUBLE_EQ(c.unknown.recall(), 0.5);
}

TEST(CompareLabels, SweepTotalsAreRatiosOfSummedCountsNotMeansOfRatios) {
  const SquaresPair pair;
  LabelComparison total = compare_labels(pair.truth, pair.ours, pair.sector);
  LabelImage small(10, 10, kLabelPixelOutside);
  fill(small, 0, 2, 0, 2, 1);  // 4 px, identical in both: Dice 1
  const LabelComparison exact = compare_labels(small, small, ImageU8(10, 10, 255));
  EXPECT_DOUBLE_EQ(exact.labels.at(1).dice(), 1.0);
  EXPECT_TRUE(std::isnan(exact.unknown.precision()));  // no unknown pixel in either map
  total.add(exact);
  EXPECT_DOUBLE_EQ(total.labels.at(1).dice(), 2.0 * 12.0 / 40.0);  // 0.6, not (0.5 + 1) / 2
  EXPECT_EQ(total.sector_px, 199u);
  EXPECT_THROW(compare_labels(pair.truth, LabelImage(9, 10, 0), pair.sector),
               std::invalid_argument);
}

TEST(CheckTruthLabels, MismatchedFrameCountsAndSizesNameTheFileFrameAndFix) {
  acquisition::SequenceFile sweep, fewer, smaller;
  for (int k = 0; k < 3; ++k) sweep.add_frame(GreyImage(8, 6, 0));
  fewer.add_frame(LabelImage(8, 6, 0));
  for (int k = 0; k < 3; ++k) smaller.add_frame(LabelImage(8, 5, 0));
  EXPECT_TRUE(check_truth_labels(sweep, "s.igs.mha", sweep, "labels.mha"));
  const Status count = check_truth_labels(sweep, "s.igs.mha", fewer, "truth/labels.mha");
  ASSERT_FALSE(count);
  EXPECT_NE(count.message().find("truth/labels.mha has 1 label frames but s.igs.mha has 3"),
            std::string::npos)
      << count.message();
  EXPECT_NE(count.message().find("simulate --truth"), std::string::npos) << count.message();
  const Status size = check_truth_labels(sweep, "s.igs.mha", smaller, "truth/labels.mha");
  ASSERT_FALSE(size);
  EXPECT_NE(size.message().find("frame 0: the label frame is 8x5 but the frame of s.igs.mha is "
                                "8x6"),
            std::string::npos)
      << size.message();
}

TEST(SegmentSweepLabels, PerfectLabelsScoreOneAndTheSegmenterBelowOne) {
  const simulator::SimulatedSweep sweep = test::organ_and_lesion_sweep(8).sweep;
  const auto setup =
      prepare_sweep(sweep.bmode, "memory.igs.mha", std::optional<SegmentationConfig>{},
                    std::optional<Eigen::Matrix4d>{});
  ASSERT_TRUE(setup) << setup.message();
  const SweepSegmentation perfect =
      segment_sweep(sweep.bmode, *setup, 1, {}, {}, SweepLabels{&sweep.truth, &sweep.truth, {}});
  ASSERT_EQ(perfect.comparisons.size(), perfect.considered - perfect.invalid_pose);
  ASSERT_GE(perfect.comparison_total.labels.size(), 3u);  // background, organ, lesion
  for (const auto& [label, counts] : perfect.comparison_total.labels)
    EXPECT_DOUBLE_EQ(counts.dice(), 1.0) << "label " << label;
  EXPECT_GT(perfect.slices.slices.size(), 0u);
  EXPECT_TRUE(validate_slice_set(perfect.slices, "perfect"));

  const SweepSegmentation ours =
      segment_sweep(sweep.bmode, *setup, 1, {}, {}, SweepLabels{nullptr, &sweep.truth, {}});
  ASSERT_EQ(ours.comparisons.size(), perfect.comparisons.size());
  const double organ = ours.comparison_total.labels.at(1).dice();
  EXPECT_GT(organ, 0.5);  // the segmenter finds the organ, but not to the pixel
  EXPECT_LT(organ, 1.0);

  acquisition::SequenceFile short_truth;
  short_truth.add_frame(sweep.truth.image(0));
  EXPECT_THROW(
      segment_sweep(sweep.bmode, *setup, 1, {}, {}, SweepLabels{&short_truth, nullptr, {}}),
      std::invalid_argument);
}

}  // namespace
}  // namespace sonoshape::segmentation::scoring_test
