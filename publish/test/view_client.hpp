#pragma once
// A page's side of `sonoshape view` for tests: HTTP GET and a WebSocket that unpacks messages
// (as viewer/src/decode.js does), with Boost.Beast.
#include <gtest/gtest.h>

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "sonoshape/publish/mesh_stream.hpp"

namespace sonoshape::testing::view {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using publish::Frames;

inline std::uint32_t read_u32(const std::string& bytes, std::size_t at) {
  std::uint32_t value = 0;
  for (int byte = 3; byte >= 0; --byte)
    value = (value << 8) | static_cast<unsigned char>(bytes.at(at + byte));
  return value;
}

// The page's decoding of one WebSocket message (viewer/src/decode.js does the same).
inline Frames unpack(const std::string& packed) {
  const std::uint32_t count = read_u32(packed, 0);
  Frames frames;
  std::size_t at = 4 + 4 * std::size_t{count};
  for (std::uint32_t i = 0; i < count; ++i) {
    const std::uint32_t size = read_u32(packed, 4 + 4 * i);
    frames.push_back(packed.substr(at, size));
    at += (size + 3) / 4 * 4;
  }
  EXPECT_EQ(at, packed.size());
  return frames;
}

inline std::uint16_t port_of(const std::string& url) {
  return static_cast<std::uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
}

struct Reply {
  unsigned status = 0;
  std::string type;
  std::string body;
};

/// GET `target` as a browser that opened `url` asks for it (Host 127.0.0.1:PORT), or with
/// another `host` (DNS rebinding tests).
inline Reply http_get(const std::string& url, const std::string& target,
                      const std::string& host = {}) {
  asio::io_context ioc;
  tcp::socket socket(ioc);
  socket.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port_of(url)));
  http::request<http::empty_body> request(http::verb::get, target, 11);
  request.set(http::field::host, host.empty() ? "127.0.0.1:" + std::to_string(port_of(url)) : host);
  http::write(socket, request);
  beast::flat_buffer buffer;
  http::response<http::string_body> response;
  http::read(socket, buffer, response);
  return {response.result_int(), std::string(response[http::field::content_type]), response.body()};
}

// A page's WebSocket, with reads that give up after a while instead of hanging a test.
class Page {
 public:
  /// Connects as the server's own page does (Origin http://127.0.0.1:PORT), or with another
  /// `origin`.
  explicit Page(const std::string& url, const std::string& origin = {}) : ws_(ioc_) {
    ws_.next_layer().connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port_of(url)));
    const std::string host = "127.0.0.1:" + std::to_string(port_of(url));
    const std::string sent = origin.empty() ? "http://" + host : origin;
    ws_.set_option(websocket::stream_base::decorator(
        [sent](websocket::request_type& request) { request.set(http::field::origin, sent); }));
    ws_.handshake(host, "/stream");
  }

  /// The next message; none (a test failure) when none comes within 10 s or the server closed.
  Frames read() {
    beast::flat_buffer buffer;
    bool done = false;
    beast::error_code result;
    ws_.async_read(buffer, [&](beast::error_code ec, std::size_t) {
      done = true;
      result = ec;
    });
    ioc_.restart();
    ioc_.run_for(std::chrono::seconds(10));
    if (!done) {
      // Closing completes the read (aborted) before its handler's locals go.
      beast::error_code ignored;
      ws_.next_layer().close(ignored);
      ioc_.restart();
      ioc_.run();
      ADD_FAILURE() << "no message within 10 s";
      return {};
    }
    if (result) {
      ADD_FAILURE() << "reading the WebSocket: " << result.message();
      return {};
    }
    EXPECT_TRUE(ws_.got_binary());
    return unpack(beast::buffers_to_string(buffer.data()));
  }

  /// Every message until the server closes the connection (or `timeout` passes: a failure),
  /// in order: what a page gets before its server goes.
  std::vector<Frames> read_until_closed(std::chrono::seconds timeout) {
    std::vector<Frames> messages;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      beast::flat_buffer buffer;
      bool done = false;
      beast::error_code result;
      ws_.async_read(buffer, [&](beast::error_code ec, std::size_t) {
        done = true;
        result = ec;
      });
      ioc_.restart();
      ioc_.run_until(deadline);
      if (!done) break;
      if (result) return messages;  // closed: the server went
      messages.push_back(unpack(beast::buffers_to_string(buffer.data())));
    }
    beast::error_code ignored;
    ws_.next_layer().close(ignored);
    ioc_.restart();
    ioc_.run();
    ADD_FAILURE() << "the server did not close the page's connection within " << timeout.count()
                  << " s";
    return messages;
  }

  // The next message of `topic`, skipping others (the server's `viewer` notices).
  Frames read_topic(const std::string& topic) {
    for (int i = 0; i < 50; ++i) {
      Frames frames = read();
      if (frames.empty()) break;
      if (frames.at(0) == topic) return frames;
    }
    ADD_FAILURE() << "no " << topic << " message";
    return {};
  }

 private:
  asio::io_context ioc_;
  websocket::stream<tcp::socket> ws_;
};

/// A page folder as viewer/ lays it out, with stand-ins for the files (the server's tests do not
/// depend on the real page); with `three`, a stand-in for three.js as npm ci installs it.
inline void write_web_root(const std::filesystem::path& root, bool three) {
  const auto write = [&](const std::string& relative, const std::string& text) {
    std::filesystem::create_directories((root / relative).parent_path());
    std::ofstream(root / relative) << text;
  };
  write("index.html", "<!doctype html><title>sonoshape test page</title>");
  write("style.css", "body {}");
  write("src/decode.js", "export function decode() {}");
  write("package.json", "{}");
  write("test/decode.test.js", "// not served");
  if (three) {
    write("node_modules/three/package.json", "{}");
    write("node_modules/three/build/three.module.js", "export const REVISION = '0';");
    write("node_modules/three/examples/jsm/controls/OrbitControls.js",
          "export class OrbitControls {}");
  }
}

}  // namespace sonoshape::testing::view
