#include "sonoshape/acquisition/v4l2_source.hpp"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/mman.h>
#include <time.h>
#include <turbojpeg.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string_view>
#include <thread>
#include <utility>

#include "sonoshape/core/log.hpp"

namespace sonoshape::acquisition {
namespace {

constexpr int kMinBuffers = 4;
constexpr const char* kSpecForm =
    "the form is v4l2:/dev/videoN?size=WxH&format=GREY|YUYV|MJPG&fps=HZ&io=mmap|read"
    "&crop=X,Y,W,H&buffers=N (every key optional)";
// The formats sonoshape reads, in the order it picks them when the user names none: grey
// levels need no conversion, YUYV's Y plane is a copy, MJPG costs a decode.
constexpr std::uint32_t kReadable[] = {V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG};

// The clock of the driver's V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC stamps and of the trackers'.
double clock_monotonic_s() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

std::string errno_text(int error) { return std::strerror(error); }

std::optional<std::uint32_t> fourcc_from_name(std::string name) {
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  if (name == "GREY" || name == "Y8" || name == "GRAY") return V4L2_PIX_FMT_GREY;
  if (name == "YUYV") return V4L2_PIX_FMT_YUYV;
  if (name == "MJPG" || name == "MJPEG") return V4L2_PIX_FMT_MJPEG;
  return std::nullopt;
}

std::vector<std::string_view> split(std::string_view text, char separator) {
  std::vector<std::string_view> parts;
  while (true) {
    const std::size_t at = text.find(separator);
    parts.push_back(text.substr(0, at));
    if (at == std::string_view::npos) return parts;
    text.remove_prefix(at + 1);
  }
}

bool parse_int(std::string_view text, int& value) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  return ec == std::errc() && ptr == end && !text.empty();
}

bool parse_ints(std::string_view text, char separator, std::vector<int>& values) {
  values.clear();
  for (const std::string_view part : split(text, separator)) {
    int v = 0;
    if (!parse_int(part, v)) return false;
    values.push_back(v);
  }
  return true;
}

// The largest image side a capture card is taken to give (V4L2 drivers stop at 8192).
constexpr int kMaxSidePx = 16384;

Status spec_error(const std::string& spec, const std::string& what) {
  return Status::error("--source v4l2:" + spec + ": " + what + "; " + kSpecForm);
}

// Applies one key=value of the query to `options`.
Status apply_spec_item(const std::string& spec, std::string_view item, V4l2Options& options) {
  const std::size_t eq = item.find('=');
  if (eq == std::string_view::npos)
    return spec_error(spec, "'" + std::string(item) + "' is not key=value");
  const std::string key(item.substr(0, eq));
  const std::string value(item.substr(eq + 1));
  std::vector<int> numbers;
  if (key == "size") {
    if (!parse_ints(value, 'x', numbers) || numbers.size() != 2 || numbers[0] <= 0 ||
        numbers[1] <= 0)
      return spec_error(spec, "size=" + value + " is not WIDTHxHEIGHT in pixels (e.g. 1280x720)");
    // Checked before anything is sized from it: 99999999x99999999 ended in a bare bad_alloc.
    if (numbers[0] > kMaxSidePx || numbers[1] > kMaxSidePx)
      return spec_error(spec, "size=" + value + " is larger than any capture device gives (" +
                                  std::to_string(kMaxSidePx) + " pixels a side at most)");
    options.width_px = numbers[0];
    options.height_px = numbers[1];
  } else if (key == "format") {
    if (!fourcc_from_name(value))
      return spec_error(spec, "format=" + value + " is not one sonoshape reads (GREY, YUYV, MJPG)");
    options.pixel_format = value;
  } else if (key == "fps") {
    char* end = nullptr;
    const double hz = std::strtod(value.c_str(), &end);
    if (value.empty() || *end != '\0' || !(hz > 0.0) || !std::isfinite(hz))
      return spec_error(spec, "fps=" + value + " is not a positive frame rate in Hz");
    options.frame_rate_hz = hz;
  } else if (key == "io") {
    if (value == "mmap")
      options.io = V4l2Io::kMmap;
    else if (value == "read")
      options.io = V4l2Io::kRead;
    else if (value == "auto")
      options.io = V4l2Io::kAuto;
    else
      return spec_error(spec, "io=" + value + " is neither mmap nor read");
  } else if (key == "crop") {
    if (!parse_ints(value, ',', numbers) || numbers.size() != 4 || numbers[0] < 0 ||
        numbers[1] < 0 || numbers[2] <= 0 || numbers[3] <= 0)
      return spec_error(
          spec, "crop=" + value + " is not X,Y,WIDTH,HEIGHT in pixels (a non-empty rectangle)");
    if (numbers[0] + std::int64_t{numbers[2]} > kMaxSidePx ||
        numbers[1] + std::int64_t{numbers[3]} > kMaxSidePx)
      return spec_error(spec, "crop=" + value + " reaches beyond any capture device's image (" +
                                  std::to_string(kMaxSidePx) + " pixels a side at most)");
    options.crop = PixelRect{numbers[0], numbers[1], numbers[2], numbers[3]};
  } else if (key == "buffers") {
    if (!parse_int(value, options.buffer_count) || options.buffer_count < kMinBuffers)
      return spec_error(spec, "buffers=" + value + " must be a count of at least " +
                                  std::to_string(kMinBuffers) +
                                  " (fewer lose frames while one is processed)");
  } else {
    return spec_error(spec, "unknown key '" + key + "'");
  }
  return Status::ok();
}

std::string rect_text(const PixelRect& r) {
  return std::to_string(r.x_px) + "," + std::to_string(r.y_px) + "," + std::to_string(r.width_px) +
         "," + std::to_string(r.height_px);
}

Status check_crop(const PixelRect& crop, int width_px, int height_px) {
  if (crop.x_px < 0 || crop.y_px < 0 || crop.width_px <= 0 || crop.height_px <= 0 ||
      std::int64_t{crop.x_px} + crop.width_px > width_px ||
      std::int64_t{crop.y_px} + crop.height_px > height_px)
    return Status::error("crop " + rect_text(crop) + " is not inside the " +
                         std::to_string(width_px) + "x" + std::to_string(height_px) +
                         " frame; choose the scanner's image area inside it");
  return Status::ok();
}

// libjpeg-turbo's TurboJPEG API. Webcam MJPG frames often leave out the Huffman tables; the
// decoder then takes the standard ones, as a JPEG viewer does.
Result<GreyImage> decode_mjpeg(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return Status::error("MJPG frame is empty");
  const std::unique_ptr<void, int (*)(tjhandle)> decoder(tjInitDecompress(), tjDestroy);
  if (!decoder) return Status::error(std::string("MJPG decoder: ") + tjGetErrorStr2(nullptr));
  const auto failed = [&](const char* what) {
    return Status::error("MJPG frame of " + std::to_string(size) + " bytes " + what + ": " +
                         tjGetErrorStr2(decoder.get()));
  };
  int width = 0, height = 0, subsampling = 0, colourspace = 0;
  if (tjDecompressHeader3(decoder.get(), data, static_cast<unsigned long>(size), &width, &height,
                          &subsampling, &colourspace) != 0)
    return failed("has no readable JPEG header");
  if (width <= 0 || height <= 0 || width > kMaxSidePx || height > kMaxSidePx)
    return Status::error("MJPG frame of " + std::to_string(size) + " bytes says it is " +
                         std::to_string(width) + "x" + std::to_string(height) +
                         " pixels, not a capture device's size");
  GreyImage image(width, height);
  if (tjDecompress2(decoder.get(), data, static_cast<unsigned long>(size), image.pixels.data(),
                    width, width, height, TJPF_GRAY, TJFLAG_ACCURATEDCT) != 0 &&
      tjGetErrorCode(decoder.get()) == TJERR_FATAL)
    return failed("does not decode");
  return image;
}

GreyImage crop_image(const GreyImage& image, const PixelRect& r) {
  GreyImage out(r.width_px, r.height_px);
  for (int j = 0; j < r.height_px; ++j)
    for (int i = 0; i < r.width_px; ++i) out.at(i, j) = image.at(r.x_px + i, r.y_px + j);
  return out;
}

}  // namespace

std::string fourcc_text(std::uint32_t fourcc) {
  std::string text;
  for (int k = 0; k < 4; ++k) {
    const char c = static_cast<char>((fourcc >> (8 * k)) & 0xFF);
    text += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
  }
  return text;
}

Result<V4l2Options> parse_v4l2_spec(const std::string& spec) {
  V4l2Options options;
  const std::size_t query = spec.find('?');
  options.device = spec.substr(0, query);
  if (options.device.empty()) return spec_error(spec, "no device node (e.g. /dev/video0)");
  if (query == std::string::npos) return options;
  for (const std::string_view item : split(std::string_view(spec).substr(query + 1), '&')) {
    if (item.empty()) continue;
    if (Status applied = apply_spec_item(spec, item, options); !applied) return applied;
  }
  return options;
}

Result<GreyImage> v4l2_to_grey(std::uint32_t fourcc, const std::uint8_t* data, std::size_t size,
                               int width_px, int height_px, int bytes_per_line,
                               const std::optional<PixelRect>& crop) {
  if (fourcc == V4L2_PIX_FMT_MJPEG) {
    auto image = decode_mjpeg(data, size);
    if (!image || !crop) return image;
    if (Status inside = check_crop(*crop, image->width, image->height); !inside) return inside;
    return crop_image(*image, *crop);
  }
  const int bytes_per_pixel =
      fourcc == V4L2_PIX_FMT_GREY ? 1 : (fourcc == V4L2_PIX_FMT_YUYV ? 2 : 0);
  if (bytes_per_pixel == 0)
    return Status::error("pixel format " + fourcc_text(fourcc) +
                         " is not one sonoshape reads (GREY, YUYV, MJPG)");
  if (width_px <= 0 || height_px <= 0) return Status::error("frame size is not positive");
  const std::size_t row_bytes = std::size_t(width_px) * bytes_per_pixel;
  const std::size_t stride = bytes_per_line > 0 ? std::size_t(bytes_per_line) : row_bytes;
  const std::size_t needed = stride * std::size_t(height_px - 1) + row_bytes;
  if (stride < row_bytes || size < needed)
    return Status::error(fourcc_text(fourcc) + " frame of " + std::to_string(size) +
                         " bytes is short: " + std::to_string(width_px) + "x" +
                         std::to_string(height_px) + " needs " + std::to_string(needed));
  const PixelRect r = crop.value_or(PixelRect{0, 0, width_px, height_px});
  if (Status inside = check_crop(r, width_px, height_px); !inside) return inside;
  // YUYV is Y0 U Y1 V: pixel i's grey level (luma) is byte 2 i of its row.
  GreyImage out(r.width_px, r.height_px);
  for (int j = 0; j < r.height_px; ++j) {
    const std::uint8_t* row = data + std::size_t(r.y_px + j) * stride;
    for (int i = 0; i < r.width_px; ++i)
      out.at(i, j) = row[std::size_t(r.x_px + i) * bytes_per_pixel];
  }
  return out;
}

V4l2Frames::V4l2Frames(V4l2Options options, std::shared_ptr<V4l2Device> device)
    : options_(std::move(options)), device_(std::move(device)) {}

V4l2Counters V4l2Frames::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

std::map<std::string, std::size_t> V4l2Frames::losses() const {
  const V4l2Counters c = counters();
  return {{"driver_dropped", c.driver_dropped},
          {"error_frames", c.error_frames},
          {"undecodable", c.undecodable}};
}

std::optional<V4l2Format> V4l2Frames::format() const {
  std::lock_guard lock(mutex_);
  return format_;
}

void V4l2Frames::update(const std::function<void(V4l2Counters&)>& change) {
  std::lock_guard lock(mutex_);
  change(counters_);
}

int V4l2Frames::xioctl(unsigned long request, void* arg) {
  int result = 0;
  do {
    result = device_->ioctl(fd_, request, arg);
  } while (result == -1 && errno == EINTR);
  return result;
}

Status V4l2Frames::open() {
  if (!device_) return Status::error(describe() + ": no device interface");
  if (options_.crop)
    if (Status valid = check_crop(*options_.crop, INT32_MAX, INT32_MAX); !valid)
      return Status::error(describe() + ": " + valid.message());
  return open_device();
}

void V4l2Frames::close() { release_device(); }

Status V4l2Frames::open_device() {
  fd_ = device_->open(options_.device, O_RDWR | O_NONBLOCK);
  if (fd_ < 0) {
    const int e = errno;
    const std::string fix =
        e == EACCES  ? "add the user to the 'video' group (usermod -aG video USER, log in again)"
        : e == EBUSY ? "another program is capturing from it; close that program"
                     : "check the grabber is plugged in; `sonoshape devices` lists capture devices";
    return Status::error(describe() + ": cannot open " + options_.device + " (" + errno_text(e) +
                         "); " + fix);
  }
  std::uint32_t fourcc = 0;
  Status status = query_capabilities();
  if (status) status = choose_format(fourcc);
  if (status) status = set_format(fourcc);
  if (status) {
    set_frame_rate();
    if (current_.io == V4l2Io::kMmap)
      status = start_mmap();
    else
      read_buffer_.assign(std::max<std::size_t>(current_.image_bytes, 1), 0);
  }
  if (!status) {
    release_device();
    return status;
  }
  last_sequence_.reset();
  std::lock_guard lock(mutex_);
  format_ = current_;
  return Status::ok();
}

Status V4l2Frames::query_capabilities() {
  v4l2_capability cap{};
  if (xioctl(VIDIOC_QUERYCAP, &cap) < 0)
    return Status::error(describe() + ": VIDIOC_QUERYCAP failed (" + errno_text(errno) + "); " +
                         options_.device + " is not a V4L2 device");
  // device_caps describe this node; capabilities the whole physical device (all its nodes).
  const std::uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
  current_ = V4l2Format{};
  current_.card.assign(reinterpret_cast<const char*>(cap.card),
                       strnlen(reinterpret_cast<const char*>(cap.card), sizeof cap.card));
  if (!(caps & V4L2_CAP_VIDEO_CAPTURE))
    return Status::error(describe() + ": '" + current_.card +
                         "' is not a video capture node (a grabber may have several "
                         "/dev/video nodes; `sonoshape devices` lists the capture ones)");
  V4l2Io io = options_.io;
  if (io == V4l2Io::kAuto) io = (caps & V4L2_CAP_STREAMING) ? V4l2Io::kMmap : V4l2Io::kRead;
  if (io == V4l2Io::kMmap && !(caps & V4L2_CAP_STREAMING))
    return Status::error(describe() + ": '" + current_.card + "' does not stream; use io=read");
  if (io == V4l2Io::kRead && !(caps & V4L2_CAP_READWRITE))
    return Status::error(describe() + ": '" + current_.card +
                         "' does not support read(); use io=mmap");
  current_.io = io;
  return Status::ok();
}

Status V4l2Frames::choose_format(std::uint32_t& fourcc) {
  std::vector<std::uint32_t> offered;
  for (std::uint32_t index = 0;; ++index) {
    v4l2_fmtdesc desc{};
    desc.index = index;
    desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(VIDIOC_ENUM_FMT, &desc) < 0) break;  // EINVAL past the last one
    offered.push_back(desc.pixelformat);
  }
  std::string offered_text;
  for (const std::uint32_t f : offered)
    offered_text += (offered_text.empty() ? "" : ", ") + fourcc_text(f);
  if (offered_text.empty()) offered_text = "none";
  const auto is_offered = [&](std::uint32_t f) {
    return std::find(offered.begin(), offered.end(), f) != offered.end();
  };
  if (!options_.pixel_format.empty()) {
    const auto wanted = fourcc_from_name(options_.pixel_format);
    if (!wanted || !is_offered(*wanted))
      return Status::error(describe() + ": '" + current_.card + "' offers no " +
                           options_.pixel_format + " frames; it offers " + offered_text +
                           "; choose one of these that sonoshape reads (GREY, YUYV, MJPG)");
    fourcc = *wanted;
    return Status::ok();
  }
  for (const std::uint32_t f : kReadable)
    if (is_offered(f)) {
      fourcc = f;
      return Status::ok();
    }
  return Status::error(describe() + ": '" + current_.card +
                       "' offers none of the formats sonoshape reads (GREY, YUYV, MJPG); it "
                       "offers " +
                       offered_text);
}

Status V4l2Frames::set_format(std::uint32_t fourcc) {
  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(VIDIOC_G_FMT, &fmt) < 0)
    return Status::error(describe() + ": VIDIOC_G_FMT failed (" + errno_text(errno) + ")");
  if (options_.width_px > 0) {
    fmt.fmt.pix.width = static_cast<std::uint32_t>(options_.width_px);
    fmt.fmt.pix.height = static_cast<std::uint32_t>(options_.height_px);
  }
  fmt.fmt.pix.pixelformat = fourcc;
  fmt.fmt.pix.field = V4L2_FIELD_ANY;
  fmt.fmt.pix.bytesperline = 0;  // the driver computes stride and size
  fmt.fmt.pix.sizeimage = 0;
  if (xioctl(VIDIOC_S_FMT, &fmt) < 0)
    return Status::error(describe() + ": the driver refused " + fourcc_text(fourcc) + " " +
                         std::to_string(fmt.fmt.pix.width) + "x" +
                         std::to_string(fmt.fmt.pix.height) + " (" + errno_text(errno) + ")");
  // What the driver granted, read back rather than trusted from S_FMT's reply.
  if (xioctl(VIDIOC_G_FMT, &fmt) < 0)
    return Status::error(describe() + ": VIDIOC_G_FMT failed (" + errno_text(errno) + ")");
  const v4l2_pix_format& pix = fmt.fmt.pix;
  if (pix.pixelformat != fourcc)
    return Status::error(describe() + ": asked for " + fourcc_text(fourcc) +
                         " frames, the driver granted " + fourcc_text(pix.pixelformat) +
                         "; choose a format it grants (`sonoshape devices`)");
  current_.fourcc = fourcc;
  current_.width_px = static_cast<int>(pix.width);
  current_.height_px = static_cast<int>(pix.height);
  current_.bytes_per_line = static_cast<int>(pix.bytesperline);
  current_.image_bytes = pix.sizeimage;
  if (current_.image_bytes == 0)  // MJPG needs at most about 2 bytes a pixel
    current_.image_bytes = std::size_t(pix.width) * pix.height * 2;
  if (options_.width_px > 0 &&
      (current_.width_px != options_.width_px || current_.height_px != options_.height_px))
    log_warning(describe() + ": asked for " + std::to_string(options_.width_px) + "x" +
                std::to_string(options_.height_px) + ", the driver granted " +
                std::to_string(current_.width_px) + "x" + std::to_string(current_.height_px));
  if (options_.crop && fourcc != V4L2_PIX_FMT_MJPEG)
    if (Status inside = check_crop(*options_.crop, current_.width_px, current_.height_px); !inside)
      return Status::error(describe() + ": " + inside.message());
  return Status::ok();
}

void V4l2Frames::set_frame_rate() {
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(VIDIOC_G_PARM, &parm) < 0) return;  // the driver does not say: rate unknown
  if (options_.frame_rate_hz > 0.0) {
    if (parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME) {
      parm.parm.capture.timeperframe.numerator = 1000;
      parm.parm.capture.timeperframe.denominator =
          static_cast<std::uint32_t>(std::lround(options_.frame_rate_hz * 1000.0));
      if (xioctl(VIDIOC_S_PARM, &parm) < 0 || xioctl(VIDIOC_G_PARM, &parm) < 0)
        log_warning(describe() + ": the driver refused " + std::to_string(options_.frame_rate_hz) +
                    " fps (" + errno_text(errno) + ")");
    } else {
      log_warning(describe() + ": the driver cannot set the frame rate; capturing at its own");
    }
  }
  const v4l2_fract& period = parm.parm.capture.timeperframe;
  if (period.numerator > 0) current_.frame_rate_hz = double(period.denominator) / period.numerator;
}

Status V4l2Frames::start_mmap() {
  v4l2_requestbuffers request{};
  request.count = static_cast<std::uint32_t>(std::max(kMinBuffers, options_.buffer_count));
  request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  request.memory = V4L2_MEMORY_MMAP;
  if (xioctl(VIDIOC_REQBUFS, &request) < 0)
    return Status::error(describe() + ": VIDIOC_REQBUFS failed (" + errno_text(errno) +
                         "); the device may not support MMAP streaming: use io=read");
  buffers_.resize(request.count);  // before mapping: release_device() undoes what was done
  if (request.count < 2)
    return Status::error(describe() + ": the driver granted " + std::to_string(request.count) +
                         " buffer(s); at least 2 are needed (close other programs using it)");
  for (std::uint32_t index = 0; index < request.count; ++index) {
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    buffer.index = index;
    if (xioctl(VIDIOC_QUERYBUF, &buffer) < 0)
      return Status::error(describe() + ": VIDIOC_QUERYBUF failed (" + errno_text(errno) + ")");
    void* address = device_->mmap(buffer.length, fd_, static_cast<off_t>(buffer.m.offset));
    if (address == MAP_FAILED)
      return Status::error(describe() + ": mmap of buffer " + std::to_string(index) + " failed (" +
                           errno_text(errno) + ")");
    buffers_[index] = Buffer{address, buffer.length};
    if (xioctl(VIDIOC_QBUF, &buffer) < 0)
      return Status::error(describe() + ": VIDIOC_QBUF failed (" + errno_text(errno) + ")");
  }
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (xioctl(VIDIOC_STREAMON, &type) < 0)
    return Status::error(describe() + ": VIDIOC_STREAMON failed (" + errno_text(errno) + ")");
  streaming_ = true;
  current_.buffers = static_cast<int>(request.count);
  return Status::ok();
}

// Undoes open_device() in reverse; after an unplug every call may fail, which changes nothing.
void V4l2Frames::release_device() {
  if (fd_ < 0) return;
  if (streaming_) {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    xioctl(VIDIOC_STREAMOFF, &type);
    streaming_ = false;
  }
  for (const Buffer& buffer : buffers_)
    if (buffer.address) device_->munmap(buffer.address, buffer.length);
  if (!buffers_.empty()) {
    v4l2_requestbuffers request{};
    request.count = 0;
    request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    request.memory = V4L2_MEMORY_MMAP;
    xioctl(VIDIOC_REQBUFS, &request);
    buffers_.clear();
  }
  device_->close(fd_);
  fd_ = -1;
}

Result<Polled> V4l2Frames::poll(Frame& frame) {
  if (fd_ < 0) return try_reopen();
  const Result<Read> got = current_.io == V4l2Io::kMmap ? dequeue_mmap(frame) : read_frame(frame);
  if (!got) return got.status();
  return *got == Read::kFrame ? Polled::kItem : Polled::kNothing;
}

Result<V4l2Frames::Read> V4l2Frames::wait_readable() {
  if (device_->poll_in(fd_, options_.poll_timeout_ms) < 0 && errno != EINTR)
    return Status::error(describe() + ": poll failed (" + errno_text(errno) + ")");
  return Read::kNothing;  // the next poll() takes the frame, if one came
}

Result<V4l2Frames::Read> V4l2Frames::dequeue_mmap(Frame& frame) {
  v4l2_buffer buffer{};
  buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  buffer.memory = V4L2_MEMORY_MMAP;
  if (xioctl(VIDIOC_DQBUF, &buffer) < 0) {
    const int e = errno;
    if (e == EAGAIN) return wait_readable();
    if (e == ENODEV) return mark_unplugged("VIDIOC_DQBUF");
    if (e == EIO) {  // a transient fault (e.g. signal loss): that frame is gone
      update([](V4l2Counters& c) { ++c.error_frames; });
      count_lost(1);
      return restart_stream();
    }
    return Status::error(describe() + ": VIDIOC_DQBUF failed (" + errno_text(e) + ")");
  }
  if (buffer.index >= buffers_.size())
    return Status::error(describe() + ": the driver returned buffer " +
                         std::to_string(buffer.index) + " of " + std::to_string(buffers_.size()));
  note_sequence(buffer.sequence);
  bool delivered = false;
  if (buffer.flags & V4L2_BUF_FLAG_ERROR) {
    update([](V4l2Counters& c) { ++c.error_frames; });
    count_lost(1);
  } else {
    const Buffer& mapped = buffers_[buffer.index];
    const bool monotonic =
        (buffer.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
    const double t_s =
        monotonic ? double(buffer.timestamp.tv_sec) + 1e-6 * double(buffer.timestamp.tv_usec)
                  : clock_monotonic_s();
    note_timestamps(monotonic);
    const std::size_t used = buffer.bytesused > 0
                                 ? std::min<std::size_t>(buffer.bytesused, mapped.length)
                                 : mapped.length;
    delivered = deliver(static_cast<const std::uint8_t*>(mapped.address), used, t_s, frame);
  }
  // Back to the driver at once: it fills the other buffers meanwhile.
  if (xioctl(VIDIOC_QBUF, &buffer) < 0) {
    const int e = errno;
    if (e != ENODEV)
      return Status::error(describe() + ": VIDIOC_QBUF failed (" + errno_text(e) + ")");
    mark_unplugged("VIDIOC_QBUF");  // the frame already copied is still good
  }
  return delivered ? Read::kFrame : Read::kNothing;
}

// After EIO the driver may have kept a buffer, or stopped capturing: STREAMOFF takes every
// buffer back, and all of them are queued again.
Result<V4l2Frames::Read> V4l2Frames::restart_stream() {
  int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  bool ok = xioctl(VIDIOC_STREAMOFF, &type) == 0;
  for (std::uint32_t index = 0; ok && index < buffers_.size(); ++index) {
    v4l2_buffer buffer{};
    buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer.memory = V4L2_MEMORY_MMAP;
    buffer.index = index;
    ok = xioctl(VIDIOC_QBUF, &buffer) == 0;
  }
  if (ok) ok = xioctl(VIDIOC_STREAMON, &type) == 0;
  if (ok) return Read::kNothing;
  const int e = errno;
  if (e == ENODEV) return mark_unplugged("restarting the stream after EIO");
  return Status::error(describe() + ": restarting the stream after EIO failed (" + errno_text(e) +
                       ")");
}

Result<V4l2Frames::Read> V4l2Frames::read_frame(Frame& frame) {
  ssize_t n = 0;
  do {
    n = device_->read(fd_, read_buffer_.data(), read_buffer_.size());
  } while (n < 0 && errno == EINTR);
  if (n < 0) {
    const int e = errno;
    if (e == EAGAIN) return wait_readable();
    if (e == ENODEV) return mark_unplugged("read");
    if (e == EIO) {
      update([](V4l2Counters& c) { ++c.error_frames; });
      count_lost(1);
      return Read::kNothing;
    }
    return Status::error(describe() + ": read failed (" + errno_text(e) + ")");
  }
  if (n == 0) return wait_readable();
  // read() carries no driver timestamp: the frame is stamped when it arrives.
  note_timestamps(false);
  const bool delivered = deliver(read_buffer_.data(), std::size_t(n), clock_monotonic_s(), frame);
  return delivered ? Read::kFrame : Read::kNothing;
}

void V4l2Frames::note_sequence(std::uint32_t sequence) {
  if (last_sequence_ && sequence > *last_sequence_ + 1) {
    const std::size_t gap = sequence - *last_sequence_ - 1;
    update([gap](V4l2Counters& c) { c.driver_dropped += gap; });
    count_lost(gap);
  }
  last_sequence_ = sequence;
}

void V4l2Frames::note_timestamps(bool from_driver) {
  if (current_.driver_timestamps == from_driver) return;
  current_.driver_timestamps = from_driver;
  std::lock_guard lock(mutex_);
  if (format_) format_->driver_timestamps = from_driver;
}

bool V4l2Frames::deliver(const std::uint8_t* data, std::size_t size, double timestamp_s,
                         Frame& frame) {
  auto grey = v4l2_to_grey(current_.fourcc, data, size, current_.width_px, current_.height_px,
                           current_.bytes_per_line, options_.crop);
  if (!grey) {
    update([](V4l2Counters& c) { ++c.undecodable; });
    count_lost(1);
    set_condition("frames do not convert: " + grey.message());
    undecodable_ = true;
    return false;
  }
  if (undecodable_) {
    set_condition("");
    undecodable_ = false;
  }
  frame.image = std::move(*grey);
  frame.timestamp_s = timestamp_s;
  frame.index = next_index_++;
  update([](V4l2Counters& c) { ++c.delivered; });
  return true;
}

V4l2Frames::Read V4l2Frames::mark_unplugged(const std::string& where) {
  release_device();
  update([](V4l2Counters& c) { ++c.unplugs; });
  reopen_wait_s_ = options_.reopen_first_s;
  next_reopen_s_ = clock_monotonic_s() + reopen_wait_s_;
  const std::string text = options_.device + " vanished (ENODEV at " + where +
                           "; unplugged?): reopening it when it comes back";
  set_condition(text);
  log_warning(describe() + ": " + text);
  return Read::kUnplugged;
}

Result<Polled> V4l2Frames::try_reopen() {
  const double wait_s = next_reopen_s_ - clock_monotonic_s();
  if (wait_s > 0.0) {  // short naps: stop() is honoured quickly
    std::this_thread::sleep_for(std::chrono::duration<double>(std::min(wait_s, 0.05)));
    return Polled::kNothing;
  }
  if (const Status opened = open_device(); !opened) {
    reopen_wait_s_ = std::min(2.0 * reopen_wait_s_, options_.reopen_max_s);
    next_reopen_s_ = clock_monotonic_s() + reopen_wait_s_;
    set_condition(options_.device + " vanished; reopening it (last try: " + opened.message() + ")");
    return Polled::kNothing;
  }
  update([](V4l2Counters& c) { ++c.reopens; });
  set_condition("");
  log_info(describe() + ": " + options_.device + " is back; capture resumed");
  return Polled::kNothing;
}

}  // namespace sonoshape::acquisition
