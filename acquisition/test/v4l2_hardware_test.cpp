// A real frame grabber, when one is attached (label `hardware`, skipped by default):
//   SONOSHAPE_TEST_V4L2='/dev/video0?format=YUYV' ctest --test-dir build -L hardware
// Checks what no emulation can: the driver's timestamps are on this machine's CLOCK_MONOTONIC,
// frames come at the granted rate, and the device is released for the next program.
#include <gtest/gtest.h>
#include <time.h>

#include <cstdlib>
#include <iostream>

#include "sonoshape/acquisition/v4l2_source.hpp"

namespace sonoshape::acquisition::v4l2_hardware_test {
namespace {

double clock_monotonic_s() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

TEST(V4l2Hardware, AnAttachedGrabberDeliversFramesOnTheMonotonicClock) {
  const char* spec = std::getenv("SONOSHAPE_TEST_V4L2");
  if (!spec) GTEST_SKIP() << "set SONOSHAPE_TEST_V4L2=/dev/videoN[?...] to test a real grabber";
  const auto options = parse_v4l2_spec(spec);
  ASSERT_TRUE(options) << options.message();
  for (int run = 0; run < 2; ++run) {  // the second run finds the device released
    V4l2FrameSource source(*options);
    ASSERT_TRUE(source.start());
    std::vector<Frame> frames;
    while (frames.size() < 30) {
      auto got = source.next(5.0);
      ASSERT_TRUE(got) << "no frame for 5 s: " << source.message() << source.condition();
      frames.push_back(std::move(got->item));
    }
    const double now_s = clock_monotonic_s();
    const auto format = source.backend().format();
    ASSERT_TRUE(format);
    std::cout << source.describe() << ": '" << format->card << "' " << fourcc_text(format->fourcc)
              << " " << format->width_px << "x" << format->height_px << " at "
              << format->frame_rate_hz << " fps, "
              << (format->io == V4l2Io::kMmap ? "mmap" : "read") << ", driver timestamps "
              << (format->driver_timestamps ? "yes" : "no") << ", dropped " << source.dropped()
              << "\n";
    for (std::size_t k = 1; k < frames.size(); ++k)
      EXPECT_GT(frames[k].timestamp_s, frames[k - 1].timestamp_s) << k;
    EXPECT_NEAR(frames.back().timestamp_s, now_s, 1.0);  // stamped on our clock
    const double span_s = frames.back().timestamp_s - frames.front().timestamp_s;
    if (format->frame_rate_hz > 0.0 && source.dropped() == 0) {
      EXPECT_NEAR(29.0 / span_s, format->frame_rate_hz, 0.2 * format->frame_rate_hz);
    }
    const int width = options->crop ? options->crop->width_px : format->width_px;
    EXPECT_EQ(frames.back().image.width, width);
    source.stop();
    EXPECT_EQ(source.state(), SourceState::kEnded) << source.message();
  }
}

}  // namespace
}  // namespace sonoshape::acquisition::v4l2_hardware_test
