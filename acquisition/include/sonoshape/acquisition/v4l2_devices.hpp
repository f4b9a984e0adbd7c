#pragma once
// The V4L2 capture devices of this machine with their formats, sizes and rates, for
// `sonoshape devices`: each offered mode as a `--source v4l2:...` a user can paste.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "sonoshape/acquisition/v4l2_device.hpp"

namespace sonoshape::acquisition {

/// One capture size of a format and the frame rates the driver lists for it (Hz, highest
/// first; empty when it lists none).
struct V4l2FrameSize {
  int width_px = 0;
  int height_px = 0;
  std::vector<double> rates_hz;
};

/// One pixel format a device offers.
struct V4l2FormatInfo {
  std::uint32_t fourcc = 0;
  std::string description;           ///< the driver's ("YUYV 4:2:2")
  bool readable = false;             ///< sonoshape converts it (GREY, YUYV, MJPG)
  std::vector<V4l2FrameSize> sizes;  ///< discrete sizes
  /// Stepwise or continuous sizes, as "MINxMIN..MAXxMAX" (then `sizes` is empty).
  std::string size_range;
};

/// One video capture node.
struct V4l2DeviceInfo {
  std::string path;        ///< "/dev/video0"
  std::string card;        ///< VIDIOC_QUERYCAP's card name
  std::string bus;         ///< bus_info ("usb-0000:00:14.0-2")
  bool streaming = false;  ///< supports io=mmap
  bool read = false;       ///< supports io=read
  std::vector<V4l2FormatInfo> formats;
};

/// Lists the video capture nodes named in `sys_class` (the kernel's /sys/class/video4linux:
/// one entry per /dev/videoN), queried through `device` (QUERYCAP, ENUM_FMT,
/// ENUM_FRAMESIZES, ENUM_FRAMEINTERVALS), sorted by path. Nodes that are not video capture
/// (metadata, output) are left out; nodes that cannot be opened are listed in `unreadable`
/// as "PATH: reason" when it is given.
std::vector<V4l2DeviceInfo> list_v4l2_devices(
    V4l2Device& device, const std::filesystem::path& sys_class = "/sys/class/video4linux",
    std::vector<std::string>* unreadable = nullptr);

/// The `--source` strings of a device's readable modes, one per format and size, at the
/// highest rate listed ("v4l2:/dev/video0?size=1280x720&format=YUYV&fps=30"); for a size
/// range, one without size.
std::vector<std::string> v4l2_source_specs(const V4l2DeviceInfo& info);

/// The text `sonoshape devices` prints for the grabbers: per device its node, card, bus and
/// I/O methods, per format its sizes and rates, and under each readable mode the `--source`
/// to paste; formats sonoshape does not read are named as such; `unreadable` nodes are listed
/// with the fix for a permission problem. Says so when there is no device.
std::string v4l2_devices_report(const std::vector<V4l2DeviceInfo>& devices,
                                const std::vector<std::string>& unreadable);

}  // namespace sonoshape::acquisition
