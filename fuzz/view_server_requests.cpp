// Fuzz target: the browser view's server (`scan --view`, `view`) as a hostile client sees it:
// its HTTP requests (paths, Host, Origin, methods) and, behind an accepted WebSocket upgrade, the
// frames a client sends. One server runs in the fuzzer's process (loopback, a free port) on a
// scratch web root, with a few stream messages posted; each input is one connection.
//
// Input: byte 0 bit 0 clear: the rest is sent as it is (raw HTTP). Set: a valid WebSocket
// upgrade for the page is sent first, its answer read, and the rest follows as WebSocket
// frames. Bits 1-7 set the piece size of the sends; "127.0.0.1:8080" in the input is replaced by
// the server's address. The client then closes its sending side and reads until the server
// closes; the server must close within kStallS, whatever it was sent.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "fuzz_support.hpp"
#include "loopback_client.hpp"
#include "sonoshape/publish/view_server.hpp"

namespace {

namespace pub = sonoshape::publish;
namespace fs = std::filesystem;
using sonoshape::fuzz::kStallS;

pub::ViewServer& server() {
  static std::unique_ptr<pub::ViewServer> instance = [] {
    sonoshape::fuzz::quiet_logs();
    const fs::path root =
        fs::temp_directory_path() / ("sonoshape-fuzz-web-" + std::to_string(::getpid()));
    fs::create_directories(root / "src");
    std::ofstream(root / "index.html") << "<!doctype html><title>view</title>";
    std::ofstream(root / "src" / "main.js") << std::string(200000, 'x');
    pub::ViewServerOptions options;
    options.http = "127.0.0.1:0";
    options.web_root = root;
    auto started = pub::ViewServer::start(options);
    if (!started) {
      std::fprintf(stderr, "cannot start the view server: %s\n", started.message().c_str());
      std::abort();
    }
    auto s = std::make_unique<pub::ViewServer>(std::move(*started));
    s->post({"status", R"({"scan": "fuzz", "state": "scanning"})"});
    s->post_stream_state(sonoshape::publish::StreamState::kConnected, "tcp://127.0.0.1:5556", "");
    return s;
  }();
  return *instance;
}

int port_of(const std::string& url) {  // "http://127.0.0.1:PORT/"
  const std::size_t colon = url.rfind(':');
  return std::atoi(url.c_str() + colon + 1);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  pub::ViewServer& s = server();
  const int port = port_of(s.url());
  const int fd = sonoshape::fuzz::connect_loopback(port);
  if (fd < 0) return 0;  // refused at the connection cap while earlier ones close
  const std::uint8_t mode = size > 0 ? data[0] : 0;
  const std::size_t piece = 1 + (mode >> 1);
  bool answered = true;
  std::string upgrade_answer, answer;
  if (mode & 1) {
    const std::string host = "127.0.0.1:" + std::to_string(port);
    const std::string upgrade = "GET /stream HTTP/1.1\r\nHost: " + host + "\r\nOrigin: http://" +
                                host +
                                "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                                "Sec-WebSocket-Version: 13\r\n\r\n";
    sonoshape::fuzz::send_in_pieces(fd, reinterpret_cast<const std::uint8_t*>(upgrade.data()),
                                    upgrade.size(), upgrade.size());
    answered = sonoshape::fuzz::read_until(fd, upgrade_answer, "\r\n\r\n");
  }
  // The seeds name the server 127.0.0.1:8080; it listens on another port.
  std::string rest = size > 1 ? sonoshape::fuzz::as_string(data + 1, size - 1) : std::string();
  const std::string seed_host = "127.0.0.1:8080", host = "127.0.0.1:" + std::to_string(port);
  for (std::size_t at = rest.find(seed_host); at != std::string::npos;
       at = rest.find(seed_host, at + host.size()))
    rest.replace(at, seed_host.size(), host);
  sonoshape::fuzz::send_in_pieces(fd, reinterpret_cast<const std::uint8_t*>(rest.data()),
                                  rest.size(), piece);
  ::shutdown(fd, SHUT_WR);
  const bool closed = answered && sonoshape::fuzz::read_until(fd, answer);
  ::close(fd);
  if (!closed) {
    std::fprintf(stderr, "the view server neither answered nor closed within %.0f s\n", kStallS);
    std::abort();
  }
  sonoshape::fuzz::explain((upgrade_answer.empty() ? "" : upgrade_answer + "; then ") +
                           (answer.empty() ? "closed without an answer" : answer));
  return 0;
}
