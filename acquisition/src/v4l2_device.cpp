#include "sonoshape/acquisition/v4l2_device.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

namespace sonoshape::acquisition {
namespace {

class SystemV4l2Device final : public V4l2Device {
 public:
  int open(const std::string& path, int flags) override { return ::open(path.c_str(), flags); }
  int close(int fd) override { return ::close(fd); }
  int ioctl(int fd, unsigned long request, void* arg) override { return ::ioctl(fd, request, arg); }
  void* mmap(std::size_t length, int fd, off_t offset) override {
    return ::mmap(nullptr, length, PROT_READ | PROT_WRITE, MAP_SHARED, fd, offset);
  }
  int munmap(void* address, std::size_t length) override { return ::munmap(address, length); }
  int poll_in(int fd, int timeout_ms) override {
    pollfd entry{fd, POLLIN, 0};
    return ::poll(&entry, 1, timeout_ms);
  }
  ssize_t read(int fd, void* buffer, std::size_t size) override { return ::read(fd, buffer, size); }
};

}  // namespace

std::shared_ptr<V4l2Device> system_v4l2_device() { return std::make_shared<SystemV4l2Device>(); }

}  // namespace sonoshape::acquisition
