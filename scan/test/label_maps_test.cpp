// `scan --labels`: pairing label maps with frames by timestamp (LabelMapMatcher), and
// LabelMapStage giving a frame the slice segmentation::make_slice gives its label map.
#include "sonoshape/scan/label_maps.hpp"

#include <gtest/gtest.h>

#include "sonoshape/segmentation/contours.hpp"

namespace sonoshape::scan::label_maps_test {
namespace {

LabelImage filled(std::uint8_t value) { return LabelImage(8, 6, value); }

TEST(LabelMapMatcher, TakesTheMapOfTheFramesTimeAndForgetsOlderOnes) {
  LabelMapMatcher matcher(1e-3, 4);
  matcher.offer(10.0, filled(1));
  matcher.offer(10.05, filled(2));
  matcher.offer(10.1, filled(3));
  // Frame 10.05 (a keyframe; 10.0 was skipped): its own map, 10.0's dropped on the way.
  const auto second = matcher.take(10.0504);
  ASSERT_TRUE(second);
  EXPECT_EQ(second->pixels[0], 2);
  EXPECT_FALSE(matcher.take(10.0));
  EXPECT_TRUE(matcher.passed(10.07));  // 10.1 is held: 10.07's will not come
  EXPECT_FALSE(matcher.take(10.07));
  EXPECT_FALSE(matcher.passed(10.1));
  EXPECT_EQ(matcher.nearest(10.2), 10.1);
  // Beyond the tolerance is another frame's.
  EXPECT_FALSE(matcher.take(10.0985));
  ASSERT_TRUE(matcher.take(10.1));
  EXPECT_FALSE(matcher.nearest(10.2));
}

TEST(LabelMapMatcher, HoldsAtMostItsCapacityDroppingTheOldest) {
  LabelMapMatcher matcher(1e-3, 2);
  for (int k = 0; k < 5; ++k) matcher.offer(k, filled(static_cast<std::uint8_t>(k)));
  EXPECT_EQ(matcher.nearest(0.0), 3.0);
  EXPECT_TRUE(matcher.take(4.0));
}

// Frame k's label map: a block of label 2 in column k, unknown on the last row.
class FakeFeed final : public LabelMapFeed {
 public:
  Result<LabelImage> label_map(const Frame& frame) override {
    if (frame.index == 3) return Status::error("frame 3 has no label map");
    LabelImage map(8, 6, 0);
    for (int j = 1; j < 4; ++j) map.at(static_cast<int>(frame.index), j) = 2;
    for (int i = 0; i < 8; ++i) map.at(i, 5) = kLabelPixelUnknown;
    return map;
  }
  std::string describe() const override { return "fake"; }
};

TEST(LabelMapStage, GivesEachFrameTheSliceOfItsLabelMapAndNoneWithoutOne) {
  ScanSetup setup;
  setup.geometry = segmentation::full_image_geometry(8, 6, 0.5);
  setup.T_probe_image = Eigen::Vector4d(0.5, 0.5, 1.0, 1.0).asDiagonal();
  setup.segmentation.simplify_mm = 0.0;
  LabelMapStage stage(setup, std::make_unique<FakeFeed>());
  TrackedFrame frame;
  frame.frame.image = GreyImage(8, 6, 100);
  frame.frame.index = 2;
  frame.frame.timestamp_s = 4.5;
  frame.T_reference_probe.translation() = Vec3(0, 0, 7);
  const auto slice = stage.segment(frame);
  ASSERT_TRUE(slice) << slice.message();
  FakeFeed feed;
  const auto plane = segmentation::image_plane(
      frame.T_reference_probe.matrix() * setup.T_probe_image, Vec3(0, 0, 7));
  // The site's map as drawn: its pixels' outlines.
  const auto expected = segmentation::make_slice(
      *feed.label_map(frame.frame), setup.geometry.sector, setup.geometry.sector_px, plane, 0.0,
      nullptr, segmentation::OutlineForm::kPixelEdges);
  ASSERT_TRUE(expected);
  ASSERT_EQ(slice->regions.size(), expected->regions.size());
  for (std::size_t r = 0; r < slice->regions.size(); ++r) {
    EXPECT_EQ(slice->regions[r].label, expected->regions[r].label);
    EXPECT_EQ(slice->regions[r].outer, expected->regions[r].outer);
  }
  EXPECT_EQ(slice->timestamp_s, 4.5);
  EXPECT_EQ(slice->regions.size(), 2u);  // label 2 and the unknown row

  frame.frame.index = 3;
  const auto none = stage.segment(frame);
  ASSERT_FALSE(none);
  EXPECT_NE(none.message().find("frame 3 has no label map"), std::string::npos);
}

}  // namespace
}  // namespace sonoshape::scan::label_maps_test
