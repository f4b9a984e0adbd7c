// The READ path of V4l2FrameSource with the real system calls against a /dev/video0 that
// umockdev emulates: a UMockdevIoctlBase answers QUERYCAP / ENUM_FMT / G_FMT / S_FMT and read(),
// and can fail them with ENODEV (unplugged) or EIO. Runs under umockdev-wrapper (ctest does so).
// umockdev emulates neither mmap() nor poll(): the MMAP path is tested in v4l2_source_test.cpp.
#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <umockdev.h>

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

#include "sonoshape/acquisition/v4l2_source.hpp"

namespace sonoshape::acq {
namespace {

constexpr int kWidth = 32, kHeight = 24;
constexpr const char* kDeviceRecord =
    "P: /devices/pci0000:00/usb1/1-1/1-1:1.0/video4linux/video0\n"
    "N: video0\n"
    "E: SUBSYSTEM=video4linux\n"
    "E: DEVNAME=/dev/video0\n"
    "A: dev=81:0\n"
    "A: name=Fake USB grabber\n";
constexpr const char* kSysPath = "/sys/devices/pci0000:00/usb1/1-1/1-1:1.0/video4linux/video0";

// What the emulated grabber does; shared with umockdev's worker thread.
struct Grabber {
  std::mutex mutex;
  std::deque<std::variant<std::vector<std::uint8_t>, int>> reads;  // a frame or an errno
  bool unplugged = false;
};

void* resolve(UMockdevIoctlClient* client, gsize size) {
  UMockdevIoctlData* data =
      umockdev_ioctl_data_resolve(umockdev_ioctl_client_get_arg(client), 0, size, nullptr);
  return data ? data->data : nullptr;
}

void answer_format(v4l2_format& format) {
  v4l2_pix_format& pix = format.fmt.pix;
  pix.width = kWidth;  // the only size and format this grabber has
  pix.height = kHeight;
  pix.pixelformat = V4L2_PIX_FMT_GREY;
  pix.field = V4L2_FIELD_NONE;
  pix.bytesperline = kWidth;
  pix.sizeimage = kWidth * kHeight;
}

gboolean on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer user) {
  auto* grabber = static_cast<Grabber*>(user);
  std::lock_guard lock(grabber->mutex);
  if (grabber->unplugged) {
    umockdev_ioctl_client_complete(client, -1, ENODEV);
    return TRUE;
  }
  switch (umockdev_ioctl_client_get_request(client)) {
    case VIDIOC_QUERYCAP: {
      auto* cap = static_cast<v4l2_capability*>(resolve(client, sizeof(v4l2_capability)));
      std::memset(cap, 0, sizeof *cap);
      std::strcpy(reinterpret_cast<char*>(cap->card), "Fake USB grabber");
      cap->capabilities = V4L2_CAP_DEVICE_CAPS | V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE;
      cap->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE;
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    case VIDIOC_ENUM_FMT: {
      auto* desc = static_cast<v4l2_fmtdesc*>(resolve(client, sizeof(v4l2_fmtdesc)));
      if (desc->index != 0) {
        umockdev_ioctl_client_complete(client, -1, EINVAL);
        return TRUE;
      }
      desc->pixelformat = V4L2_PIX_FMT_GREY;
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    case VIDIOC_G_FMT:
    case VIDIOC_S_FMT:
      answer_format(*static_cast<v4l2_format*>(resolve(client, sizeof(v4l2_format))));
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    default:  // no G_PARM: the frame rate stays unknown, as with many cheap grabbers
      umockdev_ioctl_client_complete(client, -1, ENOTTY);
      return TRUE;
  }
}

gboolean on_read(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer user) {
  auto* grabber = static_cast<Grabber*>(user);
  std::lock_guard lock(grabber->mutex);
  if (grabber->unplugged) {
    umockdev_ioctl_client_complete(client, -1, ENODEV);
    return TRUE;
  }
  if (grabber->reads.empty()) {
    umockdev_ioctl_client_complete(client, -1, EAGAIN);
    return TRUE;
  }
  auto next = std::move(grabber->reads.front());
  grabber->reads.pop_front();
  if (const int* error = std::get_if<int>(&next)) {
    umockdev_ioctl_client_complete(client, -1, *error);
    return TRUE;
  }
  const auto& frame = std::get<std::vector<std::uint8_t>>(next);
  UMockdevIoctlData* buffer = umockdev_ioctl_client_get_arg(client);
  const std::size_t n = std::min(frame.size(), static_cast<std::size_t>(buffer->data_len));
  std::memcpy(buffer->data, frame.data(), n);
  umockdev_ioctl_client_complete(client, static_cast<glong>(n), 0);
  return TRUE;
}

std::vector<std::uint8_t> grey_frame(int shade) {
  std::vector<std::uint8_t> bytes(std::size_t(kWidth) * kHeight);
  for (int j = 0; j < kHeight; ++j)
    for (int i = 0; i < kWidth; ++i)
      bytes[std::size_t(j) * kWidth + i] = static_cast<std::uint8_t>(i + 3 * j + shade);
  return bytes;
}

double clock_monotonic_s() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

class V4l2Umockdev : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* preload = std::getenv("LD_PRELOAD");
    ASSERT_TRUE(preload && std::strstr(preload, "umockdev-preload"))
        << "run this test under umockdev-wrapper (ctest does)";
    testbed_ = umockdev_testbed_new();
    handler_ = umockdev_ioctl_base_new();
    g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(on_ioctl), &grabber_);
    g_signal_connect(handler_, "handle-read", G_CALLBACK(on_read), &grabber_);
    plug_in();
  }
  void TearDown() override {
    if (handler_) g_object_unref(handler_);
    if (testbed_) g_object_unref(testbed_);
  }
  void plug_in() {
    GError* error = nullptr;
    ASSERT_TRUE(umockdev_testbed_add_from_string(testbed_, kDeviceRecord, &error))
        << error->message;
    ASSERT_TRUE(umockdev_testbed_attach_ioctl(testbed_, "/dev/video0", handler_, &error))
        << error->message;
  }
  // The node vanishes and comes back as the kernel's would. (umockdev 0.17 cannot add a
  // device again after umockdev_testbed_remove_device: it keeps the node's PTY.)
  std::string node_path(const char* suffix) const {
    gchar* root = umockdev_testbed_get_root_dir(testbed_);
    std::string path = std::string(root) + "/dev/video0" + suffix;
    g_free(root);
    return path;
  }
  void remove_node() {
    ASSERT_EQ(std::rename(node_path("").c_str(), node_path(".gone").c_str()), 0);
  }
  void restore_node() {
    ASSERT_EQ(std::rename(node_path(".gone").c_str(), node_path("").c_str()), 0);
  }
  void push(std::variant<std::vector<std::uint8_t>, int> read) {
    std::lock_guard lock(grabber_.mutex);
    grabber_.reads.push_back(std::move(read));
  }
  void set_unplugged(bool unplugged) {
    std::lock_guard lock(grabber_.mutex);
    grabber_.unplugged = unplugged;
  }
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

  Grabber grabber_;
  UMockdevTestbed* testbed_ = nullptr;
  UMockdevIoctlBase* handler_ = nullptr;
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
  const auto format = source.format();
  ASSERT_TRUE(format);
  EXPECT_EQ(format->card, "Fake USB grabber");
  EXPECT_EQ(format->io, V4l2Io::kRead);  // the device cannot stream: auto chose read()
  EXPECT_EQ(fourcc_text(format->fourcc), "GREY");
  EXPECT_FALSE(format->driver_timestamps);
  EXPECT_DOUBLE_EQ(format->frame_rate_hz, 0.0);
  EXPECT_EQ(source.counters().error_frames, 1u);
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
  EXPECT_EQ(source.counters().unplugs, 1u);
  EXPECT_EQ(source.counters().reopens, 1u);
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

}  // namespace
}  // namespace sonoshape::acq
