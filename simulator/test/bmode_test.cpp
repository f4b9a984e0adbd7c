#include "sonoshape/simulator/bmode.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace sonoshape::simulator::bmode_test {
namespace {

// Probe pose that puts the phantom point `centre` at probe coordinates `in_probe`.
Eigen::Isometry3d pose_seeing(const Vec3& centre, const Vec3& in_probe,
                              const Eigen::Matrix3d& rotation) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = rotation;
  T.translation() = centre - rotation * in_probe;
  return T;
}

Eigen::Matrix3d some_rotation() {
  return (Eigen::AngleAxisd(0.7, Vec3(0.3, -0.5, 0.8).normalized()) *
          Eigen::AngleAxisd(0.2, Vec3::UnitX()))
      .toRotationMatrix();
}

struct Ball {
  Vec3 centre;
  double radius;
  int label;
};

// Expected label of the pixel centre from the analytic spheres (innermost wins); none when the
// centre is within `margin` mm of a sphere (the mesh approximates it) or of the sector edge.
std::optional<std::uint8_t> analytic_label(const acquisition::Probe& probe,
                                           const Eigen::Isometry3d& T,
                                           const std::vector<Ball>& balls, int i, int j,
                                           double margin) {
  const Vec2 xy = probe.pixel_to_mm(i, j);
  if (!probe.in_sector(xy)) return kLabelPixelUnknown;
  const Vec3 p = T * Vec3(xy.x(), xy.y(), 0.0);
  std::uint8_t label = kLabelPixelOutside;
  double best_radius = std::numeric_limits<double>::infinity();
  for (const Ball& b : balls) {
    const double d = (p - b.centre).norm();
    if (std::abs(d - b.radius) < margin) return std::nullopt;
    if (d < b.radius && b.radius < best_radius) {
      best_radius = b.radius;
      label = static_cast<std::uint8_t>(b.label);
    }
  }
  return label;
}

void expect_labels_match(const acquisition::Probe& probe, const std::vector<Ball>& balls,
                         const Eigen::Isometry3d& T, std::size_t min_inner_pixels) {
  Phantom phantom;
  for (const Ball& b : balls) {
    Eigen::Affine3d place = Eigen::Affine3d::Identity();
    place.translation() = b.centre;
    phantom.add(b.label, "ball", make_sphere(b.radius, 256, 128), place);
  }
  const BModeSimulator simulator(phantom, probe);
  const SimulatedFrame frame = simulator.render(T, 1);
  ASSERT_EQ(frame.labels.width, probe.width_px());
  std::size_t checked = 0, skipped = 0;
  std::map<int, std::size_t> per_label;
  for (int j = 0; j < probe.height_px(); ++j)
    for (int i = 0; i < probe.width_px(); ++i) {
      // Mesh vs sphere: the chord sagitta of 128 rings of radius 25 is 0.008 mm.
      const auto expected = analytic_label(probe, T, balls, i, j, 0.02);
      if (!expected) {
        ++skipped;
        continue;
      }
      ++checked;
      ++per_label[*expected];
      ASSERT_EQ(frame.labels.at(i, j), *expected) << "pixel " << i << ", " << j;
      // Soft tissue casts no shadow: the ground truth is the label image.
      ASSERT_EQ(frame.truth.at(i, j), *expected) << "pixel " << i << ", " << j;
    }
  EXPECT_LT(skipped, checked / 50);
  for (const Ball& b : balls) EXPECT_GE(per_label[b.label], min_inner_pixels) << b.label;
  EXPECT_GT(per_label[kLabelPixelOutside], 1000u);
  EXPECT_GT(per_label[kLabelPixelUnknown], 1000u);
}

TEST(BMode, SphereLabelImageMatchesTheAnalyticCutConvex) {
  const acquisition::Probe probe(acquisition::convex_probe_geometry(240, 200));
  const std::vector<Ball> balls{{Vec3(10, -20, 5), 25.0, 1}};
  expect_labels_match(probe, balls, pose_seeing(balls[0].centre, Vec3(4, 60, 7), some_rotation()),
                      2000);
}

TEST(BMode, NestedSpheresLabelImageMatchesTheAnalyticCutLinear) {
  const acquisition::Probe probe(acquisition::linear_probe_geometry(200, 220));
  const std::vector<Ball> balls{{Vec3(0, 0, 0), 18.0, 1}, {Vec3(2, 1, -1), 7.0, 2}};
  expect_labels_match(probe, balls, pose_seeing(Vec3(0, 0, 0), Vec3(-3, 25, 2), some_rotation()),
                      1000);
}

TEST(BMode, DeterministicForASeedAndGreyFollowsEchogenicity) {
  Phantom phantom;
  Eigen::Affine3d left = Eigen::Affine3d::Identity(), right = left;
  left.translation() = Vec3(-15, 0, 0);
  right.translation() = Vec3(15, 0, 0);
  phantom.add(1, "dark", make_sphere(12.0), left, tissue_preset("hypoechoic"));
  phantom.add(2, "bright", make_sphere(12.0), right, tissue_preset("hyperechoic"));
  const acquisition::Probe probe(acquisition::linear_probe_geometry(160, 160));
  const BModeSimulator simulator(phantom, probe);
  const auto T = pose_seeing(Vec3::Zero(), Vec3(0, 25, 0), Eigen::Matrix3d::Identity());
  const SimulatedFrame a = simulator.render(T, 42), b = simulator.render(T, 42);
  const SimulatedFrame c = simulator.render(T, 43);
  EXPECT_EQ(a.bmode, b.bmode);
  EXPECT_NE(a.bmode, c.bmode);
  EXPECT_EQ(a.labels, c.labels);
  double sum[3] = {0, 0, 0}, count[3] = {0, 0, 0};
  for (std::size_t p = 0; p < a.truth.pixels.size(); ++p)
    if (a.truth.pixels[p] <= 2) {
      sum[a.truth.pixels[p]] += a.bmode.pixels[p];
      count[a.truth.pixels[p]] += 1;
    }
  ASSERT_GT(count[1], 500);
  ASSERT_GT(count[2], 500);
  const double background = sum[0] / count[0], dark = sum[1] / count[1], bright = sum[2] / count[2];
  EXPECT_LT(dark + 25, background) << dark << " vs " << background;
  EXPECT_GT(bright - 25, background) << bright << " vs " << background;
  EXPECT_DOUBLE_EQ(a.shadow_fraction, 0.0);
}

TEST(BMode, StrongReflectorCastsAShadowMarkedUnknown) {
  // A bone bar across the top of the image, a soft organ below it.
  Phantom phantom;
  Eigen::Affine3d bar = Eigen::Affine3d::Identity();
  bar.translate(Vec3(0, 10, 0));
  bar.rotate(Eigen::AngleAxisd(std::acos(-1.0) / 2, Vec3::UnitY()));  // along x
  phantom.add(1, "rib", make_cylinder(3.0, 14.0), bar, tissue_preset("bone"));
  Eigen::Affine3d organ = Eigen::Affine3d::Identity();
  organ.translation() = Vec3(0, 32, 0);
  phantom.add(2, "organ", make_sphere(10.0), organ, tissue_preset("hyperechoic"));
  const acquisition::Probe probe(
      acquisition::linear_probe_geometry(200, 200));  // 40 mm wide, 50 deep; rib 14 mm long
  const BModeSimulator simulator(phantom, probe);
  const SimulatedFrame frame = simulator.render(Eigen::Isometry3d::Identity(), 5);
  EXPECT_GT(frame.shadow_fraction, 0.1);
  auto mean_grey = [&](double x0, double x1, double y0, double y1) {
    double sum = 0, n = 0;
    for (int j = 0; j < probe.height_px(); ++j)
      for (int i = 0; i < probe.width_px(); ++i) {
        const Vec2 p = probe.pixel_to_mm(i, j);
        if (p.x() < x0 || p.x() > x1 || p.y() < y0 || p.y() > y1) continue;
        sum += frame.bmode.at(i, j);
        n += 1;
      }
    return sum / n;
  };
  auto truth_share = [&](std::uint8_t value, double x0, double x1, double y0, double y1) {
    double hits = 0, n = 0;
    for (int j = 0; j < probe.height_px(); ++j)
      for (int i = 0; i < probe.width_px(); ++i) {
        const Vec2 p = probe.pixel_to_mm(i, j);
        if (p.x() < x0 || p.x() > x1 || p.y() < y0 || p.y() > y1) continue;
        hits += frame.truth.at(i, j) == value ? 1 : 0;
        n += 1;
      }
    return hits / n;
  };
  // Behind the rib (|x| < 5, deeper than 15 mm): dark and unknown, organ included.
  const double behind = mean_grey(-5, 5, 16, 48);
  const double beside = mean_grey(12, 18, 16, 48);  // same depths, beside the rib
  EXPECT_LT(behind + 60, beside) << behind << " vs " << beside;
  EXPECT_GT(truth_share(kLabelPixelUnknown, -5, 5, 16, 48), 0.99);
  EXPECT_EQ(
      frame.labels.at(probe.width_px() / 2, static_cast<int>(probe.mm_to_pixel(Vec2(0, 32)).y())),
      2);  // the organ is in the labels, just not in the truth
  // In front of the rib nothing is shadowed, and its top surface echoes brightly.
  EXPECT_LT(truth_share(kLabelPixelUnknown, -5, 5, 1, 6), 0.01);
  EXPECT_GT(mean_grey(-4, 4, 6.8, 7.2), 200.0);
  // The organ beside the shadow stays known.
  EXPECT_GT(truth_share(2, 8, 9.5, 30, 34), 0.9);
  // The bone keeps its whole section in the truth (it casts its shadow); the organ does not.
  EXPECT_TRUE(simulator.casts_shadow(1));
  EXPECT_FALSE(simulator.casts_shadow(2));
  EXPECT_EQ(
      frame.truth.at(probe.width_px() / 2, static_cast<int>(probe.mm_to_pixel(Vec2(0, 11)).y())),
      1);
}

}  // namespace
}  // namespace sonoshape::simulator::bmode_test
