// Fuzz target: the OpenIGTLink server of `scan --igtl-serve` as a hostile client sees it. One
// server runs in the fuzzer's process (loopback, a free port) holding a surface, an image and a
// status; each input is the byte stream of one client: connect, send the input in pieces (the
// first byte sets the piece size, so that headers and bodies split across reads), close the
// sending side, then read what the server answers until it closes the connection.
//
// The server must answer or close within kStallS of the client's last byte, whatever it was
// sent; otherwise the target aborts (a stalled server thread is a finding, as a crash is).
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include "fuzz_support.hpp"
#include "sonoshape/publish/igtl_server.hpp"

namespace {

namespace pub = sonoshape::publish;
constexpr double kStallS = 5.0;

pub::IgtlServer& server() {
  static std::unique_ptr<pub::IgtlServer> instance = [] {
    sonoshape::fuzz::quiet_logs();
    pub::IgtlServerOptions options;
    options.port = 0;
    options.linger_ms = 0;
    auto started = pub::IgtlServer::start(options);
    if (!started) {
      std::fprintf(stderr, "cannot start the OpenIGTLink server: %s\n", started.message().c_str());
      std::abort();
    }
    auto s = std::make_unique<pub::IgtlServer>(std::move(*started));
    sonoshape::MeshSet meshes;
    sonoshape::TriangleMesh tetrahedron;
    tetrahedron.vertices = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 10}};
    tetrahedron.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    meshes.meshes.push_back({1, "organ", tetrahedron});
    (void)s->publish_meshes(meshes);
    Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();
    (void)s->publish_image(sonoshape::GreyImage(8, 8, 100), pose);
    return s;
  }();
  return *instance;
}

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

int connect_to(int port) {
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

// Reads and drops what the server sends until it closes the connection; false after kStallS.
bool drain_until_closed(int fd) {
  const double deadline_s = now_s() + kStallS;
  char buffer[65536];
  while (now_s() < deadline_s) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) return true;  // closed (or reset) by the server
  }
  return false;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  pub::IgtlServer& s = server();
  const int fd = connect_to(s.port());
  if (fd < 0) return 0;  // refused while earlier clients were still being closed
  const std::size_t piece = size > 0 ? 1 + data[0] % 97 : 1;
  for (std::size_t at = size > 0 ? 1 : 0; at < size; at += piece) {
    const std::size_t n = std::min(piece, size - at);
    if (::send(fd, data + at, n, MSG_NOSIGNAL) != static_cast<ssize_t>(n)) break;
  }
  ::shutdown(fd, SHUT_WR);
  const bool closed = drain_until_closed(fd);
  const pub::IgtlServerStats stats = s.stats();
  sonoshape::fuzz::explain(std::to_string(stats.requests_answered) + " requests answered, " +
                           std::to_string(stats.clients_expelled) + " clients expelled so far");
  ::close(fd);
  if (!closed) {
    std::fprintf(stderr, "the OpenIGTLink server neither answered nor closed within %.0f s\n",
                 kStallS);
    std::abort();
  }
  return 0;
}
