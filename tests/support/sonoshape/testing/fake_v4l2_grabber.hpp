#pragma once
// A USB frame grabber emulated with umockdev for tests of the V4L2 backend and of
// `sonoshape devices`: /dev/video0 captures 32x24 GREY by read() only (15 and 30 fps listed),
// /dev/video1 is its metadata node. A UMockdevIoctlBase answers QUERYCAP, ENUM_FMT,
// ENUM_FRAMESIZES, ENUM_FRAMEINTERVALS, G_FMT/S_FMT and read(); reads are scripted (a frame or
// an errno); unplugging fails every call with ENODEV and can remove the node. The program must
// run under umockdev-wrapper (LD_PRELOAD); child processes inherit the emulation.
#include <linux/videodev2.h>
#include <umockdev.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

namespace sonoshape::testing {
namespace fake_v4l2 {

inline constexpr int kWidth = 32, kHeight = 24;
inline constexpr const char* kDeviceRecord =
    "P: /devices/pci0000:00/usb1/1-1/1-1:1.0/video4linux/video0\n"
    "N: video0\n"
    "E: SUBSYSTEM=video4linux\n"
    "E: DEVNAME=/dev/video0\n"
    "A: dev=81:0\n"
    "A: name=Fake USB grabber\n";
// The grabber's second node carries metadata only, as UVC devices' odd nodes do.
inline constexpr const char* kMetadataRecord =
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

inline gboolean complete(UMockdevIoctlClient* client, bool ok, int error = EINVAL) {
  umockdev_ioctl_client_complete(client, ok ? 0 : -1, ok ? 0 : error);
  return TRUE;
}

inline bool answer_capability(v4l2_capability& cap, bool metadata) {
  cap = v4l2_capability{};
  set_text(cap.card, "Fake USB grabber");
  set_text(cap.bus_info, "usb-0000:00:14.0-1");
  cap.capabilities =
      V4L2_CAP_DEVICE_CAPS | V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE | V4L2_CAP_META_CAPTURE;
  cap.device_caps = metadata ? V4L2_CAP_META_CAPTURE | V4L2_CAP_STREAMING
                             : V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_READWRITE;
  return true;
}

inline bool answer_format_description(v4l2_fmtdesc& desc) {
  if (desc.index != 0) return false;
  desc.pixelformat = V4L2_PIX_FMT_GREY;
  set_text(desc.description, "8-bit Greyscale");
  return true;
}

inline bool answer_frame_size(v4l2_frmsizeenum& size) {
  if (size.index != 0 || size.pixel_format != V4L2_PIX_FMT_GREY) return false;
  size.type = V4L2_FRMSIZE_TYPE_DISCRETE;
  size.discrete = {kWidth, kHeight};
  return true;
}

inline bool answer_frame_interval(v4l2_frmivalenum& interval) {  // 15 and 30 fps, slowest first
  if (interval.index >= 2 || interval.width != kWidth || interval.height != kHeight) return false;
  interval.type = V4L2_FRMIVAL_TYPE_DISCRETE;
  interval.discrete = {1, interval.index == 0 ? 15u : 30u};
  return true;
}

inline bool answer_format(v4l2_format& format) {
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
inline gboolean answer(UMockdevIoctlClient* client, Answer fill) {
  Argument<T> arg(client);
  const bool ok = fill(arg.value);
  if (ok) arg.store();
  return complete(client, ok);
}

inline gboolean on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer user) {
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

inline gboolean on_read(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer user) {
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

inline std::vector<std::uint8_t> grey_frame(int shade) {
  std::vector<std::uint8_t> bytes(std::size_t(kWidth) * kHeight);
  for (int j = 0; j < kHeight; ++j)
    for (int i = 0; i < kWidth; ++i)
      bytes[std::size_t(j) * kWidth + i] = static_cast<std::uint8_t>(i + 3 * j + shade);
  return bytes;
}

}  // namespace fake_v4l2

/// Whether this process runs under umockdev-wrapper.
inline bool umockdev_preloaded() {
  const char* preload = std::getenv("LD_PRELOAD");
  return preload && std::strstr(preload, "umockdev-preload");
}

/// The emulated grabber in a umockdev testbed of its own (the testbed lives as long as this).
class FakeV4l2Grabber {
 public:
  using Read = std::variant<std::vector<std::uint8_t>, int>;  ///< a frame or an errno

  /// Adds /dev/video0 (and, with `with_metadata_node`, /dev/video1). Throws std::runtime_error
  /// when umockdev refuses.
  explicit FakeV4l2Grabber(bool with_metadata_node = false) {
    testbed_ = umockdev_testbed_new();
    handler_ = umockdev_ioctl_base_new();
    g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(fake_v4l2::on_ioctl), &state_);
    g_signal_connect(handler_, "handle-read", G_CALLBACK(fake_v4l2::on_read), &state_);
    add(fake_v4l2::kDeviceRecord, "/dev/video0");
    if (with_metadata_node) add(fake_v4l2::kMetadataRecord, "/dev/video1");
  }
  ~FakeV4l2Grabber() {
    g_object_unref(handler_);
    g_object_unref(testbed_);
  }
  FakeV4l2Grabber(const FakeV4l2Grabber&) = delete;
  FakeV4l2Grabber& operator=(const FakeV4l2Grabber&) = delete;

  /// Queues what the next read() gets.
  void push(Read read) {
    std::lock_guard lock(state_.mutex);
    state_.reads.push_back(std::move(read));
  }
  /// true: every ioctl and read fails with ENODEV, as an unplugged device's open file does.
  void set_unplugged(bool unplugged) {
    std::lock_guard lock(state_.mutex);
    state_.unplugged = unplugged;
  }
  /// The node vanishes and comes back as the kernel's would. (umockdev 0.17 cannot add a
  /// device again after umockdev_testbed_remove_device: it keeps the node's PTY.)
  bool remove_node() { return std::rename(node("").c_str(), node(".gone").c_str()) == 0; }
  bool restore_node() { return std::rename(node(".gone").c_str(), node("").c_str()) == 0; }

 private:
  void add(const char* record, const char* devnode) {
    GError* error = nullptr;
    if (!umockdev_testbed_add_from_string(testbed_, record, &error) ||
        !umockdev_testbed_attach_ioctl(testbed_, devnode, handler_, &error))
      throw std::runtime_error(std::string("umockdev: ") + (error ? error->message : "failed"));
  }
  std::string node(const char* suffix) const {
    gchar* root = umockdev_testbed_get_root_dir(testbed_);
    std::string path = std::string(root) + "/dev/video0" + suffix;
    g_free(root);
    return path;
  }

  fake_v4l2::Grabber state_;
  UMockdevTestbed* testbed_ = nullptr;
  UMockdevIoctlBase* handler_ = nullptr;
};

}  // namespace sonoshape::testing
