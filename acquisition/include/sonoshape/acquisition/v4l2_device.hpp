#pragma once
// The system calls the V4L2 frame grabber makes, behind an interface: the real ones
// (system_v4l2_device()) at the bedside, a fake in tests. umockdev emulates ioctl() and read()
// on a fake device node but neither mmap() nor poll(), so the MMAP streaming path is tested
// through a fake of this interface; the READ path runs against umockdev with the real calls.
#include <sys/types.h>

#include <cstddef>
#include <memory>
#include <string>

namespace sonoshape::acquisition {

/// The POSIX calls of a V4L2 capture, with their POSIX contracts: a failing call returns -1
/// (mmap: MAP_FAILED) and sets errno. Implementations must be thread-compatible (one source
/// thread calls them).
class V4l2Device {
 public:
  virtual ~V4l2Device() = default;
  /// open(2) of a device node; returns the descriptor.
  virtual int open(const std::string& path, int flags) = 0;
  /// close(2).
  virtual int close(int fd) = 0;
  /// ioctl(2) with a pointer argument (every V4L2 request takes one).
  virtual int ioctl(int fd, unsigned long request, void* arg) = 0;
  /// mmap(2) of `length` bytes of the device at `offset` (V4L2's m.offset), shared, read-write.
  virtual void* mmap(std::size_t length, int fd, off_t offset) = 0;
  /// munmap(2).
  virtual int munmap(void* address, std::size_t length) = 0;
  /// poll(2) of one descriptor for input: > 0 ready, 0 timed out.
  virtual int poll_in(int fd, int timeout_ms) = 0;
  /// read(2).
  virtual ssize_t read(int fd, void* buffer, std::size_t size) = 0;
};

/// The real system calls.
std::shared_ptr<V4l2Device> system_v4l2_device();

}  // namespace sonoshape::acquisition
