#pragma once
// V4L2 frame grabber (Linux): the scanner's video output through a USB grabber, as
// `--source v4l2:/dev/videoN?size=WxH&format=YUYV&fps=30&io=mmap&crop=x,y,w,h`.
// Frames carry the driver's timestamps (CLOCK_MONOTONIC, the clock tracker samples are stamped
// with), not their arrival time; frames the driver skipped (gaps in `sequence`) and frames it
// flagged broken are counted; an unplugged grabber is reopened when it comes back.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/acquisition/frame_source.hpp"
#include "sonoshape/acquisition/v4l2_device.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition {

/// How frames leave the driver: MMAP streaming (the driver fills buffers we share with it)
/// or read(2) (a copy per frame; some grabbers offer only this). kAuto: MMAP when the device
/// streams, else read.
enum class V4l2Io { kAuto, kMmap, kRead };

/// A rectangle of pixels: columns x_px .. x_px + width_px - 1, rows y_px .. y_px + height_px - 1.
struct PixelRect {
  int x_px = 0;
  int y_px = 0;
  int width_px = 0;
  int height_px = 0;
  bool operator==(const PixelRect&) const = default;
};

/// What to capture. Zero / empty fields keep the driver's choice.
struct V4l2Options {
  std::string device;  ///< the device node, e.g. "/dev/video0"
  int width_px = 0;    ///< capture size asked for (the driver may grant another: see format())
  int height_px = 0;
  /// "GREY" (alias "Y8"), "YUYV" or "MJPG" (alias "MJPEG"); empty: the first of these the
  /// device offers, in that order.
  std::string pixel_format;
  double frame_rate_hz = 0.0;  ///< asked for with VIDIOC_S_PARM; 0: the driver's
  V4l2Io io = V4l2Io::kAuto;
  /// The B-mode image inside the captured screen (a grabber captures the scanner's whole
  /// video output, UI included); frames are this rectangle, so the image-to-probe calibration
  /// applies to the cropped image. None: the whole frame.
  std::optional<PixelRect> crop;
  int buffer_count = 4;          ///< MMAP buffers asked for (at least 4; the driver may grant more)
  int poll_timeout_ms = 100;     ///< how long one poll() waits for a frame
  double reopen_first_s = 0.25;  ///< first wait before reopening an unplugged device (s)
  double reopen_max_s = 2.0;     ///< the wait doubles up to this (s)
};

/// Parses the part of `--source v4l2:SPEC` after "v4l2:": a device node and an optional query
/// `?size=WxH&format=FOURCC&fps=HZ&io=mmap|read&crop=X,Y,W,H&buffers=N`. Fails naming the key
/// or value that is wrong and the accepted form.
Result<V4l2Options> parse_v4l2_spec(const std::string& spec);

/// The four characters of a V4L2 pixel format code ("YUYV").
std::string fourcc_text(std::uint32_t fourcc);

/// Converts one captured frame to grey levels, cropped to `crop` (none: all).
/// `data`/`size`: the bytes the driver filled (bytesused); `bytes_per_line`: the row stride of
/// GREY/YUYV (0: packed). GREY is copied, YUYV gives its Y plane, MJPG is decoded to grey with
/// OpenCV (the decoded size wins over width/height). Fails for other formats, short buffers,
/// undecodable JPEG data, and a crop outside the image.
Result<GreyImage> v4l2_to_grey(std::uint32_t fourcc, const std::uint8_t* data, std::size_t size,
                               int width_px, int height_px, int bytes_per_line,
                               const std::optional<PixelRect>& crop);

/// What the driver granted when the device was (last) opened.
struct V4l2Format {
  std::string card;  ///< VIDIOC_QUERYCAP's card name
  std::uint32_t fourcc = 0;
  int width_px = 0;
  int height_px = 0;
  int bytes_per_line = 0;
  std::size_t image_bytes = 0;  ///< sizeimage
  double frame_rate_hz = 0.0;   ///< 0: the driver does not say
  V4l2Io io = V4l2Io::kRead;    ///< kMmap or kRead
  int buffers = 0;              ///< MMAP buffers granted
  /// false: the driver's timestamps are not CLOCK_MONOTONIC (or READ I/O, which has none), and
  /// frames are stamped with CLOCK_MONOTONIC when they arrive.
  bool driver_timestamps = false;
};

/// Why frames were lost, beyond what StreamSource::dropped() counts as a whole.
struct V4l2Counters {
  std::size_t delivered = 0;       ///< frames handed to the stream
  std::size_t driver_dropped = 0;  ///< gaps in the driver's sequence numbers
  std::size_t error_frames = 0;    ///< V4L2_BUF_FLAG_ERROR buffers and EIO
  std::size_t undecodable = 0;     ///< frames that did not convert (bad JPEG, short buffer)
  std::size_t unplugs = 0;         ///< times the device vanished (ENODEV)
  std::size_t reopens = 0;         ///< times it came back and capture resumed
};

/// A V4L2 capture device as a FrameBackend. `Frame::timestamp_s` is the driver's timestamp in
/// CLOCK_MONOTONIC seconds (arrival time when the driver gives none), `Frame::index` counts
/// delivered frames from 0. Lost frames (driver gaps, error buffers, undecodable frames) are
/// counted in dropped() and, by reason, in counters(). When the device vanishes (ENODEV) the
/// source stays running, reports it in condition(), and reopens the device with the same
/// options, retrying with a doubling wait, until it comes back or stop() is called.
class V4l2Frames final : public FrameBackend {
 public:
  /// Captures with `options` through `device` (the real system calls unless a test fakes them).
  explicit V4l2Frames(V4l2Options options,
                      std::shared_ptr<V4l2Device> device = system_v4l2_device());

  /// "v4l2:/dev/videoN".
  std::string describe() const override { return "v4l2:" + options_.device; }
  /// Thread-safe snapshot of the loss counters.
  V4l2Counters counters() const;
  /// driver_dropped, error_frames and undecodable of counters().
  std::map<std::string, std::size_t> losses() const override;
  /// What the driver granted at the last (re)open; none before the first.
  std::optional<V4l2Format> format() const;

 protected:
  Status open() override;
  Result<Polled> poll(Frame& frame) override;
  void close() override;

 private:
  struct Buffer {
    void* address = nullptr;
    std::size_t length = 0;
  };
  enum class Read { kFrame, kNothing, kUnplugged };

  Status open_device();
  Status query_capabilities();
  Status choose_format(std::uint32_t& fourcc);
  Status set_format(std::uint32_t fourcc);
  void set_frame_rate();
  Status start_mmap();
  void release_device();
  Result<Read> dequeue_mmap(Frame& frame);
  Result<Read> restart_stream();
  Result<Read> read_frame(Frame& frame);
  Result<Read> wait_readable();
  Result<Polled> try_reopen();
  Read mark_unplugged(const std::string& where);
  void note_sequence(std::uint32_t sequence);
  void note_timestamps(bool from_driver);
  bool deliver(const std::uint8_t* data, std::size_t size, double timestamp_s, Frame& frame);
  int xioctl(unsigned long request, void* arg);
  void update(const std::function<void(V4l2Counters&)>& change);

  V4l2Options options_;
  std::shared_ptr<V4l2Device> device_;
  // The source thread's own state (open, poll, close run there).
  int fd_ = -1;
  V4l2Format current_;
  std::vector<Buffer> buffers_;
  std::vector<std::uint8_t> read_buffer_;
  bool streaming_ = false;
  std::optional<std::uint32_t> last_sequence_;
  std::int64_t next_index_ = 0;
  double reopen_wait_s_ = 0.0;
  double next_reopen_s_ = 0.0;
  bool undecodable_ = false;
  mutable std::mutex mutex_;  // guards counters_ and format_
  V4l2Counters counters_;
  std::optional<V4l2Format> format_;
};
/// The stream of a V4l2Frames.
using V4l2FrameSource = SourceOf<V4l2Frames>;

}  // namespace sonoshape::acquisition
