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
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "fuzz_support.hpp"
#include "sonoshape/publish/view_server.hpp"

namespace {

namespace pub = sonoshape::publish;
namespace fs = std::filesystem;
constexpr double kStallS = 5.0;

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
    s->post_stream_state(true, "tcp://127.0.0.1:5556", "");
    return s;
  }();
  return *instance;
}

int port_of(const std::string& url) {  // "http://127.0.0.1:PORT/"
  const std::size_t colon = url.rfind(':');
  return std::atoi(url.c_str() + colon + 1);
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

void send_in_pieces(int fd, const std::uint8_t* data, std::size_t size, std::size_t piece) {
  for (std::size_t at = 0; at < size; at += piece) {
    const std::size_t n = std::min(piece, size - at);
    if (::send(fd, data + at, n, MSG_NOSIGNAL) != static_cast<ssize_t>(n)) return;
  }
}

// Reads until the server closes the connection (true), or until `until` is in what was read
// (true, the connection left open), or kStallS passes (false). `first_line`: the answer's.
bool read_until(int fd, std::string& first_line, const std::string& until = {}) {
  const double deadline_s = now_s() + kStallS;
  std::string got;
  char buffer[65536];
  while (now_s() < deadline_s) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) return true;
    if (got.size() < 4096) got.append(buffer, static_cast<std::size_t>(n));
    if (first_line.empty() && got.find("\r\n") != std::string::npos)
      first_line = got.substr(0, got.find("\r\n"));
    if (!until.empty() && got.find(until) != std::string::npos) return true;
  }
  return false;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  pub::ViewServer& s = server();
  const int port = port_of(s.url());
  const int fd = connect_to(port);
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
    send_in_pieces(fd, reinterpret_cast<const std::uint8_t*>(upgrade.data()), upgrade.size(),
                   upgrade.size());
    answered = read_until(fd, upgrade_answer, "\r\n\r\n");
  }
  // The seeds name the server 127.0.0.1:8080; it listens on another port.
  std::string rest = size > 1 ? sonoshape::fuzz::as_string(data + 1, size - 1) : std::string();
  const std::string seed_host = "127.0.0.1:8080", host = "127.0.0.1:" + std::to_string(port);
  for (std::size_t at = rest.find(seed_host); at != std::string::npos;
       at = rest.find(seed_host, at + host.size()))
    rest.replace(at, seed_host.size(), host);
  send_in_pieces(fd, reinterpret_cast<const std::uint8_t*>(rest.data()), rest.size(), piece);
  ::shutdown(fd, SHUT_WR);
  const bool closed = answered && read_until(fd, answer);
  ::close(fd);
  if (!closed) {
    std::fprintf(stderr, "the view server neither answered nor closed within %.0f s\n", kStallS);
    std::abort();
  }
  sonoshape::fuzz::explain((upgrade_answer.empty() ? "" : upgrade_answer + "; then ") +
                           (answer.empty() ? "closed without an answer" : answer));
  return 0;
}
