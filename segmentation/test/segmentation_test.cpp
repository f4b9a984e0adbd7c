// Segmentation of simulated frames against the simulator's ground truth, and the polygons and
// slices made from it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/segmentation/config.hpp"
#include "sonoshape/segmentation/contours.hpp"
#include "sonoshape/segmentation/segmenter.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/sweep.hpp"

namespace sonoshape::segmentation::segmentation_test {
namespace {

struct Ball {
  Vec3 centre_probe_mm;  // in probe coordinates of the test pose
  double radius_mm;
  int label;
};

// A scene seen by one probe: a dark ball partly behind a rib (bone cylinder along the probe's
// z, which shadows it) and a bright ball, placed in a reference frame turned and moved away
// from the probe's so that every transform matters.
struct Scene {
  acquisition::ProbeGeometry geometry;
  std::vector<Ball> balls;
  Vec3 rib_centre_probe_mm;
  double rib_radius_mm;
  Eigen::Isometry3d T_reference_probe = Eigen::Isometry3d::Identity();
  simulator::Phantom phantom;

  Scene(acquisition::ProbeGeometry g, std::vector<Ball> b, Vec3 rib, double rib_radius)
      : geometry(g), balls(std::move(b)), rib_centre_probe_mm(rib), rib_radius_mm(rib_radius) {
    T_reference_probe.linear() =
        Eigen::AngleAxisd(0.6, Vec3(0.2, 0.9, -0.4).normalized()).toRotationMatrix();
    T_reference_probe.translation() = Vec3(31.0, -12.0, 47.0);
    for (const Ball& ball : balls) {
      Eigen::Affine3d place(T_reference_probe);
      place.translate(ball.centre_probe_mm);
      phantom.add(ball.label, ball.label == 1 ? "dark" : "bright",
                  simulator::make_sphere(ball.radius_mm, 96, 48), place);
    }
    Eigen::Affine3d place(T_reference_probe);
    place.translate(rib_centre_probe_mm);
    phantom.add(3, "rib", simulator::make_cylinder(rib_radius_mm, 200.0), place,
                simulator::tissue_preset("bone"));
  }
  // The probe moved by dz mm along its own z (a neighbouring plane).
  Eigen::Isometry3d pose(double dz_mm) const {
    Eigen::Isometry3d T = T_reference_probe;
    T.translate(Vec3(0.0, 0.0, dz_mm));
    return T;
  }
};

Scene linear_scene() {
  return Scene(acquisition::linear_probe_geometry(256, 256),
               {{Vec3(-6.0, 29.0, 0.0), 10.0, 1}, {Vec3(11.0, 17.0, 0.0), 6.0, 2}},
               Vec3(-9.0, 8.0, 0.0), 2.0);
}

Scene convex_scene() {
  return Scene(acquisition::convex_probe_geometry(256, 256),
               {{Vec3(-12.0, 75.0, 0.0), 22.0, 1}, {Vec3(28.0, 45.0, 0.0), 13.0, 2}},
               Vec3(-10.0, 25.0, 0.0), 4.0);
}

ImageGeometry scene_geometry(const acquisition::Probe& probe) {
  auto geometry = geometry_from_header(acquisition::probe_fields(probe));
  EXPECT_TRUE(geometry) << geometry.message();
  return *geometry;
}

struct Scores {
  std::map<int, double> dice;  // per label value (0 background) over pixels known in both
  std::map<int, double> truth_known_pixels;  // per label: pixels the truth shows (not shadowed)
  double shadow_covered = 1.0;  // share of the truth's shadow the segmentation calls unknown
  double known_lost = 0.0;      // share of the truth's known pixels called unknown
};

Scores score(const LabelImage& truth, const LabelImage& sector_labels, const LabelImage& seg) {
  std::map<int, double> both, in_truth, in_seg;
  double shadow = 0, shadow_unknown = 0, known = 0, known_unknown = 0;
  for (std::size_t p = 0; p < truth.pixels.size(); ++p) {
    const int t = truth.pixels[p], s = seg.pixels[p];
    if (sector_labels.pixels[p] == kLabelPixelUnknown) continue;  // outside the sector
    if (t == kLabelPixelUnknown) {
      ++shadow;
      shadow_unknown += s == kLabelPixelUnknown;
      continue;
    }
    ++known;
    if (s == kLabelPixelUnknown) {
      ++known_unknown;
      continue;
    }
    in_truth[t] += 1;
    in_seg[s] += 1;
    if (s == t) both[t] += 1;
  }
  Scores scores;
  for (const auto& [label, n] : in_truth) {
    scores.dice[label] = 2.0 * both[label] / (n + in_seg[label]);
    scores.truth_known_pixels[label] = n;
  }
  scores.shadow_covered = shadow > 0 ? shadow_unknown / shadow : 1.0;
  scores.known_lost = known > 0 ? known_unknown / known : 0.0;
  return scores;
}

// A small bright organ whose boundary pixels the point-spread function blurred towards the
// background: learnt from its pixels away from the boundary its mean is the tissue's, from all
// of them over a quarter of the way to the background's (which lowered the grey boundary between
// them and made the organ come out too large). A sliver with no interior pixel keeps all of its
// own.
TEST(LearnLabelModels, LearnsFromThePixelsAwayFromOtherLabels) {
  GreyImage image(40, 20, 90);
  LabelImage labels(40, 20, 0);
  for (int j = 0; j < 20; ++j)
    for (int i = 0; i < 20; ++i) {
      const double d = std::hypot(i - 10.0, j - 10.0);
      if (d <= 6.0) labels.at(i, j) = 2;
      // The organ's grey 150 inside, ramping down to the background's over its outer 2 px.
      if (d <= 6.0)
        image.at(i, j) =
            static_cast<std::uint8_t>(d <= 4.0 ? 150.0 : 150.0 - 20.0 * (d - 4.0) - 10.0);
    }
  for (int j = 5; j < 15; ++j) {  // a one-pixel sliver of organ 3
    labels.at(30, j) = 3;
    image.at(30, j) = 120;
  }
  const SegmentationConfig all = learn_label_models(image, labels);
  const SegmentationConfig inside = learn_label_models(image, labels, {}, 2.0);
  auto mean_of = [](const SegmentationConfig& c, int label) {
    for (const LabelModel& m : c.materials)
      if (m.label == label) return m.grey_mean;
    return -1.0;
  };
  EXPECT_NEAR(mean_of(inside, 2), 150.0, 1e-9);
  EXPECT_LT(mean_of(all, 2), 135.0);
  EXPECT_NEAR(mean_of(inside, 3), 120.0, 1e-9);
  EXPECT_NEAR(inside.background.grey_mean, 90.0, 1e-9);
}

// A part of a bright organ smaller than min_region_mm2 (an ear, the end of its body: 16 mm^2
// here against 25) stays when its grey is the organ's own; one of the same size whose grey lies
// just past the boundary between background and organ (a speckle grain misread as tissue) goes,
// and so does a small part of a dark organ, whatever its grey (speckle's nulls make dark blobs),
// and one at the sector's edge (where the smoothing averages fewer speckle cells).
TEST(SegmentFrame, KeepsSmallPartsWithTheOrgansOwnGrey) {
  SegmentationConfig config;
  config.background = {0, "background", 90.0, 10.0};
  config.materials = {{1, "dark", 40.0, 10.0}, {2, "organ", 130.0, 10.0}};
  config.depth_compensation = false;
  const double spacing_mm = 0.5;
  const ImageGeometry geometry = full_image_geometry(100, 100, spacing_mm);
  GreyImage image(100, 100, 90);
  auto disc = [&](double cx, double cy, std::uint8_t grey) {
    for (int j = 0; j < 100; ++j)
      for (int i = 0; i < 100; ++i)
        if (std::hypot(i - cx, j - cy) <= 4.5) image.at(i, j) = grey;
  };
  disc(30.0, 50.0, 130);  // the organ's grey: 16 mm^2
  disc(70.0, 50.0, 116);  // just past the midpoint, 110
  disc(50.0, 20.0, 40);   // the dark organ's grey
  disc(50.0, 95.0, 130);  // the organ's grey at the sector's edge
  const Segmentation seg = segment_frame(image, geometry, config);
  auto label_px = [&](int label, int x0, int x1) {
    int n = 0;
    for (int j = 0; j < 100; ++j)
      for (int i = x0; i < x1; ++i) n += seg.labels.at(i, j) == label;
    return n;
  };
  EXPECT_GT(label_px(2, 0, 45) * spacing_mm * spacing_mm, 12.0);
  EXPECT_EQ(label_px(2, 45, 55), 0);
  EXPECT_EQ(label_px(2, 55, 100), 0);
  EXPECT_EQ(label_px(1, 0, 100), 0);
}

class SegmentSimulated : public ::testing::TestWithParam<bool> {};

TEST_P(SegmentSimulated, MatchesGroundTruthAndTheCut) {
  const bool convex = GetParam();
  const Scene scene = convex ? convex_scene() : linear_scene();
  const acquisition::Probe probe(scene.geometry);
  const simulator::BModeSimulator simulator(scene.phantom, probe);
  const ImageGeometry geometry = scene_geometry(probe);

  // Models learned from a labelled neighbouring frame with other speckle.
  const simulator::SimulatedFrame training = simulator.render(scene.pose(2.0), 11);
  const SegmentationConfig config = learn_label_models(training.bmode, training.visible_truth());
  ASSERT_EQ(config.materials.size(), 3u);
  ASSERT_TRUE(config.validate());

  const simulator::SimulatedFrame frame = simulator.render(scene.pose(0.0), 5);
  ASSERT_GT(frame.shadow_fraction, 0.01);  // the rib shadows part of the image
  const Segmentation seg = segment_frame(frame.bmode, geometry, config);
  const Scores s = score(frame.visible_truth(), frame.labels, seg.labels);
  for (const auto& [label, dice] : s.dice)
    std::cout << (convex ? "convex" : "linear") << " label " << label << " Dice " << dice << '\n';
  std::cout << "shadow covered " << s.shadow_covered << ", known lost " << s.known_lost
            << ", depth slope " << seg.depth_slope_grey_per_mm << " grey/mm\n";
  // Every label the truth shows over at least the segmenter's smallest region is scored. The rib
  // (label 3) shows only the sub-millimetre crescent of its top surface: its inside lies in its
  // own shadow, which is unknown, as a careful segmenter must call it.
  const double pixel_mm2 = geometry.spacing_mm * geometry.spacing_mm;
  int scored = 0;
  for (const auto& [label, dice] : s.dice) {
    const double visible_mm2 = s.truth_known_pixels.at(label) * pixel_mm2;
    if (visible_mm2 < config.min_region_mm2) {
      std::cout << "label " << label << " not scored: " << visible_mm2 << " mm2 visible, below "
                << config.min_region_mm2 << " mm2\n";
      continue;
    }
    EXPECT_GE(dice, 0.9) << "label " << label << " (" << visible_mm2 << " mm2 visible)";
    ++scored;
  }
  EXPECT_GE(scored, 3);  // background and both balls
  EXPECT_GE(s.shadow_covered, 0.9);
  EXPECT_LE(s.known_lost, 0.1);

  // Polygons: a valid slice in the reference frame whose contours lie on the balls.
  const ImagePlane plane =
      image_plane(scene.T_reference_probe.matrix() * probe.T_probe_image().matrix(),
                  scene.T_reference_probe.translation());
  const auto slice = make_slice(seg.labels, geometry.sector, geometry.sector_px, plane, 0.3);
  ASSERT_TRUE(slice) << slice.message();
  SliceSet set;
  set.labels = {{1, "dark"}, {2, "bright"}, {3, "rib"}};
  set.slices.push_back(*slice);
  EXPECT_TRUE(validate_slice_set(set, "test")) << validate_slice_set(set, "test").message();
  ASSERT_TRUE(slice->fov);
  EXPECT_NEAR(std::abs(signed_area(*slice->fov)), std::abs(signed_area(probe.sector_ring_mm())),
              0.01 * std::abs(signed_area(probe.sector_ring_mm())));
  bool has_unknown = false;
  for (const Region& r : slice->regions) has_unknown |= r.label == kUnknownLabel;
  EXPECT_TRUE(has_unknown);

  // Round trip: pixel -> plane -> world lands on the analytic spheres, away from unknown.
  const Eigen::Matrix2d linear = plane.pixel_to_plane.leftCols<2>();
  const Eigen::Matrix2d to_pixel = linear.inverse();
  const int keep_off_px = static_cast<int>(std::ceil(1.5 / geometry.spacing_mm)) + 1;
  std::vector<double> errors;
  for (const Region& r : slice->regions) {
    if (r.label != 1 && r.label != 2) continue;
    const Ball& ball = *std::find_if(scene.balls.begin(), scene.balls.end(),
                                     [&](const Ball& b) { return b.label == r.label; });
    const Vec3 centre = scene.T_reference_probe * ball.centre_probe_mm;
    for (const Vec2& p : r.outer) {
      const Vec2 px = to_pixel * (p - plane.pixel_to_plane.col(2));
      bool near_unknown = false;
      for (int dj = -keep_off_px; dj <= keep_off_px && !near_unknown; ++dj)
        for (int di = -keep_off_px; di <= keep_off_px && !near_unknown; ++di) {
          const int i = static_cast<int>(std::lround(px.x())) + di;
          const int j = static_cast<int>(std::lround(px.y())) + dj;
          near_unknown = i < 0 || j < 0 || i >= geometry.width_px || j >= geometry.height_px ||
                         seg.labels.at(i, j) == kLabelPixelUnknown;
        }
      if (!near_unknown)
        errors.push_back(std::abs((slice->to_world(p) - centre).norm() - ball.radius_mm));
    }
  }
  ASSERT_GT(errors.size(), 20u);
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2];
  const double p90 = errors[errors.size() * 9 / 10];
  std::cout << "contour to sphere: median " << median << " mm, 90% " << p90 << " mm (pixel "
            << geometry.spacing_mm << " mm)\n";
  EXPECT_LT(median, 2.0 * geometry.spacing_mm + 0.2);
  EXPECT_LT(p90, 4.0 * geometry.spacing_mm + 0.5);
}

INSTANTIATE_TEST_SUITE_P(Probes, SegmentSimulated, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "convex" : "linear"; });

TEST(ImagePlane, ScaledRotationGivesProbeCoordinates) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.3, Vec3::UnitY()).toRotationMatrix();
  T.translation() = Vec3(5, 6, 7);
  const acquisition::Probe probe(acquisition::convex_probe_geometry(128, 100));
  const ImagePlane plane =
      image_plane(T.matrix() * probe.T_probe_image().matrix(), T.translation());
  for (const auto& [i, j] : {std::pair{0.0, 0.0}, std::pair{127.0, 3.0}, std::pair{40.0, 99.0}}) {
    EXPECT_TRUE(plane.to_plane(i, j).isApprox(probe.pixel_to_mm(i, j), 1e-12));
    const Vec3 world = T * Vec3(probe.pixel_to_mm(i, j).x(), probe.pixel_to_mm(i, j).y(), 0.0);
    LabeledSlice s;
    s.origin_mm = plane.origin_mm;
    s.u = plane.u;
    s.v = plane.v;
    EXPECT_LT((s.to_world(plane.to_plane(i, j)) - world).norm(), 1e-9);
  }
  EXPECT_NEAR(plane.spacing_mm(), probe.spacing_mm(), 1e-12);
}

TEST(Contours, HolesNestedLabelsAndNoOverlaps) {
  // Label 1 ring with label 2 inside its hole, and an unknown patch touching label 1.
  LabelImage map(60, 50, 0);
  for (int j = 5; j < 45; ++j)
    for (int i = 5; i < 40; ++i) map.at(i, j) = 1;
  for (int j = 15; j < 30; ++j)
    for (int i = 15; i < 28; ++i) map.at(i, j) = 2;
  for (int j = 20; j < 50; ++j)
    for (int i = 40; i < 55; ++i) map.at(i, j) = kLabelPixelUnknown;
  const ImageU8 sector(60, 50, 255);
  ImagePlane plane;
  plane.pixel_to_plane << 0.5, 0.0, -3.0, 0.0, 0.5, 1.0;
  const auto regions = label_map_regions(map, sector, plane, 0.0);
  ASSERT_EQ(regions.size(), 3u);
  std::map<int, const Region*> by_label;
  for (const Region& r : regions) by_label[r.label] = &r;
  ASSERT_EQ(by_label.at(1)->holes.size(), 1u);
  EXPECT_TRUE(by_label.at(2)->holes.empty());
  EXPECT_TRUE(by_label.count(kUnknownLabel));
  // 35 x 40 pixels of 0.5 mm traced on their edges.
  EXPECT_NEAR(std::abs(signed_area(by_label.at(1)->outer)), 35 * 40 * 0.25, 1e-9);
  const auto slice =
      make_slice(map, sector, {{-0.5, -0.5}, {59.5, -0.5}, {59.5, 49.5}, {-0.5, 49.5}}, plane, 2.0);
  ASSERT_TRUE(slice) << slice.message();
  SliceSet set;
  set.slices.push_back(*slice);
  EXPECT_TRUE(validate_slice_set(set, "contours"));
}

TEST(Segmenter, DiagonalContactsAreRepaired) {
  // A checkerboard corner between two labels would give crossing outlines.
  LabelImage image(40, 40, 120);
  SegmentationConfig config;
  config.median_px = 1;
  config.smoothing_mm = 0.0;
  config.opening_mm = 0.0;
  config.min_region_mm2 = 0.0;
  config.shadow_margin_mm = 0.0;
  config.depth_compensation = false;
  config.materials = {{1, "a", 60.0, 10.0}, {2, "b", 200.0, 10.0}};
  for (int j = 0; j < 40; ++j)
    for (int i = 0; i < 40; ++i) image.at(i, j) = (i < 20) == (j < 20) ? 60 : 200;
  const ImageGeometry geometry = full_image_geometry(40, 40, 1.0);
  const Segmentation seg = segment_frame(image, geometry, config);
  ImagePlane plane;
  plane.pixel_to_plane << 1.0, 0.0, 0.0, 0.0, 1.0, 0.0;
  const auto slice = make_slice(seg.labels, geometry.sector, geometry.sector_px, plane, 0.0);
  ASSERT_TRUE(slice) << slice.message();
}

TEST(Config, JsonRoundTripAndErrors) {
  SegmentationConfig config;
  config.materials = {{1, "liver", 70.0, 25.0}, {2, "lesion", 170.0, 27.0}};
  config.simplify_mm = 0.25;
  config.sector = SectorSource::kPolygon;
  config.sector_polygon_px = {{0, 0}, {10, 0}, {5, 8}};
  const auto parsed = parse_segmentation_config(to_json(config), "round trip");
  ASSERT_TRUE(parsed) << parsed.message();
  EXPECT_EQ(parsed->materials.size(), 2u);
  EXPECT_EQ(parsed->materials[1].name, "lesion");
  EXPECT_DOUBLE_EQ(parsed->simplify_mm, 0.25);
  EXPECT_EQ(parsed->sector, SectorSource::kPolygon);
  EXPECT_EQ(parsed->sector_polygon_px.size(), 3u);

  const auto misspelt = parse_segmentation_config(
      R"({"format": "sonoshape-segmentation", "version": 1, "smothing_mm": 1})", "seg.json");
  ASSERT_FALSE(misspelt);
  EXPECT_NE(misspelt.message().find("smothing_mm"), std::string::npos);
  const auto even_median = parse_segmentation_config(
      R"({"format": "sonoshape-segmentation", "version": 1, "median_px": 4})", "seg.json");
  ASSERT_FALSE(even_median);
  EXPECT_NE(even_median.message().find("median_px"), std::string::npos);
  const auto twice = parse_segmentation_config(
      R"({"format": "sonoshape-segmentation", "version": 1,
          "labels": [{"id": 1, "grey_mean": 50}, {"id": 1, "grey_mean": 90}]})",
      "seg.json");
  ASSERT_FALSE(twice);
}

// Found by fuzzing (tests/data/fuzz/segmentation_config/): each was an uncaught exception or a
// value wrapped into a valid one, now an error naming the field.
TEST(Config, OverflowingNumbersAndMistypedHeaderFieldsAreErrors) {
  auto error_of = [](const std::string& text) {
    const auto parsed = parse_segmentation_config(text, "seg.json");
    EXPECT_FALSE(parsed) << text;
    return parsed ? std::string() : parsed.message();
  };
  EXPECT_NE(error_of("1e99999").find("not valid JSON"), std::string::npos);
  EXPECT_NE(error_of(R"({"format": 1, "version": 1})").find("format"), std::string::npos);
  EXPECT_NE(error_of(R"({"format": "sonoshape-segmentation", "version": "1"})").find("version"),
            std::string::npos);
  const std::string header = R"({"format": "sonoshape-segmentation", "version": 1, )";
  EXPECT_NE(error_of(header + R"("median_px": 4294967297})").find("median_px: integer"),
            std::string::npos);
  EXPECT_NE(error_of(header + R"("labels": [{"id": 4294967297, "grey_mean": 50}]})")
                .find("labels[0].id: integer 4294967297 is out of range"),
            std::string::npos);
}

}  // namespace
}  // namespace sonoshape::segmentation::segmentation_test
