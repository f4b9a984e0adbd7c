#pragma once
// Shared by the fuzz targets that speak to a server in their own process over loopback: one
// client connection that sends the input in pieces and reads the answer until the server closes.
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>

namespace sonoshape::fuzz {

/// How long a server may take to answer or close after the client's last byte; longer is a
/// stalled server thread, a finding.
inline constexpr double kStallS = 5.0;

inline double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// A connected TCP socket to 127.0.0.1:`port`, or -1 (refused, e.g. at a connection cap).
inline int connect_loopback(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0)
    return fd;
  if (fd >= 0) ::close(fd);
  return -1;
}

/// Sends `size` bytes in pieces of `piece` bytes (so that a server sees headers split across
/// reads); stops at the first failed send.
inline void send_in_pieces(int fd, const std::uint8_t* data, std::size_t size, std::size_t piece) {
  for (std::size_t at = 0; at < size; at += piece) {
    const std::size_t n = std::min(piece, size - at);
    if (::send(fd, data + at, n, MSG_NOSIGNAL) != static_cast<ssize_t>(n)) return;
  }
}

/// Reads until the server closes the connection (true), until `until` is in what was read
/// (true, the connection left open), or for kStallS (false). `first_line`: the answer's first
/// line, when it has one.
inline bool read_until(int fd, std::string& first_line, const std::string& until = {}) {
  const double deadline_s = now_s() + kStallS;
  std::string got;
  char buffer[65536];
  while (now_s() < deadline_s) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) return true;  // closed (or reset) by the server
    if (got.size() < 4096) got.append(buffer, static_cast<std::size_t>(n));
    if (first_line.empty() && got.find("\r\n") != std::string::npos)
      first_line = got.substr(0, got.find("\r\n"));
    if (!until.empty() && got.find(until) != std::string::npos) return true;
  }
  return false;
}

}  // namespace sonoshape::fuzz
