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

#include "sonoshape/acquisition/v4l2_devices.hpp"
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
// The grabber's second node carries metadata only, as UVC devices' odd nodes do.
constexpr const char* kMetadataRecord =
    "P: /devices/pci0000:00/usb1/1-1/1-1:1.0/video4linux/video1\n"
    "N: video1\n"
    "E: SUBSYSTEM=video4linux\n"
    "E: DEVNAME=/dev/video1\n"
    "A: dev=81:1\n"
    "A: name=Fake USB grabber\n";

// What the emulated grabber does; shared with umockdev's worker thread.
struct Grabber {
  std::mutex mutex;
  std::deque<std::variant<std::vector<std::uint8_t>, int>> reads;  // a frame or an errno
  bool unplugged = false;
};

// The struct an ioctl points to: copied from the client, written back by store().
template <typename T>
struct Argument {
  explicit Argument(UMockdevIoctlClient* client)
      : data(umockdev_ioctl_data_resolve(umockdev_ioctl_client_get_arg(client), 0, sizeof(T),
                                         nullptr)) {
    if (data) std::memcpy(&value, data->data, sizeof(T));
  }
  void store() {
    if (data) std::memcpy(data->data, &value, sizeof(T));
  }
  UMockdevIoctlData* data;
  T value{};
};

template <std::size_t N>
void set_text(std::uint8_t (&field)[N], const char* text) {
  std::snprintf(reinterpret_cast<char*>(field), N, "%s", text);
}

gboolean complete(UMockdevIoctlClient* client, bool ok, int error = EINVAL) {
  umockdev_ioctl_client_complete(client, ok ? 0 : -1, ok ? 0 : error);
  return TRUE;
}

bool answer_capability(v4l2_capability& cap, bool metadata) {
  cap = v4l2_capability{};
  set_text(cap.card, "Fake USB grabber");
  set_text(cap.bus_info, "usb-0000:00:14.0-1");
  cap.capabilities =
      V4L2_CAP_DEVICE_CAPS | V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE | V4L2_CAP_META_CAPTURE;
  cap.device_caps = metadata ? V4L2_CAP_META_CAPTURE | V4L2_CAP_STREAMING
                             : V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE;
  return true;
}

bool answer_format_description(v4l2_fmtdesc& desc) {
  if (desc.index != 0) return false;
  desc.pixelformat = V4L2_PIX_FMT_GREY;
  set_text(desc.description, "8-bit Greyscale");
  return true;
}

bool answer_frame_size(v4l2_frmsizeenum& size) {
  if (size.index != 0 || size.pixel_format != V4L2_PIX_FMT_GREY) return false;
  size.type = V4L2_FRMSIZE_TYPE_DISCRETE;
  size.discrete = {kWidth, kHeight};
  return true;
}

bool answer_frame_interval(v4l2_frmivalenum& interval) {  // 15 and 30 fps, slowest first
  if (interval.index >= 2 || interval.width != kWidth || interval.height != kHeight) return false;
  interval.type = V4L2_FRMIVAL_TYPE_DISCRETE;
  interval.discrete = {1, interval.index == 0 ? 15u : 30u};
  return true;
}

bool answer_format(v4l2_format& format) {
  v4l2_pix_format& pix = format.fmt.pix;
  pix.width = kWidth;  // the only size and format this grabber has
  pix.height = kHeight;
  pix.pixelformat = V4L2_PIX_FMT_GREY;
  pix.field = V4L2_FIELD_NONE;
  pix.bytesperline = kWidth;
  pix.sizeimage = kWidth * kHeight;
  return true;
}

template <typename T, typename Answer>
gboolean answer(UMockdevIoctlClient* client, Answer fill) {
  Argument<T> arg(client);
  const bool ok = fill(arg.value);
  if (ok) arg.store();
  return complete(client, ok);
}

gboolean on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer user) {
  auto* grabber = static_cast<Grabber*>(user);
  std::lock_guard lock(grabber->mutex);
  if (grabber->unplugged) return complete(client, false, ENODEV);
  const bool metadata = std::strcmp(umockdev_ioctl_client_get_devnode(client), "/dev/video1") == 0;
  switch (umockdev_ioctl_client_get_request(client)) {
    case VIDIOC_QUERYCAP:
      return answer<v4l2_capability>(
          client, [&](v4l2_capability& cap) { return answer_capability(cap, metadata); });
    case VIDIOC_ENUM_FMT:
      return answer<v4l2_fmtdesc>(client, answer_format_description);
    case VIDIOC_ENUM_FRAMESIZES:
      return answer<v4l2_frmsizeenum>(client, answer_frame_size);
    case VIDIOC_ENUM_FRAMEINTERVALS:
      return answer<v4l2_frmivalenum>(client, answer_frame_interval);
    case VIDIOC_G_FMT:
    case VIDIOC_S_FMT:
      return answer<v4l2_format>(client, answer_format);
    default:  // no G_PARM: the frame rate stays unknown, as with many cheap grabbers
      return complete(client, false, ENOTTY);
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

TEST_F(V4l2Umockdev, DevicesListsCaptureNodesWithModesAPastableSourceOpens) {
  GError* error = nullptr;
  ASSERT_TRUE(umockdev_testbed_add_from_string(testbed_, kMetadataRecord, &error))
      << error->message;
  ASSERT_TRUE(umockdev_testbed_attach_ioctl(testbed_, "/dev/video1", handler_, &error))
      << error->message;
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
}  // namespace sonoshape::acq
