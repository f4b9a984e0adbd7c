// The READ path of V4l2FrameSource with the real system calls against a /dev/video0 that
// umockdev emulates: a UMockdevIoctlBase answers QUERYCAP / ENUM_FMT / G_FMT / S_FMT and read(),
// and can fail them with ENODEV (unplugged) or EIO. Runs under umockdev-wrapper (ctest does so).
// umockdev emulates neither mmap() nor poll(): the MMAP path is tested in v4l2_source_test.cpp.
#include <gtest/gtest.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <variant>

#include "sonoshape/acquisition/v4l2_devices.hpp"
#include "sonoshape/acquisition/v4l2_source.hpp"
#include "sonoshape/testing/fake_v4l2_grabber.hpp"

namespace sonoshape::acquisition::v4l2_umockdev_test {
namespace {

using testing::fake_v4l2::grey_frame;
using testing::fake_v4l2::kHeight;
using testing::fake_v4l2::kWidth;

double clock_monotonic_s() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

class V4l2Umockdev : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(testing::umockdev_preloaded())
        << "run this test under umockdev-wrapper (ctest does)";
    grabber_ = std::make_unique<testing::FakeV4l2Grabber>(with_metadata_node_);
  }
  void push(testing::FakeV4l2Grabber::Read read) { grabber_->push(std::move(read)); }
  void set_unplugged(bool unplugged) { grabber_->set_unplugged(unplugged); }
  void remove_node() { ASSERT_TRUE(grabber_->remove_node()); }
  void restore_node() { ASSERT_TRUE(grabber_->restore_node()); }
  static V4l2Options options() {
    V4l2Options o;
    o.device = "/dev/video0";
    o.poll_timeout_ms = 10;
    o.reopen_first_s = 0.01;
    o.reopen_max_s = 0.05;
    return o;
  }
  static std::vector<Frame> take(FrameSource& source, std::size_t count) {
    std::vector<Frame> frames;
    while (frames.size() < count) {
      auto got = source.next(5.0);
      if (!got) break;
      frames.push_back(std::move(got->item));
    }
    return frames;
  }

  bool with_metadata_node_ = false;
  std::unique_ptr<testing::FakeV4l2Grabber> grabber_;
};

class V4l2UmockdevWithMetadataNode : public V4l2Umockdev {
 protected:
  void SetUp() override {
    with_metadata_node_ = true;
    V4l2Umockdev::SetUp();
  }
};

TEST_F(V4l2Umockdev, ReadIoDeliversCroppedFramesStampedOnArrival) {
  push(grey_frame(0));
  push(EINTR);  // retried
  push(EIO);    // that frame is lost, counted
  push(grey_frame(1));
  push(grey_frame(2));
  V4l2Options o = options();
  o.crop = PixelRect{4, 2, 10, 8};
  V4l2FrameSource source(o);
  const double before_s = clock_monotonic_s();
  ASSERT_TRUE(source.start());
  const auto frames = take(source, 3);
  const double after_s = clock_monotonic_s();
  ASSERT_EQ(frames.size(), 3u) << source.message();
  for (std::size_t k = 0; k < frames.size(); ++k) {
    EXPECT_EQ(frames[k].index, static_cast<std::int64_t>(k));
    ASSERT_EQ(frames[k].image.width, 10);
    ASSERT_EQ(frames[k].image.height, 8);
    EXPECT_EQ(frames[k].image.at(0, 0), 4 + 3 * 2 + static_cast<int>(k));
    EXPECT_EQ(frames[k].image.at(9, 7), 13 + 3 * 9 + static_cast<int>(k));
    // read() has no driver timestamp: CLOCK_MONOTONIC on arrival.
    EXPECT_GE(frames[k].timestamp_s, before_s);
    EXPECT_LE(frames[k].timestamp_s, after_s);
    if (k > 0) {
      EXPECT_GE(frames[k].timestamp_s, frames[k - 1].timestamp_s);
    }
  }
  const auto format = source.backend().format();
  ASSERT_TRUE(format);
  EXPECT_EQ(format->card, "Fake USB grabber");
  EXPECT_EQ(format->io, V4l2Io::kRead);  // the device cannot stream: auto chose read()
  EXPECT_EQ(fourcc_text(format->fourcc), "GREY");
  EXPECT_FALSE(format->driver_timestamps);
  EXPECT_DOUBLE_EQ(format->frame_rate_hz, 0.0);
  EXPECT_EQ(source.backend().counters().error_frames, 1u);
  EXPECT_EQ(source.dropped(), 1u);
}

TEST_F(V4l2Umockdev, UnplugMidStreamIsReportedAndCaptureResumesAfterReplug) {
  push(grey_frame(0));
  push(grey_frame(1));
  V4l2FrameSource source(options());
  ASSERT_TRUE(source.start());
  ASSERT_EQ(take(source, 2).size(), 2u) << source.message();

  set_unplugged(true);  // the next read fails with ENODEV
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (source.condition().empty() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  EXPECT_NE(source.condition().find("/dev/video0 vanished"), std::string::npos)
      << source.condition();
  remove_node();  // the node is gone: reopening fails with ENOENT for a while
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_EQ(source.state(), SourceState::kRunning);
  EXPECT_NE(source.condition().find("cannot open /dev/video0"), std::string::npos)
      << source.condition();

  set_unplugged(false);
  push(grey_frame(5));
  push(grey_frame(6));
  restore_node();
  const auto after = take(source, 2);
  ASSERT_EQ(after.size(), 2u) << source.condition();
  EXPECT_EQ(after[0].index, 2);
  EXPECT_EQ(after[1].image.at(0, 0), 6);
  EXPECT_EQ(source.condition(), "");
  EXPECT_EQ(source.backend().counters().unplugs, 1u);
  EXPECT_EQ(source.backend().counters().reopens, 1u);
}

TEST_F(V4l2Umockdev, MmapOnAGrabberThatCannotStreamFailsNamingTheFix) {
  V4l2Options o = options();
  o.io = V4l2Io::kMmap;
  V4l2FrameSource source(o);
  ASSERT_TRUE(source.start());
  EXPECT_TRUE(take(source, 1).empty());
  EXPECT_EQ(source.state(), SourceState::kFailed);
  EXPECT_NE(source.message().find("'Fake USB grabber' does not stream; use io=read"),
            std::string::npos)
      << source.message();
}

TEST_F(V4l2UmockdevWithMetadataNode, DevicesListsCaptureNodesWithModesAPastableSourceOpens) {
  auto system = system_v4l2_device();
  const auto devices = list_v4l2_devices(*system);
  ASSERT_EQ(devices.size(), 1u);  // video1 is metadata only
  const V4l2DeviceInfo& grabber = devices.front();
  EXPECT_EQ(grabber.path, "/dev/video0");
  EXPECT_EQ(grabber.card, "Fake USB grabber");
  EXPECT_EQ(grabber.bus, "usb-0000:00:14.0-1");
  EXPECT_TRUE(grabber.read);
  EXPECT_FALSE(grabber.streaming);
  ASSERT_EQ(grabber.formats.size(), 1u);
  EXPECT_EQ(grabber.formats[0].description, "8-bit Greyscale");
  ASSERT_EQ(grabber.formats[0].sizes.size(), 1u);
  EXPECT_EQ(grabber.formats[0].sizes[0].rates_hz, (std::vector<double>{30.0, 15.0}));
  const auto specs = v4l2_source_specs(grabber);
  ASSERT_EQ(specs,
            (std::vector<std::string>{"v4l2:/dev/video0?size=32x24&format=GREY&fps=30&io=read"}));

  const std::string report = v4l2_devices_report(devices, {"/dev/video9: Permission denied"});
  EXPECT_NE(report.find("/dev/video0  Fake USB grabber  (usb-0000:00:14.0-1; io: read)\n"
                        "    GREY  8-bit Greyscale\n"
                        "      32x24 at 30, 15 fps:  --source " +
                        specs[0] + "\n"),
            std::string::npos)
      << report;
  EXPECT_NE(report.find("cannot open /dev/video9: Permission denied\n    (add the user to the "
                        "'video' group"),
            std::string::npos)
      << report;
  EXPECT_NE(v4l2_devices_report({}, {}).find("no video capture device found"), std::string::npos);

  // What `sonoshape devices` prints is what --source takes.
  const auto options = parse_v4l2_spec(specs[0].substr(5));
  ASSERT_TRUE(options) << options.message();
  push(grey_frame(9));
  V4l2FrameSource source(*options);
  ASSERT_TRUE(source.start());
  const auto frames = take(source, 1);
  ASSERT_EQ(frames.size(), 1u) << source.message();
  EXPECT_EQ(frames[0].image.at(1, 1), 1 + 3 + 9);
}

}  // namespace
}  // namespace sonoshape::acquisition::v4l2_umockdev_test
