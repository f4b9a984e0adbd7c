// The far-field tree against the exact edge-by-edge projected angle.
#include "chain_tree.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "mean_value.hpp"

namespace sonoshape::recon::chain_tree_test {
namespace {

// A wobbly organ-like contour of n points (radius 40 mm +- 25%), counter-clockwise.
Ring2 wobbly_ring(int n, double phase) {
  Ring2 ring;
  for (int i = 0; i < n; ++i) {
    const double t = 2.0 * std::numbers::pi * i / n;
    const double r = 40.0 * (1.0 + 0.15 * std::sin(3 * t + phase) + 0.1 * std::cos(7 * t));
    ring.emplace_back(r * std::cos(t), r * std::sin(t));
  }
  return ring;
}

TEST(ChainTree, MatchesTheExactSumNearAndFar) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> coordinate(-90.0, 90.0);
  std::uniform_real_distribution<double> log_height(-4.0, 2.2);
  for (const int n : {40, 400, 2000}) {
    for (const bool hole : {false, true}) {
      Ring2 ring = wobbly_ring(n, 0.3 * n);
      if (hole) std::reverse(ring.begin(), ring.end());
      std::vector<ChainNode> nodes;
      const std::uint32_t root = build_chain_tree(ring.data(), ring.size(), nodes);
      double worst = 0.0, worst_relative = 0.0;
      for (int k = 0; k < 4000; ++k) {
        Vec2 foot(coordinate(rng), coordinate(rng));
        if (k % 4 == 0)
          foot = ring[static_cast<std::size_t>(k) % ring.size()] +
                 Vec2(0.01, -0.02);  // on the contour
        const double height = std::pow(10.0, log_height(rng));
        const double exact = projected_angle(ring.data(), ring.size(), foot, height);
        const double tree =
            projected_angle_tree(ring.data(), ring.size(), nodes.data(), root, foot, height);
        worst = std::max(worst, std::abs(tree - exact));
        if (std::abs(exact) > 1e-12)
          worst_relative = std::max(worst_relative, std::abs(tree - exact) / std::abs(exact));
      }
      // The field is a ratio of such angles (each up to 2 pi): 2e-5 rad moves a surface by far
      // less than a micrometre where the field's gradient is one over a few mm.
      EXPECT_LT(worst, 2e-5) << n << " points, hole " << hole;
      EXPECT_LT(worst_relative, 1e-4) << n << " points, hole " << hole;
      RecordProperty("worst_" + std::to_string(n) + (hole ? "_hole" : ""), std::to_string(worst));
    }
  }
}

TEST(ChainTree, RegionMomentsAreExactForAWholeRing) {
  // The root's region is the ring itself: area and centred moments of a square are known.
  const Ring2 square{Vec2(1, 1), Vec2(3, 1), Vec2(3, 3), Vec2(1, 3)};
  std::vector<ChainNode> nodes;
  build_chain_tree(square.data(), square.size(), nodes);
  EXPECT_NEAR(nodes[0].area, 4.0, 1e-12);
  EXPECT_NEAR(nodes[0].m1x, 0.0, 1e-12);
  EXPECT_NEAR(nodes[0].m2xx, 4.0 / 3.0, 1e-12);  // integral of x^2 over [-1, 1]^2
  EXPECT_NEAR(nodes[0].m2xy, 0.0, 1e-12);
}

TEST(ChainTree, HighMomentsMatchQuadrature) {
  // The third and fourth moments of a triangle about its box centre, against a midpoint rule on
  // a fine grid (error of order the cell size at the boundary).
  const Ring2 triangle{Vec2(0, 0), Vec2(3, 0), Vec2(0, 2)};
  std::vector<ChainNode> nodes;
  build_chain_tree(triangle.data(), triangle.size(), nodes);
  const Vec2 centre(1.5, 1.0);
  ASSERT_NEAR((nodes[0].centre - centre).norm(), 0.0, 1e-12);
  constexpr int kCells = 2000;
  double m3[4] = {}, m4[5] = {};
  const double cell = 3.0 / kCells;
  for (int i = 0; i < kCells; ++i)
    for (int j = 0; j < kCells; ++j) {
      const double x = (i + 0.5) * cell, y = (j + 0.5) * cell;
      if (x / 3.0 + y / 2.0 > 1.0) continue;
      const double u = x - centre.x(), v = y - centre.y(), area = cell * cell;
      const double us[5] = {1, u, u * u, u * u * u, u * u * u * u};
      const double vs[5] = {1, v, v * v, v * v * v, v * v * v * v};
      for (int k = 0; k < 4; ++k) m3[k] += us[3 - k] * vs[k] * area;
      for (int k = 0; k < 5; ++k) m4[k] += us[4 - k] * vs[k] * area;
    }
  for (int k = 0; k < 4; ++k)
    EXPECT_NEAR(nodes[0].m3[k], m3[k], 2e-3) << "x^" << 3 - k << " y^" << k;
  for (int k = 0; k < 5; ++k)
    EXPECT_NEAR(nodes[0].m4[k], m4[k], 3e-3) << "x^" << 4 - k << " y^" << k;
  // Not all zero (a symmetric shape would test little).
  EXPECT_GT(std::abs(m3[0]) + std::abs(m3[3]), 0.1);
}

}  // namespace
}  // namespace sonoshape::recon::chain_tree_test
