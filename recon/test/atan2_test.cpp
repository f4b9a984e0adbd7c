// fast_atan2 against std::atan2: within 2 ulp everywhere, the same signs and zeros.
#include "atan2.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace sonoshape::recon::atan2_test {
namespace {

double ulps_apart(double a, double b) {
  if (a == b) return 0.0;
  const double ulp =
      std::nextafter(std::abs(a), std::numeric_limits<double>::infinity()) - std::abs(a);
  return std::abs(a - b) / ulp;
}

TEST(FastAtan2, WithinTwoUlpOfTheLibrary) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> exponent(-12.0, 12.0);
  double worst = 0.0;
  for (int i = 0; i < 1000000; ++i) {
    const double y = normal(rng) * std::pow(10.0, exponent(rng));
    const double x = normal(rng) * std::pow(10.0, exponent(rng));
    worst = std::max(worst, ulps_apart(std::atan2(y, x), fast_atan2(y, x)));
  }
  EXPECT_LE(worst, 2.0);
  // Near the branch points of the reduction (t = 0.66, t = 1) and the axes.
  for (const double t : {0.0, 1e-300, 1e-8, 0.5, 0.66, std::nextafter(0.66, 1.0), 0.99999999, 1.0})
    for (const double sx : {1.0, -1.0})
      for (const double sy : {1.0, -1.0}) {
        EXPECT_LE(ulps_apart(std::atan2(sy * t, sx), fast_atan2(sy * t, sx)), 2.0) << t;
        EXPECT_LE(ulps_apart(std::atan2(sy, sx * t), fast_atan2(sy, sx * t)), 2.0) << t;
      }
}

TEST(FastAtan2, SignsAndZerosAsTheLibrary) {
  for (const double y : {0.0, -0.0, 1.0, -1.0})
    for (const double x : {0.0, -0.0, 1.0, -1.0}) {
      const double expected = std::atan2(y, x), got = fast_atan2(y, x);
      EXPECT_EQ(expected, got) << y << ' ' << x;
      EXPECT_EQ(std::signbit(expected), std::signbit(got)) << y << ' ' << x;
    }
}

}  // namespace
}  // namespace sonoshape::recon::atan2_test
