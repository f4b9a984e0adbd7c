#include "sonoshape/core/input_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace sonoshape {
namespace {

std::string kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "a folder";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

std::string start(const std::filesystem::path& path, std::string_view what) {
  return "cannot read " + std::string(what) + " " + path.string() + ": ";
}

Status not_regular(const std::filesystem::path& path, std::string_view what, mode_t mode) {
  return Status::error(start(path, what) + "it is " + kind_of(mode) +
                       ", not a regular file; give the path of a file (devices and pipes are "
                       "not read: they may never end)");
}

Status open_failed(const std::filesystem::path& path, std::string_view what, int error) {
  if (error == ENOENT) return Status::error(start(path, what) + "no such file; check the path");
  const std::string fix = error == EACCES ? "; check the file's permissions" : "";
  return Status::error(start(path, what) + std::strerror(error) + fix);
}

}  // namespace

Status check_input_file(const std::filesystem::path& path, std::string_view what) {
  struct stat info {};
  if (::stat(path.c_str(), &info) != 0) return open_failed(path, what, errno);
  if (!S_ISREG(info.st_mode)) return not_regular(path, what, info.st_mode);
  return Status::ok();
}

Result<std::string> read_input_file(const std::filesystem::path& path, std::string_view what) {
  // Non-blocking: opening a FIFO for reading would otherwise wait for a writer.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return open_failed(path, what, errno);
  struct stat info {};
  Status status = ::fstat(fd, &info) != 0  ? open_failed(path, what, errno)
                  : !S_ISREG(info.st_mode) ? not_regular(path, what, info.st_mode)
                                           : Status::ok();
  std::string bytes;
  if (status) {
    // st_size is 0 for /proc files, which are read to their end all the same.
    bytes.reserve(static_cast<std::size_t>(info.st_size));
    char buffer[1 << 16];
    for (;;) {
      const ssize_t got = ::read(fd, buffer, sizeof buffer);
      if (got == 0) break;
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) {
        status = Status::error(start(path, what) + "read error: " + std::strerror(errno));
        break;
      }
      bytes.append(buffer, static_cast<std::size_t>(got));
    }
  }
  ::close(fd);
  if (!status) return status;
  return bytes;
}

}  // namespace sonoshape
