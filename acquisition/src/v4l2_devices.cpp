#include "sonoshape/acquisition/v4l2_devices.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <functional>
#include <sstream>
#include <system_error>

#include "sonoshape/acquisition/v4l2_source.hpp"

namespace sonoshape::acquisition {
namespace {

std::string text_of(const std::uint8_t* bytes, std::size_t capacity) {
  const char* chars = reinterpret_cast<const char*>(bytes);
  return std::string(chars, strnlen(chars, capacity));
}

bool is_readable(std::uint32_t fourcc) {
  return fourcc == V4L2_PIX_FMT_GREY || fourcc == V4L2_PIX_FMT_YUYV || fourcc == V4L2_PIX_FMT_MJPEG;
}

// An ioctl with EINTR retried.
int query(V4l2Device& device, int fd, unsigned long request, void* arg) {
  int result = 0;
  do {
    result = device.ioctl(fd, request, arg);
  } while (result == -1 && errno == EINTR);
  return result;
}

// Rates of one size: discrete intervals as Hz, highest first (stepwise: the fastest).
std::vector<double> frame_rates(V4l2Device& device, int fd, std::uint32_t fourcc,
                                std::uint32_t width, std::uint32_t height) {
  std::vector<double> rates;
  for (std::uint32_t index = 0;; ++index) {
    v4l2_frmivalenum interval{};
    interval.index = index;
    interval.pixel_format = fourcc;
    interval.width = width;
    interval.height = height;
    if (query(device, fd, VIDIOC_ENUM_FRAMEINTERVALS, &interval) < 0) break;
    const v4l2_fract& period =
        interval.type == V4L2_FRMIVAL_TYPE_DISCRETE ? interval.discrete : interval.stepwise.min;
    if (period.numerator > 0) rates.push_back(double(period.denominator) / period.numerator);
    if (interval.type != V4L2_FRMIVAL_TYPE_DISCRETE) break;
  }
  std::sort(rates.rbegin(), rates.rend());
  return rates;
}

void enumerate_sizes(V4l2Device& device, int fd, V4l2FormatInfo& format) {
  for (std::uint32_t index = 0;; ++index) {
    v4l2_frmsizeenum size{};
    size.index = index;
    size.pixel_format = format.fourcc;
    if (query(device, fd, VIDIOC_ENUM_FRAMESIZES, &size) < 0) return;
    if (size.type != V4L2_FRMSIZE_TYPE_DISCRETE) {
      const v4l2_frmsize_stepwise& s = size.stepwise;
      format.size_range = std::to_string(s.min_width) + "x" + std::to_string(s.min_height) + ".." +
                          std::to_string(s.max_width) + "x" + std::to_string(s.max_height);
      return;
    }
    format.sizes.push_back(
        {int(size.discrete.width), int(size.discrete.height),
         frame_rates(device, fd, format.fourcc, size.discrete.width, size.discrete.height)});
  }
}

// QUERYCAP and the formats of an open node; false when it is not a video capture node.
bool describe_node(V4l2Device& device, int fd, V4l2DeviceInfo& info) {
  v4l2_capability cap{};
  if (query(device, fd, VIDIOC_QUERYCAP, &cap) < 0) return false;
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
  if (!(caps & V4L2_CAP_VIDEO_CAPTURE)) return false;
  info.card = text_of(cap.card, sizeof cap.card);
  info.bus = text_of(cap.bus_info, sizeof cap.bus_info);
  info.streaming = caps & V4L2_CAP_STREAMING;
  info.read = caps & V4L2_CAP_READWRITE;
  for (std::uint32_t index = 0;; ++index) {
    v4l2_fmtdesc desc{};
    desc.index = index;
    desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (query(device, fd, VIDIOC_ENUM_FMT, &desc) < 0) break;
    V4l2FormatInfo format;
    format.fourcc = desc.pixelformat;
    format.description = text_of(desc.description, sizeof desc.description);
    format.readable = is_readable(desc.pixelformat);
    enumerate_sizes(device, fd, format);
    info.formats.push_back(std::move(format));
  }
  return true;
}

std::string rate_text(double hz) {
  std::ostringstream text;
  text << hz;
  return text.str();
}

}  // namespace

std::vector<V4l2DeviceInfo> list_v4l2_devices(V4l2Device& device,
                                              const std::filesystem::path& sys_class,
                                              std::vector<std::string>* unreadable) {
  std::vector<std::string> paths;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(sys_class, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("video", 0) == 0) paths.push_back("/dev/" + name);
  }
  std::sort(paths.begin(), paths.end());
  std::vector<V4l2DeviceInfo> devices;
  for (const std::string& path : paths) {
    const int fd = device.open(path, O_RDWR | O_NONBLOCK);
    if (fd < 0) {
      if (unreadable) unreadable->push_back(path + ": " + std::strerror(errno));
      continue;
    }
    V4l2DeviceInfo info;
    info.path = path;
    if (describe_node(device, fd, info)) devices.push_back(std::move(info));
    device.close(fd);
  }
  return devices;
}

std::vector<std::string> v4l2_source_specs(const V4l2DeviceInfo& info) {
  std::vector<std::string> specs;
  const std::string io = info.streaming ? "" : "&io=read";
  for (const V4l2FormatInfo& format : info.formats) {
    if (!format.readable) continue;
    const std::string base = "v4l2:" + info.path + "?";
    const std::string name = "format=" + fourcc_text(format.fourcc);
    if (format.sizes.empty()) specs.push_back(base + name + io);
    for (const V4l2FrameSize& size : format.sizes)
      specs.push_back(base + "size=" + std::to_string(size.width_px) + "x" +
                      std::to_string(size.height_px) + "&" + name +
                      (size.rates_hz.empty() ? "" : "&fps=" + rate_text(size.rates_hz.front())) +
                      io);
  }
  return specs;
}

std::string v4l2_devices_report(const std::vector<V4l2DeviceInfo>& devices,
                                const std::vector<std::string>& unreadable) {
  std::ostringstream out;
  out << "Frame grabbers (V4L2):\n";
  if (devices.empty())
    out << "  no video capture device found (is the grabber plugged in? ls /dev/video*)\n";
  for (const V4l2DeviceInfo& info : devices) {
    out << "  " << info.path << "  " << info.card << "  (" << info.bus
        << "; io: " << (info.streaming ? "mmap" : "") << (info.streaming && info.read ? ", " : "")
        << (info.read ? "read" : "") << ")\n";
    const std::vector<std::string> specs = v4l2_source_specs(info);
    std::size_t next_spec = 0;
    for (const V4l2FormatInfo& format : info.formats) {
      out << "    " << fourcc_text(format.fourcc) << "  " << format.description;
      if (!format.readable) {
        out << "  (sonoshape reads GREY, YUYV and MJPG only)\n";
        continue;
      }
      out << (format.size_range.empty() ? "" : "  sizes " + format.size_range) << "\n";
      if (format.sizes.empty()) out << "      --source " << specs[next_spec++] << "\n";
      for (const V4l2FrameSize& size : format.sizes) {
        out << "      " << size.width_px << "x" << size.height_px;
        for (std::size_t k = 0; k < size.rates_hz.size(); ++k)
          out << (k == 0 ? " at " : ", ") << rate_text(size.rates_hz[k])
              << (k + 1 == size.rates_hz.size() ? " fps" : "");
        out << ":  --source " << specs[next_spec++] << "\n";
      }
    }
  }
  for (const std::string& node : unreadable) {
    out << "  cannot open " << node << "\n";
    if (node.find(std::strerror(EACCES)) != std::string::npos)
      out << "    (add the user to the 'video' group: usermod -aG video USER, log in again)\n";
  }
  return out.str();
}

}  // namespace sonoshape::acquisition
