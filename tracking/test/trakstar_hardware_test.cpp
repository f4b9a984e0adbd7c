// A real trakSTAR / driveBAY on USB (ctest label `hardware`, not in the default suite): run with
// a unit powered, its transmitter and a sensor attached, and nothing else holding it:
//   SONOSHAPE_TRAKSTAR="sensor=1,rate=80" ctest --test-dir build -L hardware
// It checks what the emulator tests cannot: that the device answers the setup, and that its
// records decode to plausible poses at the measurement rate.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "sonoshape/tracking/trakstar_source.hpp"

namespace sonoshape::tracking::trakstar_hardware_test {
namespace {

TEST(TrakstarHardware, ARealUnitDeliversPosesAtItsRate) {
  const char* env = std::getenv("SONOSHAPE_TRAKSTAR");
  const auto options = parse_trakstar_options(env ? env : "");
  ASSERT_TRUE(options) << options.message();
  const auto found = find_trakstars();
  ASSERT_TRUE(found) << found.message();
  if (found->empty())
    GTEST_SKIP() << "no trakSTAR/driveBAY on USB: attach one (transmitter and a sensor) to run "
                    "this hardware test";
  TrakstarPoseSource source(*options);
  ASSERT_TRUE(source.start());
  std::vector<Pose> poses;
  while (poses.size() < 100)
    if (auto p = source.next(2.0))
      poses.push_back(p->item);
    else
      break;
  source.stop();
  ASSERT_EQ(poses.size(), 100u) << source.message();
  const TrakstarCounts c = source.backend().counts();
  EXPECT_GT(c.valid, 0u) << "every record invalid: is the sensor on port " << options->sensor
                         << " attached and within range?";
  const double span_s = poses.back().timestamp_s - poses.front().timestamp_s;
  // 99 periods at the rate, with room for a busy host.
  EXPECT_GT(span_s, 0.8 * 99.0 / options->rate_hz);
  EXPECT_LT(span_s, 3.0 * 99.0 / options->rate_hz);
  for (const Pose& p : poses) {
    if (p.status != TrackingStatus::kValid) continue;
    EXPECT_LT(p.T_reference_probe.translation().norm(),
              (options->long_range ? 72.0 : 36.0) * 25.4 * std::sqrt(3.0));
    EXPECT_NEAR(p.T_reference_probe.linear().determinant(), 1.0, 1e-6);
  }
}

}  // namespace
}  // namespace sonoshape::tracking::trakstar_hardware_test
