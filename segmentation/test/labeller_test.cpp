// The graph-cut labelling (grid alpha-expansion, the labeller over simulated frames), bone
// sections from their surface band, and the overlay pictures.
#include "sonoshape/segmentation/labeller.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "graph_cut.hpp"
#include "reflectors.hpp"
#include "small_sweep.hpp"
#include "sonoshape/segmentation/config.hpp"
#include "sonoshape/segmentation/overlay.hpp"
#include "sonoshape/segmentation/scoring.hpp"
#include "sonoshape/segmentation/sweep.hpp"

namespace sonoshape::segmentation::labeller_test {
namespace {

// A square of label 1 in a field of 0, seen through noisy costs: the Potts term must give back
// the square where the pixelwise minimum is speckled, and never raise the energy.
TEST(GridLabelling, RecoversASquareFromNoisyCosts) {
  const int w = 40, h = 30;
  std::vector<std::uint8_t> active(static_cast<std::size_t>(w) * h, 1);
  detail::GridLabelling grid(w, h, active, 3);
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.0f, 0.9f);
  std::vector<float> cost(active.size() * 3);
  std::vector<std::uint8_t> truth(active.size()), labelling(active.size());
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const std::size_t c = static_cast<std::size_t>(j) * w + i;
      truth[c] = (i >= 10 && i < 30 && j >= 8 && j < 22) ? 1 : 0;
      for (std::size_t l = 0; l < 3; ++l)
        cost[c * 3 + l] = (l == truth[c] ? 0.0f : 1.0f) + noise(rng);
      std::size_t best = 0;  // the pixelwise minimum starts the cut
      for (std::size_t l = 1; l < 3; ++l)
        if (cost[c * 3 + l] < cost[c * 3 + best]) best = l;
      labelling[c] = static_cast<std::uint8_t>(best);
    }
  auto wrong = [&] {
    int n = 0;
    for (std::size_t c = 0; c < truth.size(); ++c) n += labelling[c] != truth[c];
    return n;
  };
  const int wrong_before = wrong();
  const std::vector<float> weight(active.size(), 1.2f);
  grid.minimise(cost, weight, weight, labelling, 3);
  EXPECT_GT(wrong_before, 200);
  EXPECT_LT(wrong(), 25) << "before the cut: " << wrong_before;
}

TEST(GridLabelling, KeepsInactiveCellsAndChecksSizes) {
  std::vector<std::uint8_t> active = {1, 1, 0, 1};
  detail::GridLabelling grid(2, 2, active, 2);
  std::vector<float> cost = {0, 5, 5, 0, 0, 0, 0, 5};
  std::vector<std::uint8_t> labelling = {1, 1, 1, 1};
  const std::vector<float> weight(4, 0.0f);
  grid.minimise(cost, weight, weight, labelling, 2);
  EXPECT_EQ(labelling, (std::vector<std::uint8_t>{0, 1, 1, 0}));
  std::vector<std::uint8_t> short_labelling(3);
  EXPECT_THROW(grid.minimise(cost, weight, weight, short_labelling, 1), std::invalid_argument);
}

// The upper arc of a disc (what a probe sees of a rib) becomes the whole disc, at a fine pixel
// size and at a coarse one (the rib of the default simulated scan is 30 px thick at 512 x 512
// and 15 px at 256 x 256, its echo band about 2 px and 1 px).
TEST(ReflectorSections, UpperArcBecomesTheDisc) {
  struct Case {
    double radius_px, band_px, arc_deg;
  };
  for (const Case& c : {Case{15.0, 2.0, 60.0}, Case{7.5, 1.0, 45.0}}) {
    const double r = c.radius_px;
    cv::Mat map(100, 100, CV_8U, cv::Scalar(0)), sector(100, 100, CV_8U, cv::Scalar(255));
    cv::Mat grey(100, 100, CV_32F, cv::Scalar(100.0f));
    const double cx = 50.3, cy = 50.6;
    int disc = 0;
    for (int j = 0; j < 100; ++j)
      for (int i = 0; i < 100; ++i) {
        const double d = std::hypot(i - cx, j - cy);
        if (d <= r) ++disc;
        // The echo band about the surface, where the beam meets it within arc_deg of normal.
        const double from_top_deg = std::atan2(std::abs(i - cx), cy - j) * 180.0 / M_PI;
        if (std::abs(d - r) <= 0.5 * c.band_px && j < cy && from_top_deg <= c.arc_deg) {
          map.at<std::uint8_t>(j, i) = 3;
          grey.at<float>(j, i) = static_cast<float>(250.0 - 40.0 * std::abs(d - r));
        }
      }
    detail::fill_reflector_sections(map, grey, sector, 3, 2 * r, 3);
    int both = 0, ours = 0;
    for (int j = 0; j < 100; ++j)
      for (int i = 0; i < 100; ++i) {
        const bool in = std::hypot(i - cx, j - cy) <= r, got = map.at<std::uint8_t>(j, i) == 3;
        ours += got;
        both += in && got;
      }
    const double iou = static_cast<double>(both) / (disc + ours - both);
    EXPECT_GT(iou, 0.88) << "radius " << r << " px: ours " << ours << " px, disc " << disc << " px";
  }
}

TEST(ReflectorSections, SpecksAndUnknownThicknessChangeNothing) {
  cv::Mat map(20, 20, CV_8U, cv::Scalar(0)), sector(20, 20, CV_8U, cv::Scalar(255));
  const cv::Mat grey(20, 20, CV_32F, cv::Scalar(100.0f));
  map.at<std::uint8_t>(5, 5) = 3;  // one bright speck
  const cv::Mat before = map.clone();
  detail::fill_reflector_sections(map, grey, sector, 3, 8.0, 3);
  EXPECT_EQ(cv::countNonZero(map != before), 0);
  map.row(5).setTo(3);
  const cv::Mat band = map.clone();
  detail::fill_reflector_sections(map, grey, sector, 3, 0.0, 3);
  EXPECT_EQ(cv::countNonZero(map != band), 0);
}

// Over a small simulated sweep the graph cut is at least as close to the truth as the
// threshold labelling it starts from, and a prior equal to the truth brings it closer still.
TEST(GraphCutLabeller, RefinesTheThresholdLabellingAndFollowsAPrior) {
  const test::SmallSweep small = test::organ_and_lesion_sweep(8);
  const acquisition::SequenceFile& bmode = small.sweep.bmode;
  const acquisition::SequenceFile& truth_frames = small.sweep.truth;
  const auto setup =
      prepare_sweep(bmode, "small.igs.mha", std::optional<SegmentationConfig>(), std::nullopt);
  ASSERT_TRUE(setup) << setup.message();
  GraphCutLabeller plain(setup->config, setup->geometry), guided(setup->config, setup->geometry);
  LabelComparison threshold_total, cut_total, guided_total;
  for (std::size_t k = 0; k < bmode.frame_count(); ++k) {
    const GreyImage image = bmode.image(k);
    const LabelImage truth = truth_frames.image(k);
    threshold_total.add(compare_labels(truth,
                                       segment_frame(image, setup->geometry, setup->config).labels,
                                       setup->geometry.sector));
    cut_total.add(compare_labels(truth, plain.segment(image).labels, setup->geometry.sector));
    guided_total.add(
        compare_labels(truth, guided.segment(image, &truth).labels, setup->geometry.sector));
  }
  for (const auto& [label, counts] : threshold_total.labels) {
    if (label == 0) continue;
    std::cout << "label " << label << " Dice threshold " << counts.dice() << ", graph cut "
              << cut_total.labels[label].dice() << ", with the truth as prior "
              << guided_total.labels[label].dice() << '\n';
    EXPECT_GE(cut_total.labels[label].dice(), counts.dice() - 0.02) << "label " << label;
    EXPECT_GE(guided_total.labels[label].dice(), cut_total.labels[label].dice() - 0.005)
        << "label " << label;
  }
  const LabelImage wrong_size(3, 3, 0);
  EXPECT_THROW(guided.segment(bmode.image(0), &wrong_size), std::invalid_argument);
}

// Background speckle only, with a dark organ in the configuration: the threshold labelling
// leaves grains, which its cleaning removes where they are below min_region_mm2. The cut may
// move the boundary of a grain the cleaning keeps (a fifth more pixels here), but must not grow
// neighbouring grains into organ pieces the cleaning then keeps (it did: 1.9 times the
// threshold's pixels).
TEST(GraphCutLabeller, MakesNoOrganOutOfSpeckle) {
  const int w = 320, h = 320;
  const double px_mm = 0.3;
  const ImageGeometry geometry = full_image_geometry(w, h, px_mm);
  SegmentationConfig config;
  config.background = {0, "background", 87.0, 25.0};
  config.materials = {{1, "dark organ", 42.0, 25.0}};
  config.depth_compensation = false;
  config.psf_sigma_mm = 0.0;
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 1.0);
  int organ_px_threshold = 0, organ_px_cut = 0;
  for (int frame = 0; frame < 6; ++frame) {
    // Speckle grains about 1 mm across: white noise blurred, then scaled to the grey's spread.
    cv::Mat field(h, w, CV_32F);
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) field.at<float>(j, i) = static_cast<float>(noise(rng));
    cv::GaussianBlur(field, field, cv::Size(0, 0), 1.0 / px_mm / 2.0);
    cv::Scalar mean, spread;
    cv::meanStdDev(field, mean, spread);
    GreyImage image(w, h, 0);
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i)
        image.at(i, j) = static_cast<std::uint8_t>(
            std::clamp(87.0 + 25.0 * (field.at<float>(j, i) - mean[0]) / spread[0], 0.0, 255.0));
    const LabelImage threshold = segment_frame(image, geometry, config).labels;
    const LabelImage cut = GraphCutLabeller(config, geometry).segment(image).labels;
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        organ_px_threshold += threshold.at(i, j) == 1;
        organ_px_cut += cut.at(i, j) == 1;
      }
  }
  std::cout << "organ pixels in pure background: threshold " << organ_px_threshold << ", graph cut "
            << organ_px_cut << '\n';
  EXPECT_LE(organ_px_cut, 1.2 * organ_px_threshold);
}

// Two organs of the same grey (look-alikes): which is which comes from the prior where it
// predicts them and from the nearest seed elsewhere, not from the image.
TEST(GraphCutLabeller, NamesLookAlikeOrgansByPriorThenSeed) {
  const int w = 160, h = 100;
  const double px_mm = 0.25;
  const ImageGeometry geometry = full_image_geometry(w, h, px_mm);
  GreyImage image(w, h, 0);
  std::mt19937 rng(3);
  std::normal_distribution<double> speckle(0.0, 12.0);
  const cv::Point left(40, 50), right(120, 50);
  const int radius_px = 22;
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const bool in = std::hypot(i - left.x, j - left.y) < radius_px ||
                      std::hypot(i - right.x, j - right.y) < radius_px;
      image.at(i, j) =
          static_cast<std::uint8_t>(std::clamp((in ? 50.0 : 130.0) + speckle(rng), 0.0, 255.0));
    }
  SegmentationConfig config;
  config.background = {0, "background", 130.0, 12.0};
  config.materials = {{1, "a", 50.0, 12.0}, {2, "b", 50.0, 12.0}};
  config.depth_compensation = false;
  config.psf_sigma_mm = 0.0;
  ImagePlane plane;  // pixels -> mm: the plane's (a, b) are the reference frame's (x, y)
  plane.pixel_to_plane << px_mm, 0.0, 0.0, 0.0, px_mm, 0.0;
  const Vec3 left_mm(left.x * px_mm, left.y * px_mm, 0.0);
  const Vec3 right_mm(right.x * px_mm, right.y * px_mm, 0.0);
  auto label_at = [](const LabelImage& labels, cv::Point p) { return int{labels.at(p.x, p.y)}; };

  // Seeds alone: the left disc is organ 2, the right one organ 1.
  config.materials[0].seed_mm = right_mm;
  config.materials[1].seed_mm = left_mm;
  GraphCutLabeller seeded(config, geometry);
  const LabelImage by_seed = seeded.segment(image, nullptr, &plane).labels;
  EXPECT_EQ(label_at(by_seed, left), 2);
  EXPECT_EQ(label_at(by_seed, right), 1);

  // A prior over the left disc names it, whatever the seeds say; the right one keeps its seed.
  LabelImage prior(w, h, 0);
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i)
      if (std::hypot(i - left.x, j - left.y) < radius_px - 3) prior.at(i, j) = 1;
  GraphCutLabeller guided(config, geometry);
  const LabelImage by_prior = guided.segment(image, &prior, &plane).labels;
  EXPECT_EQ(label_at(by_prior, left), 1);
  EXPECT_EQ(label_at(by_prior, right), 1);
  config.materials[0].seed_mm = left_mm;  // now the right disc is nearest seed 2
  config.materials[1].seed_mm = right_mm;
  GraphCutLabeller reseeded(config, geometry);
  const LabelImage both = reseeded.segment(image, &prior, &plane).labels;
  EXPECT_EQ(label_at(both, left), 1);
  EXPECT_EQ(label_at(both, right), 2);

  // Without a plane, seeds cannot place a region: each keeps the label the cut gave it.
  const LabelImage unplaced = GraphCutLabeller(config, geometry).segment(image).labels;
  EXPECT_NE(label_at(unplaced, left), 0);
  EXPECT_NE(label_at(unplaced, right), 0);
}

// The blur behind the blooming correction comes from a simulated sweep's header unless the
// configuration gives it; 0 there turns the correction off.
TEST(SweepSetup, BlurFromTheHeaderUnlessTheConfigurationGivesIt) {
  const test::SmallSweep small = test::organ_and_lesion_sweep(2);
  const auto from_header = prepare_sweep(small.sweep.bmode, "s.igs.mha",
                                         std::optional<SegmentationConfig>(), std::nullopt);
  ASSERT_TRUE(from_header) << from_header.message();
  EXPECT_GT(from_header->config.psf_sigma_mm, 0.0);
  SegmentationConfig off;
  off.psf_sigma_mm = 0.0;
  const auto without = prepare_sweep(small.sweep.bmode, "s.igs.mha",
                                     std::optional<SegmentationConfig>(off), std::nullopt);
  ASSERT_TRUE(without) << without.message();
  EXPECT_EQ(without->config.psf_sigma_mm, 0.0);
}

TEST(Overlay, WritesAPictureAndNamesASizeMismatch) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("sonoshape_overlay_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  GreyImage frame(32, 24, 100);
  LabelImage ours(32, 24, 0), truth(32, 24, 0);
  for (int j = 8; j < 16; ++j)
    for (int i = 8; i < 20; ++i) ours.at(i, j) = truth.at(i + 1, j) = 1;
  const ImageU8 sector(32, 24, 255);
  ASSERT_TRUE(write_overlay(dir / "a.png", frame, ours, sector, &truth));
  EXPECT_GT(std::filesystem::file_size(dir / "a.png"), 100u);
  const LabelImage small(8, 8, 0);
  const Status mismatch = write_overlay(dir / "b.png", frame, small, sector);
  ASSERT_FALSE(mismatch);
  EXPECT_NE(mismatch.message().find("differ in size"), std::string::npos) << mismatch.message();
  const Status unwritable = write_overlay(dir / "no_such_dir" / "c.png", frame, ours, sector);
  EXPECT_FALSE(unwritable);
  std::filesystem::remove_all(dir);
}

TEST(SegmentationConfigMethod, ParsesAndRoundTrips) {
  const auto config = parse_segmentation_config(
      R"({"format": "sonoshape-segmentation", "version": 1, "method": "graph_cut",
          "labels": [{"id": 3, "name": "rib", "grey_mean": 250, "grey_std": 15,
                      "thickness_mm": 9.5, "seed_mm": [1.5, -2, 30]}]})",
      "test");
  ASSERT_TRUE(config) << config.message();
  EXPECT_EQ(config->method, LabellingMethod::kGraphCut);
  EXPECT_DOUBLE_EQ(config->materials.at(0).thickness_mm, 9.5);
  const auto again = parse_segmentation_config(to_json(*config), "round trip");
  ASSERT_TRUE(again) << again.message();
  EXPECT_EQ(again->method, LabellingMethod::kGraphCut);
  EXPECT_DOUBLE_EQ(again->materials.at(0).thickness_mm, 9.5);
  ASSERT_TRUE(again->materials.at(0).seed_mm.has_value());
  EXPECT_EQ(*again->materials.at(0).seed_mm, Vec3(1.5, -2.0, 30.0));
  const auto bad_seed = parse_segmentation_config(
      R"({"format": "sonoshape-segmentation", "version": 1,
          "labels": [{"id": 1, "grey_mean": 50, "seed_mm": [1, 2]}]})",
      "seed.json");
  ASSERT_FALSE(bad_seed);
  EXPECT_NE(bad_seed.message().find("labels[0].seed_mm"), std::string::npos) << bad_seed.message();
  const auto bad = parse_segmentation_config(
      R"({"format": "sonoshape-segmentation", "version": 1, "method": "magic"})", "bad.json");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("method"), std::string::npos) << bad.message();
}

// The graph cut's weights come from the configuration's "graph_cut" object, round-trip, and a
// wrong one is an error naming it.
TEST(SegmentationConfigMethod, GraphCutWeightsParseRoundTripAndAreChecked) {
  const std::string head = R"({"format": "sonoshape-segmentation", "version": 1, "graph_cut": )";
  const auto config = parse_segmentation_config(
      head + R"({"cell_mm": 0.3, "smoothness": 0.75, "prior_weight": 2, "prior_margin_mm": 1,
                 "model_update": 0.5}})",
      "weights.json");
  ASSERT_TRUE(config) << config.message();
  const auto again = parse_segmentation_config(to_json(*config), "round trip");
  ASSERT_TRUE(again) << again.message();
  for (const SegmentationConfig* c : {&*config, &*again}) {
    EXPECT_DOUBLE_EQ(c->graph_cut.cell_mm, 0.3);
    EXPECT_DOUBLE_EQ(c->graph_cut.smoothness, 0.75);
    EXPECT_DOUBLE_EQ(c->graph_cut.prior_weight, 2.0);
    EXPECT_DOUBLE_EQ(c->graph_cut.prior_margin_mm, 1.0);
    EXPECT_DOUBLE_EQ(c->graph_cut.model_update, 0.5);
  }
  for (const auto& [body, named] : std::vector<std::pair<std::string, std::string>>{
           {R"({"cell_mm": 0})", "graph_cut.cell_mm"},
           {R"({"smoothness": -1})", "graph_cut.smoothness"},
           {R"({"model_update": 1.5})", "graph_cut.model_update"},
           {R"({"cells": 2})", "graph_cut.cells"},
           {R"({"cell_mm": "fine"})", "graph_cut.cell_mm"},
           {R"(0.6)", "graph_cut"}}) {
    const auto wrong = parse_segmentation_config(head + body + "}", "weights.json");
    ASSERT_FALSE(wrong) << body;
    EXPECT_NE(wrong.message().find("weights.json"), std::string::npos) << wrong.message();
    EXPECT_NE(wrong.message().find(named), std::string::npos) << wrong.message();
  }
}

}  // namespace
}  // namespace sonoshape::segmentation::labeller_test
