// Fuzz target: the OpenIGTLink server of `scan --igtl-serve` as a hostile client sees it. One
// server runs in the fuzzer's process (loopback, a free port) holding a surface, an image and a
// status; each input is the byte stream of one client: connect, send the input in pieces (the
// first byte sets the piece size, so that headers and bodies split across reads), close the
// sending side, then read what the server answers until it closes the connection.
//
// The server must answer or close within kStallS of the client's last byte, whatever it was
// sent; otherwise the target aborts (a stalled server thread is a finding, as a crash is).

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "fuzz_support.hpp"
#include "loopback_client.hpp"
#include "sonoshape/publish/igtl_server.hpp"

namespace {

namespace pub = sonoshape::publish;
using sonoshape::fuzz::kStallS;

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

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  pub::IgtlServer& s = server();
  const int fd = sonoshape::fuzz::connect_loopback(s.port());
  if (fd < 0) return 0;  // refused while earlier clients were still being closed
  const std::size_t piece = size > 0 ? 1 + data[0] % 97 : 1;
  if (size > 1) sonoshape::fuzz::send_in_pieces(fd, data + 1, size - 1, piece);
  ::shutdown(fd, SHUT_WR);
  std::string answer;
  const bool closed = sonoshape::fuzz::read_until(fd, answer);
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
