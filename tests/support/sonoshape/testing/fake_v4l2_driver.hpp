#pragma once
// A V4L2 driver behind the system-call seam of the grabber backend (v4l2_device.hpp), scripted
// by a test: the MMAP streaming path, which umockdev cannot emulate (no mmap(), no poll()).
// Each DQBUF takes the next scripted event: a filled buffer (bytes, sequence, timestamp, flags)
// or an errno; with none it answers EAGAIN, as a non-blocking device does between frames.
// set_present(false) unplugs it: every ioctl fails with ENODEV and open with ENOENT.
#include <linux/videodev2.h>
#include <sys/mman.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "sonoshape/acquisition/v4l2_device.hpp"

namespace sonoshape::testing {

class FakeV4l2Driver final : public acquisition::V4l2Device {
 public:
  /// A device at `path` whose largest (and initial) size is width x height.
  explicit FakeV4l2Driver(std::string path = "/dev/video7", std::uint32_t width = 64,
                          std::uint32_t height = 48)
      : max_width(width), max_height(height), path_(std::move(path)) {
    pix_.width = width;
    pix_.height = height;
    pix_.pixelformat = V4L2_PIX_FMT_YUYV;
  }

  struct Filled {
    std::vector<std::uint8_t> bytes;
    std::uint32_t sequence = 0;
    double timestamp_s = 0.0;
    std::uint32_t flags = V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
  };
  using Event = std::variant<Filled, int>;  // int: the errno DQBUF fails with

  std::vector<std::uint32_t> offered = {V4L2_PIX_FMT_YUYV};
  std::uint32_t max_width, max_height;  // the driver grants at most this size
  std::uint32_t granted_buffers = 5;    // whatever count is asked for (0 aside)

  void push(Event event) {
    std::lock_guard lock(mutex_);
    events_.push_back(std::move(event));
  }
  void set_present(bool present) {
    std::lock_guard lock(mutex_);
    present_ = present;
  }
  int maps() const {
    std::lock_guard lock(mutex_);
    return maps_;
  }
  int open_fds() const {
    std::lock_guard lock(mutex_);
    return open_fds_;
  }
  int released_buffers() const {
    std::lock_guard lock(mutex_);
    return reqbufs_zero_;
  }
  /// STREAMON calls so far.
  int stream_starts() const {
    std::lock_guard lock(mutex_);
    return stream_starts_;
  }
  bool streaming() const {
    std::lock_guard lock(mutex_);
    return streaming_;
  }

  int open(const std::string& path, int) override {
    std::lock_guard lock(mutex_);
    if (!present_ || path != path_) return fail(ENOENT);
    ++open_fds_;
    return 7;
  }
  int close(int) override {
    std::lock_guard lock(mutex_);
    --open_fds_;
    return 0;
  }
  void* mmap(std::size_t length, int, off_t offset) override {
    std::lock_guard lock(mutex_);
    const std::size_t index = static_cast<std::size_t>(offset) / kPage;
    if (index >= buffers_.size() || length != buffers_[index].size()) {
      errno = EINVAL;
      return MAP_FAILED;
    }
    ++maps_;
    return buffers_[index].data();
  }
  int munmap(void*, std::size_t) override {
    std::lock_guard lock(mutex_);
    --maps_;
    return 0;
  }
  int poll_in(int, int) override {
    {
      std::lock_guard lock(mutex_);
      if (!events_.empty() || !present_) return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    return 0;
  }
  ssize_t read(int, void*, std::size_t) override { return fail(EINVAL); }

  int ioctl(int, unsigned long request, void* arg) override {
    std::lock_guard lock(mutex_);
    if (!present_) return fail(ENODEV);
    switch (request) {
      case VIDIOC_QUERYCAP: {
        auto* cap = static_cast<v4l2_capability*>(arg);
        std::strcpy(reinterpret_cast<char*>(cap->card), "fake grabber");
        cap->capabilities = V4L2_CAP_DEVICE_CAPS | V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_META_CAPTURE |
                            V4L2_CAP_STREAMING;
        cap->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
        return 0;
      }
      case VIDIOC_ENUM_FMT: {
        auto* desc = static_cast<v4l2_fmtdesc*>(arg);
        if (desc->index >= offered.size()) return fail(EINVAL);
        desc->pixelformat = offered[desc->index];
        return 0;
      }
      case VIDIOC_G_FMT:
        static_cast<v4l2_format*>(arg)->fmt.pix = pix_;
        return 0;
      case VIDIOC_S_FMT: {
        v4l2_pix_format& pix = static_cast<v4l2_format*>(arg)->fmt.pix;
        if (std::find(offered.begin(), offered.end(), pix.pixelformat) == offered.end())
          pix.pixelformat = offered.front();
        pix.width = std::min(pix.width, max_width);
        pix.height = std::min(pix.height, max_height);
        const std::uint32_t bpp = pix.pixelformat == V4L2_PIX_FMT_GREY ? 1 : 2;
        pix.bytesperline = pix.width * bpp + 8;  // padded rows, as many drivers have
        pix.sizeimage = pix.bytesperline * pix.height;
        pix_ = pix;
        return 0;
      }
      case VIDIOC_G_PARM:
      case VIDIOC_S_PARM: {
        auto* parm = static_cast<v4l2_streamparm*>(arg);
        if (request == VIDIOC_S_PARM) period_ = parm->parm.capture.timeperframe;
        parm->parm.capture.capability = V4L2_CAP_TIMEPERFRAME;
        parm->parm.capture.timeperframe = period_;
        return 0;
      }
      case VIDIOC_REQBUFS: {
        auto* req = static_cast<v4l2_requestbuffers*>(arg);
        if (req->memory != V4L2_MEMORY_MMAP) return fail(EINVAL);
        if (req->count == 0) {
          ++reqbufs_zero_;
          buffers_.clear();
          return 0;
        }
        req->count = granted_buffers;
        buffers_.assign(granted_buffers, std::vector<std::uint8_t>(pix_.sizeimage));
        queued_.clear();
        return 0;
      }
      case VIDIOC_QUERYBUF: {
        auto* buf = static_cast<v4l2_buffer*>(arg);
        if (buf->index >= buffers_.size()) return fail(EINVAL);
        buf->length = static_cast<std::uint32_t>(buffers_[buf->index].size());
        buf->m.offset = buf->index * kPage;
        return 0;
      }
      case VIDIOC_QBUF:
        queued_.push_back(static_cast<v4l2_buffer*>(arg)->index);
        return 0;
      case VIDIOC_DQBUF:
        return dequeue(*static_cast<v4l2_buffer*>(arg));
      case VIDIOC_STREAMON:
        ++stream_starts_;
        streaming_ = true;
        return 0;
      case VIDIOC_STREAMOFF:  // the driver takes every buffer back
        streaming_ = false;
        queued_.clear();
        return 0;
      default:
        return fail(ENOTTY);
    }
  }

 private:
  static constexpr std::size_t kPage = 4096;
  static int fail(int error) {
    errno = error;
    return -1;
  }
  int dequeue(v4l2_buffer& buf) {
    if (!streaming_ || events_.empty() || queued_.empty()) return fail(EAGAIN);
    Event event = std::move(events_.front());
    events_.pop_front();
    if (const int* error = std::get_if<int>(&event)) return fail(*error);
    const Filled& f = std::get<Filled>(event);
    buf.index = queued_.front();
    queued_.pop_front();
    std::vector<std::uint8_t>& target = buffers_[buf.index];
    std::copy_n(f.bytes.begin(), std::min(f.bytes.size(), target.size()), target.begin());
    buf.bytesused = static_cast<std::uint32_t>(f.bytes.size());
    buf.sequence = f.sequence;
    buf.flags = f.flags;
    buf.timestamp.tv_sec = static_cast<time_t>(f.timestamp_s);
    buf.timestamp.tv_usec = static_cast<suseconds_t>(
        std::llround((f.timestamp_s - static_cast<double>(buf.timestamp.tv_sec)) * 1e6));
    return 0;
  }

  mutable std::mutex mutex_;
  std::deque<Event> events_;
  bool present_ = true;
  std::string path_;
  v4l2_pix_format pix_{};
  v4l2_fract period_{1, 30};
  std::vector<std::vector<std::uint8_t>> buffers_;
  std::deque<std::uint32_t> queued_;
  int maps_ = 0;
  int open_fds_ = 0;
  int reqbufs_zero_ = 0;
  bool streaming_ = false;
  int stream_starts_ = 0;
};

}  // namespace sonoshape::testing
