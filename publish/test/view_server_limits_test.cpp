// The view server against hostile local clients (issue 40, C1, C2 and the `..` mutation): raw
// sockets that send large WebSocket messages, half-open requests, clients that ask for a large
// file and never read it, more pages than the limit, and `..` in a raw request target. The page
// must stay reachable and the server's memory bounded.
#include <gtest/gtest.h>
#include <sys/socket.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <thread>
#include <vector>

#include "sonoshape/publish/view_server.hpp"
#include "sonoshape/testing/temp_dir.hpp"
#include "view_client.hpp"

namespace sonoshape::publish::view_server_limits_test {
namespace {

using namespace sonoshape::testing::view;
using sonoshape::testing::contains;
using sonoshape::testing::TempDir;

ViewServer start_server(const std::filesystem::path& root) {
  ViewServerOptions options;
  options.http = "127.0.0.1:0";
  options.web_root = root;
  Result<ViewServer> server = ViewServer::start(options);
  if (!server) throw std::runtime_error(server.message());
  return std::move(*server);
}

tcp::endpoint endpoint_of(const ViewServer& server) {
  return {asio::ip::make_address("127.0.0.1"), port_of(server.url())};
}

std::string host_of(const ViewServer& server) {
  return "127.0.0.1:" + std::to_string(port_of(server.url()));
}

// The status of GET `target`, or 0 when no answer comes within `limit` (the server unreachable).
unsigned get_within(const ViewServer& server, const std::string& target,
                    std::chrono::seconds limit) {
  asio::io_context ioc;
  beast::tcp_stream stream(ioc);
  http::request<http::empty_body> request(http::verb::get, target, 11);
  request.set(http::field::host, host_of(server));
  beast::flat_buffer buffer;
  http::response<http::string_body> response;
  unsigned status = 0;
  stream.expires_after(limit);
  stream.async_connect(endpoint_of(server), [&](beast::error_code ec) {
    if (ec) return;
    http::async_write(stream, request, [&](beast::error_code wec, std::size_t) {
      if (wec) return;
      http::async_read(stream, buffer, response, [&](beast::error_code rec, std::size_t) {
        if (!rec) status = response.result_int();
      });
    });
  });
  ioc.run();
  return status;
}

// Resident memory of this process (the server runs in it), in MiB.
double resident_mib() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return 0;
}

// Waits until `done` or 10 s.
template <class Predicate>
bool eventually(Predicate done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

// A page's WebSocket, opened with the server's own Origin.
std::unique_ptr<websocket::stream<tcp::socket>> open_page(asio::io_context& ioc,
                                                          const ViewServer& server) {
  auto ws = std::make_unique<websocket::stream<tcp::socket>>(ioc);
  ws->next_layer().connect(endpoint_of(server));
  const std::string origin = "http://" + host_of(server);
  ws->set_option(websocket::stream_base::decorator(
      [origin](websocket::request_type& request) { request.set(http::field::origin, origin); }));
  ws->handshake(host_of(server), "/stream");
  return ws;
}

// Issue 40, C1: 480 pages each sending 16 MiB (Beast's default limit) aborted the scan with
// bad_alloc. The page never sends data: a message above 1 KiB closes that page (code 1009).
TEST(ViewServerLimits, AWebSocketMessageAboveOneKibClosesOnlyThatPage) {
  const TempDir root;
  write_web_root(root.path(), true);
  ViewServer server = start_server(root.path());
  asio::io_context ioc;
  std::vector<std::unique_ptr<websocket::stream<tcp::socket>>> flooders;
  for (int i = 0; i < 8; ++i) flooders.push_back(open_page(ioc, server));
  // Half send 2 KiB (the write completes, the close frame is read: code 1009), half 1 MiB (the
  // server closes while the client still writes: the client sees its connection end).
  for (std::size_t i = 0; i < flooders.size(); ++i) {
    auto& ws = flooders[i];
    const std::string message(i < 4 ? 2048 : 1 << 20, 'x');
    ws->binary(true);
    beast::error_code ec;
    ws->write(asio::buffer(message), ec);
  }
  for (std::size_t i = 0; i < flooders.size(); ++i) {
    auto& ws = flooders[i];
    beast::flat_buffer buffer;
    beast::error_code ec;
    for (int k = 0; k < 10 && !ec; ++k) ws->read(buffer, ec);  // skips the viewer notices
    EXPECT_TRUE(ec) << i;
    // The server's close frame says why (its reply to it may find the socket gone already).
    if (i < 4) {
      EXPECT_EQ(ws->reason().code, websocket::close_code::too_big) << ec.message();
    }
  }
  EXPECT_TRUE(eventually([&] { return server.connections() == 0; })) << server.connections();
  // A small message (what a page's close frame or a stray text could be) keeps the page.
  Page page(server.url());
  server.post(Frames{"status", "{}"});
  EXPECT_EQ(page.read_topic("status").at(0), "status");
}

// Issue 40, C2: 1500 clients asking for three.js without reading it took +1 GB, and 1100
// half-open requests kept the page unreachable for 20 s.
TEST(ViewServerLimits, HalfOpenRequestsAndClientsThatDoNotReadLeaveThePageReachable) {
  const TempDir root;
  write_web_root(root.path(), true);
  std::ofstream(root.path() / "node_modules/three/build/three.module.js")
      << std::string(8 << 20, 'x');  // 8 MiB: 100 whole copies would be 800 MiB
  ViewServer server = start_server(root.path());
  const double before_mib = resident_mib();

  asio::io_context ioc;
  std::vector<tcp::socket> clients;
  const std::string three =
      "GET /three/build/three.module.js HTTP/1.1\r\nHost: " + host_of(server) + "\r\n\r\n";
  for (int i = 0; i < 100; ++i) {
    tcp::socket& socket = clients.emplace_back(ioc);
    socket.open(tcp::v4());
    socket.set_option(asio::socket_base::receive_buffer_size(4096));
    socket.connect(endpoint_of(server));
    asio::write(socket, asio::buffer(three));  // and never reads
  }
  const std::string half = "GET / HTTP/1.1\r\nHost: " + host_of(server) + "\r\n";
  for (int i = 0; i < 200; ++i) {
    tcp::socket& socket = clients.emplace_back(ioc);
    socket.connect(endpoint_of(server));
    asio::write(socket, asio::buffer(half));  // the request's last line never comes
  }
  EXPECT_EQ(get_within(server, "/", std::chrono::seconds(5)), 200u);
  EXPECT_EQ(get_within(server, "/three/build/three.module.js", std::chrono::seconds(10)), 200u);
  EXPECT_LE(server.open_connections(), 32u);
  EXPECT_GE(server.connections_closed_at_limit(), 300u - 32u);
  EXPECT_LT(resident_mib() - before_mib, 64.0) << "before " << before_mib << " MiB";
}

TEST(ViewServerLimits, AtMostSixteenPagesStreamAndFilesAreStillServed) {
  const TempDir root;
  write_web_root(root.path(), true);
  ViewServer server = start_server(root.path());
  asio::io_context ioc;
  std::vector<std::unique_ptr<websocket::stream<tcp::socket>>> pages;
  for (int i = 0; i < 16; ++i) pages.push_back(open_page(ioc, server));
  EXPECT_TRUE(eventually([&] { return server.connections() == 16; })) << server.connections();
  try {
    open_page(ioc, server);
    ADD_FAILURE() << "a 17th page was given a WebSocket";
  } catch (const boost::system::system_error& error) {
    EXPECT_EQ(error.code(), websocket::error::upgrade_declined) << error.what();
  }
  EXPECT_EQ(get_within(server, "/", std::chrono::seconds(5)), 200u);
  pages.pop_back();  // a page closed makes room for another
  EXPECT_TRUE(eventually([&] { return server.connections() == 15; }));
  EXPECT_NO_THROW(open_page(ioc, server));
}

// Browsers resolve `..` before they send a request, so only a raw client shows whether the server
// itself keeps requests inside its web root (scripts/mutate: view-server-dot-dot-allowed).
TEST(ViewServerLimits, ARawRequestWithDotDotReadsNothingOutsideTheWebRoot) {
  const TempDir dir;
  const std::filesystem::path root = dir.path() / "viewer";
  write_web_root(root, true);
  std::ofstream(dir.path() / "secret.js") << "outside the web root";
  ViewServer server = start_server(root);
  for (const char* target : {"/src/../../secret.js", "/three/build/../../../../secret.js",
                             "/three/examples/jsm/../../../../../secret.js"}) {
    const Reply reply = http_get(server.url(), target);
    EXPECT_EQ(reply.status, 404u) << target;
    EXPECT_FALSE(contains(reply.body, "outside")) << target;
  }
}

Frames mesh_frames(const std::string& scan, std::uint64_t seq, int label) {
  MeshUpdate update;
  update.label = label;
  update.mesh.vertices = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  update.mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return encode_message(StreamMessage{seq, scan, update}).value();
}

// Issue 40, C6: a publisher with many labels stalled the view (a linear search of every topic
// per message, and a page sent every label). Labels beyond kMaxStreamLabels are not kept.
TEST(ViewServerLimits, MeshesOfLabelsBeyondTheLimitAreCountedNotKept) {
  const TempDir root;
  write_web_root(root.path(), true);
  ViewServer server = start_server(root.path());
  std::uint64_t seq = 0;
  for (int label = 1; label <= 1000; ++label) server.post(mesh_frames("scan-a", ++seq, label));
  EXPECT_TRUE(eventually([&] { return server.meshes_refused_over_label_limit() == 744; }))
      << server.meshes_refused_over_label_limit();
  // Newer meshes of labels already kept still go through.
  server.post(mesh_frames("scan-a", ++seq, 1));
  server.post(encode_message(StreamMessage{++seq, "scan-a", StatusReport{}}).value());
  Page late(server.url());
  std::set<std::string> topics;
  for (Frames frames = late.read(); !frames.empty() && frames.at(0) != "status";
       frames = late.read())
    if (frames.at(0) != "viewer") topics.insert(frames.at(0));
  EXPECT_EQ(topics.size(), static_cast<std::size_t>(kMaxStreamLabels));
  EXPECT_EQ(topics.count("mesh.256"), 1u);
  EXPECT_EQ(topics.count("mesh.257"), 0u);
  // A new scan starts with a clean count.
  server.post(mesh_frames("scan-b", 1, 999));
  EXPECT_EQ(late.read_topic("mesh.999").at(0), "mesh.999");
}

// Issue 40: a folder path was answered 200 with an empty body.
TEST(ViewServerLimits, AFolderIsNotFoundNotAnEmptyFile) {
  const TempDir root;
  write_web_root(root.path(), true);
  std::filesystem::create_directories(root.path() / "src" / "folder.js");
  ViewServer server = start_server(root.path());
  EXPECT_EQ(http_get(server.url(), "/src/folder.js").status, 404u);
  EXPECT_EQ(http_get(server.url(), "/three/build/").status, 404u);
  EXPECT_EQ(http_get(server.url(), "/src/decode.js").status, 200u);
}

}  // namespace
}  // namespace sonoshape::publish::view_server_limits_test
