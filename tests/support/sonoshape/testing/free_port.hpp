#pragma once
// A loopback TCP port free now, for peers that take a port number and cannot pick one themselves
// (Debian's OpenIGTLink example servers, the tests' own servers).
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

namespace sonoshape::testing {

/// A port free now (bound to 0 and released): another program may take it before the caller.
inline int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

}  // namespace sonoshape::testing
