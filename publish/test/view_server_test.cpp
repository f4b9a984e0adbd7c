// ViewServer and StreamView against a Boost.Beast HTTP and WebSocket client: the page's files,
// the frames byte for byte, late pages, new scans, a page that does not read, and the relay from
// a real publisher.
#include "sonoshape/publish/view_server.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <thread>

#include "sonoshape/publish/mesh_stream.hpp"
#include "sonoshape/publish/publisher.hpp"
#include "sonoshape/publish/stream_view.hpp"
#include "sonoshape/testing/sanitizer_slowdown.hpp"
#include "sonoshape/testing/temp_dir.hpp"
#include "view_client.hpp"

namespace sonoshape::publish::view_server_test {
namespace {

using namespace sonoshape::testing::view;

using sonoshape::testing::TempDir;

// The page folder of every server in these tests, with three.js's stand-in.
const std::filesystem::path& web_root() {
  static const TempDir dir;
  static const bool written = (write_web_root(dir.path(), true), true);
  (void)written;
  return dir.path();
}

ViewServer start_server() {
  ViewServerOptions options;
  options.http = "127.0.0.1:0";
  options.web_root = web_root();
  Result<ViewServer> server = ViewServer::start(options);
  if (!server) throw std::runtime_error(server.message());
  return std::move(*server);
}

TriangleMesh tetrahedron(double size_mm) {
  TriangleMesh mesh;
  mesh.vertices = {Vec3(0, 0, 0), Vec3(size_mm, 0, 0), Vec3(0, size_mm, 0), Vec3(0, 0, size_mm)};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

Frames mesh_frames(const std::string& scan, std::uint64_t seq, int label, double size_mm) {
  StreamMessage message;
  message.seq = seq;
  message.scan = scan;
  MeshUpdate update;
  update.label = label;
  update.name = "organ " + std::to_string(label);
  update.slices = seq;
  update.mesh = tetrahedron(size_mm);
  message.body = update;
  return encode_message(message).value();
}

Frames status_frames(const std::string& scan, std::uint64_t seq) {
  StreamMessage message;
  message.seq = seq;
  message.scan = scan;
  StatusReport status;
  status.frames_received = 10 * seq;
  message.body = status;
  return encode_message(message).value();
}

std::uint64_t seq_of(const Frames& frames) {
  return nlohmann::json::parse(frames.at(1)).at("seq").get<std::uint64_t>();
}

TEST(PackFrames, PadsEachFrameToFourBytesAndKeepsItsBytes) {
  const Frames frames{"mesh.1", std::string("\x01\x02\x03\x04\x05", 5), ""};
  const std::string packed = pack_frames(frames);
  ASSERT_EQ(packed.size(), 4u + 3 * 4 + 8 + 8 + 0);
  EXPECT_EQ(read_u32(packed, 0), 3u);
  EXPECT_EQ(read_u32(packed, 4), 6u);
  EXPECT_EQ(read_u32(packed, 8), 5u);
  EXPECT_EQ(read_u32(packed, 12), 0u);
  EXPECT_EQ(packed.substr(16, 8), std::string("mesh.1\0\0", 8));
  EXPECT_EQ(unpack(packed), frames);
}

TEST(ViewServer, ServesThePageItsScriptsAndThreeButNothingElse) {
  const ViewServer server = start_server();
  EXPECT_EQ(server.url().rfind("http://127.0.0.1:", 0), 0u) << server.url();

  const Reply page = http_get(server.url(), "/");
  EXPECT_EQ(page.status, 200u);
  EXPECT_EQ(page.type, "text/html; charset=utf-8");
  EXPECT_EQ(page.body, "<!doctype html><title>sonoshape test page</title>");
  const Reply script = http_get(server.url(), "/src/decode.js?v=1");
  EXPECT_EQ(script.status, 200u);
  EXPECT_EQ(script.type, "text/javascript; charset=utf-8");
  EXPECT_EQ(script.body, "export function decode() {}");

  for (const char* outside : {"/../CMakeLists.txt", "/package.json", "/src/../../README.md",
                              "/node_modules/three/package.json", "/three/package.json",
                              "/test/decode.test.js", "/src/missing.js", "/%2e%2e/x"})
    EXPECT_EQ(http_get(server.url(), outside).status, 404u) << outside;

  const Reply three = http_get(server.url(), "/three/build/three.module.js");
  EXPECT_EQ(three.status, 200u);
  EXPECT_EQ(three.body, "export const REVISION = '0';");
  EXPECT_EQ(http_get(server.url(), "/three/examples/jsm/controls/OrbitControls.js").status, 200u);
  EXPECT_EQ(http_get(server.url(), "/style.css").type, "text/css; charset=utf-8");
}

TEST(ViewServer, SaysHowToInstallThreeWhenItIsMissing) {
  const TempDir bare;
  write_web_root(bare.path(), false);
  ViewServerOptions options;
  options.http = "127.0.0.1:0";
  options.web_root = bare.path();
  const ViewServer server = ViewServer::start(options).value();
  EXPECT_EQ(http_get(server.url(), "/").status, 200u);
  const Reply three = http_get(server.url(), "/three/build/three.module.js");
  EXPECT_EQ(three.status, 404u);
  EXPECT_NE(three.body.find("scripts/install-deps"), std::string::npos) << three.body;
}

TEST(ViewServer, RefusesBadAddressesABusyPortAndAFolderWithoutThePage) {
  ViewServerOptions options;
  options.web_root = web_root();
  for (const char* address :
       {"8080", "127.0.0.1:", "127.0.0.1:99999", "127.0.0.1:80x", "example.org:8080", ":8080"}) {
    options.http = address;
    const Result<ViewServer> server = ViewServer::start(options);
    ASSERT_FALSE(server) << address;
    EXPECT_NE(server.message().find(address), std::string::npos) << server.message();
    EXPECT_NE(server.message().find("--http"), std::string::npos) << server.message();
  }
  const ViewServer first = start_server();
  options.http = "127.0.0.1:" + std::to_string(port_of(first.url()));
  const Result<ViewServer> second = ViewServer::start(options);
  ASSERT_FALSE(second);
  EXPECT_NE(second.message().find("in use"), std::string::npos) << second.message();

  options.http = "127.0.0.1:0";
  options.web_root = web_root() / "src";
  const Result<ViewServer> no_page = ViewServer::start(options);
  ASSERT_FALSE(no_page);
  EXPECT_NE(no_page.message().find("--web-root"), std::string::npos) << no_page.message();
}

TEST(ViewServer, ForwardsTheStreamFramesByteForByte) {
  ViewServer server = start_server();
  Page page(server.url());
  const Frames mesh = mesh_frames("scan-a", 1, 2, 10.0);
  server.post(mesh);
  const Frames received = page.read_topic("mesh.2");
  EXPECT_EQ(received, mesh);
  ASSERT_TRUE(decode_message(received));
}

TEST(ViewServer, RefusesAWebSocketFromAnotherSitesPage) {
  ViewServer server = start_server();
  const std::string own = "http://127.0.0.1:" + std::to_string(port_of(server.url()));
  EXPECT_NO_THROW(Page(server.url(), own));
  EXPECT_THROW(Page(server.url(), "http://evil.example"), boost::system::system_error);
}

// The status of a WebSocket upgrade sent with `host` and `origin` (empty: no Origin header).
unsigned upgrade_status(const std::string& url, const std::string& host, const std::string& origin,
                        std::string* body = nullptr) {
  asio::io_context ioc;
  tcp::socket socket(ioc);
  socket.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port_of(url)));
  http::request<http::empty_body> request(http::verb::get, "/stream", 11);
  request.set(http::field::host, host);
  request.set(http::field::upgrade, "websocket");
  request.set(http::field::connection, "upgrade");
  request.set(http::field::sec_websocket_key, "dGhlIHNhbXBsZSBub25jZQ==");
  request.set(http::field::sec_websocket_version, "13");
  if (!origin.empty()) request.set(http::field::origin, origin);
  http::write(socket, request);
  beast::flat_buffer buffer;
  http::response<http::string_body> response;  // a 101 has no body: Beast reads none
  http::read(socket, buffer, response);
  if (body) *body = response.body();
  return response.result_int();
}

// Issue 40, S3: a page of evil.example whose name is rebound to 127.0.0.1 reaches the server
// with Host evil.example:PORT and, for its WebSocket, Origin http://evil.example:PORT (the pair
// that passed the old check, which compared Origin with "http://" + Host).
TEST(ViewServer, ARebindingPagesHostAndOriginAreRefusedAndTheOwnNamesServed) {
  ViewServer server = start_server();
  const std::string port = std::to_string(port_of(server.url()));
  const std::string evil = "evil.example:" + port;
  const Reply page = http_get(server.url(), "/", evil);
  EXPECT_EQ(page.status, 421u);
  EXPECT_NE(page.body.find("not for Host 'evil.example:" + port + "'"), std::string::npos)
      << page.body;
  EXPECT_NE(page.body.find(server.url()), std::string::npos) << page.body;
  std::string why;
  EXPECT_EQ(upgrade_status(server.url(), evil, "http://" + evil, &why), 421u);
  EXPECT_NE(why.find("rebound"), std::string::npos) << why;
  // The right Host with another site's Origin, or none (a browser always sends one).
  EXPECT_EQ(upgrade_status(server.url(), "127.0.0.1:" + port, "http://" + evil, &why), 403u);
  EXPECT_NE(why.find("not Origin 'http://evil.example:" + port + "'"), std::string::npos) << why;
  EXPECT_EQ(upgrade_status(server.url(), "127.0.0.1:" + port, ""), 403u);
  // Another port on this machine is another site too.
  EXPECT_EQ(http_get(server.url(), "/", "127.0.0.1:1").status, 421u);
  EXPECT_EQ(upgrade_status(server.url(), "127.0.0.1:" + port, "http://127.0.0.1:1"), 403u);
  EXPECT_EQ(http_get(server.url(), "/", "10.1.2.3:" + port).status, 421u);  // bound to loopback

  // This machine's own names are served.
  for (const std::string& host :
       {"127.0.0.1:" + port, "localhost:" + port, "LocalHost:" + port, "[::1]:" + port}) {
    EXPECT_EQ(http_get(server.url(), "/", host).status, 200u) << host;
    EXPECT_EQ(upgrade_status(server.url(), host, "http://" + host), 101u) << host;
  }
}

TEST(ViewServer, BoundToEveryInterfaceItAnswersAnyAddressButNoName) {
  ViewServerOptions options;
  options.http = "0.0.0.0:0";
  options.web_root = web_root();
  auto server = ViewServer::start(options);
  ASSERT_TRUE(server) << server.message();
  const std::string port = std::to_string(port_of(server->url()));
  EXPECT_EQ(http_get(server->url(), "/", "192.168.1.20:" + port).status, 200u);
  EXPECT_EQ(http_get(server->url(), "/", "0.0.0.0:" + port).status, 200u);
  EXPECT_EQ(http_get(server->url(), "/", "scanner.example:" + port).status, 421u);
  EXPECT_EQ(upgrade_status(server->url(), "192.168.1.20:" + port, "http://evil.example:" + port),
            403u);
}

TEST(ViewServer, ALatePageGetsTheNewestOfEveryTopicAndANewScanDropsTheOld) {
  ViewServer server = start_server();
  server.post(mesh_frames("scan-a", 1, 1, 10.0));
  server.post(mesh_frames("scan-a", 2, 2, 10.0));
  server.post(mesh_frames("scan-a", 3, 1, 12.0));
  server.post(status_frames("scan-a", 4));
  {
    Page late(server.url());
    const Frames first = late.read();
    EXPECT_EQ(first.at(0), "mesh.1");
    EXPECT_EQ(seq_of(first), 3u);
    EXPECT_EQ(late.read().at(0), "mesh.2");
    EXPECT_EQ(late.read().at(0), "status");
  }
  server.post(mesh_frames("scan-b", 1, 1, 8.0));
  server.post(status_frames("scan-b", 2));
  Page later(server.url());
  const Frames mesh = later.read();
  EXPECT_EQ(mesh.at(0), "mesh.1");
  EXPECT_NE(mesh.at(1).find("scan-b"), std::string::npos);
  const Frames status = later.read();
  EXPECT_EQ(status.at(0), "status");
  EXPECT_NE(status.at(1).find("scan-b"), std::string::npos);  // scan-a's mesh.2 is gone
}

Frames slice_frames(const std::string& scan, std::uint64_t seq, std::uint64_t index) {
  LabeledSlice slice;
  slice.origin_mm = Vec3(0, 0, static_cast<double>(index));
  Region organ;
  organ.label = 1;
  organ.outer = {Vec2(0, 0), Vec2(5, 0), Vec2(5, 5), Vec2(0, 5)};
  slice.regions = {organ};
  return encode_message(StreamMessage{seq, scan, SliceUpdate{index, slice}}).value();
}

TEST(ViewServer, APageGetsEverySliceOfTheScanAndALatePageTooButNotAnOldScans) {
  // The page draws the slice planes so far and colours the surfaces by them: no slice of the
  // current scan is conflated away, whereas meshes and frames keep only the newest.
  ViewServer server = start_server();
  server.post(slice_frames("scan-a", 1, 0));
  server.post(slice_frames("scan-a", 2, 1));
  server.post(mesh_frames("scan-a", 3, 1, 10.0));
  server.post(slice_frames("scan-a", 4, 2));
  server.post(mesh_frames("scan-a", 5, 1, 12.0));
  Page late(server.url());
  std::vector<std::uint64_t> slice_seqs;
  std::uint64_t mesh_seq = 0;
  for (int k = 0; k < 4; ++k) {
    const Frames frames = late.read();
    if (frames.at(0) == "slice")
      slice_seqs.push_back(seq_of(frames));
    else
      mesh_seq = seq_of(frames);
  }
  EXPECT_EQ(slice_seqs, (std::vector<std::uint64_t>{1, 2, 4}));
  EXPECT_EQ(mesh_seq, 5u);

  server.post(slice_frames("scan-b", 1, 0));
  Page later(server.url());
  const Frames first = later.read();
  EXPECT_EQ(first.at(0), "slice");
  EXPECT_NE(first.at(1).find("scan-b"), std::string::npos);  // scan-a's slices are gone
}

TEST(ViewServer, APageThatDoesNotReadLosesIntermediateMeshesNeverTheNewestAndNeverBlocks) {
  ViewServer server = start_server();
  Page slow(server.url());
  // Messages of 4 MB: a few fill the socket buffers of a page that reads nothing.
  constexpr std::uint64_t kPosted = 40;
  const std::string payload(4u << 20, 'x');
  const auto started = std::chrono::steady_clock::now();
  for (std::uint64_t seq = 1; seq <= kPosted; ++seq) {
    nlohmann::json header{{"seq", seq}, {"scan", "scan-a"}};
    server.post(Frames{"mesh.1", header.dump(), payload});
  }
  const double posting_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  // Copies only, no waiting for the page (waiting would last until the page reads: forever).
  EXPECT_LT(posting_s, 2.0 * sonoshape::testing::kSanitizerSlowdown);

  std::uint64_t received = 0;
  std::uint64_t last_seq = 0;
  while (last_seq < kPosted) {
    const Frames frames = slow.read_topic("mesh.1");
    ASSERT_FALSE(frames.empty());
    EXPECT_GT(seq_of(frames), last_seq);
    last_seq = seq_of(frames);
    ++received;
  }
  EXPECT_EQ(last_seq, kPosted);
  EXPECT_LT(received, kPosted / 2);
  EXPECT_EQ(server.messages_replaced(), kPosted - received);
}

TEST(StreamView, RelaysARunningScanToAPageThroughTheSnapshotThenLive) {
  PublisherOptions publisher_options;
  publisher_options.endpoint = "tcp://127.0.0.1:*";
  publisher_options.snapshot_endpoint = "tcp://127.0.0.1:*";
  publisher_options.linger_ms = 0;
  MeshPublisher publisher = MeshPublisher::bind(publisher_options).value();
  MeshSet meshes;
  meshes.meshes = {{1, "liver", tetrahedron(10.0)}, {2, "kidney", tetrahedron(5.0)}};
  ASSERT_TRUE(publisher.publish_meshes(meshes, 1.0, 3));
  ASSERT_TRUE(publisher.publish_status(StatusReport{}));

  StreamViewOptions options;
  options.stream.endpoint = publisher.endpoint();
  options.stream.snapshot_endpoint = publisher.snapshot_endpoint();
  options.server.http = "127.0.0.1:0";
  options.server.web_root = web_root();
  const StreamView view = StreamView::start(options).value();
  Page page(view.url());
  // First perhaps "waiting: connecting" (the page came before the snapshot), then "connected".
  Frames notice = page.read_topic("viewer");
  if (notice.at(1).find("\"connecting\"") != std::string::npos) notice = page.read_topic("viewer");
  EXPECT_NE(notice.at(1).find("\"stream\":\"connected\""), std::string::npos) << notice.at(1);

  const Frames liver = page.read_topic("mesh.1");
  const Result<StreamMessage> decoded = decode_message(liver);
  ASSERT_TRUE(decoded) << decoded.message();
  EXPECT_EQ(decoded->scan, publisher.scan());
  EXPECT_EQ(std::get<MeshUpdate>(decoded->body).name, "liver");
  page.read_topic("mesh.2");
  page.read_topic("status");

  // Live: the liver grows.
  meshes.meshes[0].mesh = tetrahedron(20.0);
  ASSERT_TRUE(publisher.publish_meshes(meshes, 2.0, 4));
  const Frames grown = page.read_topic("mesh.1");
  EXPECT_EQ(seq_of(grown), publisher.last_seq() - 1);
  EXPECT_GE(view.messages_relayed(), 4u);  // the snapshot's three and the grown liver
}

TEST(StreamView, FollowsAScanRestartedOnTheSameEndpoints) {
  PublisherOptions publisher_options;
  publisher_options.endpoint = "tcp://127.0.0.1:*";
  publisher_options.snapshot_endpoint = "tcp://127.0.0.1:*";
  publisher_options.linger_ms = 0;
  auto first = std::make_unique<MeshPublisher>(MeshPublisher::bind(publisher_options).value());
  MeshSet meshes;
  meshes.meshes = {{1, "liver", tetrahedron(10.0)}, {2, "kidney", tetrahedron(5.0)}};
  ASSERT_TRUE(first->publish_meshes(meshes, 1.0, 3));

  StreamViewOptions options;
  options.stream.endpoint = first->endpoint();
  options.stream.snapshot_endpoint = first->snapshot_endpoint();
  options.server.http = "127.0.0.1:0";
  options.server.web_root = web_root();
  const StreamView view = StreamView::start(options).value();
  Page page(view.url());
  EXPECT_NE(page.read_topic("mesh.2").at(1).find(first->scan()), std::string::npos);

  // The scan restarts: a new publisher, a new scan uuid, the same endpoints. Its first messages
  // may pass before the subscriber has reconnected; the view then joins through the snapshot.
  publisher_options.endpoint = first->endpoint();
  publisher_options.snapshot_endpoint = first->snapshot_endpoint();
  first.reset();
  MeshPublisher second = MeshPublisher::bind(publisher_options).value();
  meshes.meshes = {{1, "liver", tetrahedron(7.0)}};
  ASSERT_TRUE(second.publish_meshes(meshes, 0.5, 1));
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  ASSERT_TRUE(second.publish_status(StatusReport{}));

  const Frames liver = page.read_topic("mesh.1");
  const Result<StreamMessage> decoded = decode_message(liver);
  ASSERT_TRUE(decoded) << decoded.message();
  EXPECT_EQ(decoded->scan, second.scan());
  const Frames status = page.read_topic("status");
  EXPECT_NE(status.at(1).find(second.scan()), std::string::npos);
}

// Issue 40, "a finished scan reads as finished": a publisher that goes after its scan's last
// status (`"finished": true`) is a normal end, told to the page as `finished`, never as a
// missing publisher; one that goes without it is still waited for.
TEST(StreamView, APublisherGoneAfterItsFinishedStatusIsAFinishedScanNotAMissingOne) {
  for (const bool finish : {true, false}) {
    SCOPED_TRACE(finish ? "finished" : "gone without finishing");
    PublisherOptions publisher_options;
    publisher_options.endpoint = "tcp://127.0.0.1:*";
    publisher_options.snapshot_endpoint = "tcp://127.0.0.1:*";
    publisher_options.linger_ms = 0;
    auto publisher =
        std::make_unique<MeshPublisher>(MeshPublisher::bind(publisher_options).value());
    MeshSet meshes;
    meshes.meshes = {{1, "liver", tetrahedron(10.0)}};
    ASSERT_TRUE(publisher->publish_meshes(meshes, 1.0, 3));

    StreamViewOptions options;
    options.stream.endpoint = publisher->endpoint();
    options.stream.snapshot_endpoint = publisher->snapshot_endpoint();
    options.stream.snapshot_timeout_ms = 300;
    options.retry_ms = 100;
    options.server.http = "127.0.0.1:0";
    options.server.web_root = web_root();
    StreamView view = StreamView::start(options).value();
    Page page(view.url());
    page.read_topic("mesh.1");
    StatusReport last;
    last.slices = 3;
    last.frames_received = 30;
    last.state = ScanState::kIdle;
    last.finished = finish;
    ASSERT_TRUE(publisher->publish_status(last));
    const Result<StreamMessage> status = decode_message(page.read_topic("status"));
    ASSERT_TRUE(status) << status.message();
    EXPECT_EQ(std::get<StatusReport>(status->body).finished, finish);
    // Delivered to the page: drain() returns at once; without the last status it waits its time.
    const auto before = std::chrono::steady_clock::now();
    EXPECT_EQ(view.drain(publisher->scan(), std::chrono::milliseconds(500)), finish);
    EXPECT_LT(std::chrono::steady_clock::now() - before, std::chrono::seconds(2));

    publisher.reset();  // the scan exits
    std::string said;
    for (int i = 0; i < 20; ++i) {
      const nlohmann::json header = nlohmann::json::parse(page.read_topic("viewer").at(1));
      said = header.at("stream").get<std::string>() + ": " + header.value("message", "");
      if (header.at("stream") != "connected") break;
    }
    if (finish) {
      EXPECT_TRUE(said.starts_with("finished: scan ")) << said;
      EXPECT_NE(said.find("3 slices, 30 frames in (0 dropped)"), std::string::npos) << said;
      EXPECT_EQ(said.find("no mesh-stream publisher answered"), std::string::npos) << said;
    } else {
      EXPECT_TRUE(said.starts_with("waiting: ")) << said;
    }
  }
}

TEST(StreamView, TellsThePageWhileNoPublisherAnswers) {
  StreamViewOptions options;
  options.stream.endpoint = "tcp://127.0.0.1:1";  // nothing listens on port 1
  options.stream.snapshot_endpoint = "tcp://127.0.0.1:2";
  options.stream.snapshot_timeout_ms = 200;
  options.retry_ms = 100;
  options.server.http = "127.0.0.1:0";
  options.server.web_root = web_root();
  const StreamView view = StreamView::start(options).value();
  Page page(view.url());
  for (int i = 0; i < 10; ++i) {
    const Frames notice = page.read_topic("viewer");
    const nlohmann::json header = nlohmann::json::parse(notice.at(1));
    EXPECT_EQ(header.at("stream"), "waiting");
    EXPECT_EQ(header.at("endpoint"), "tcp://127.0.0.1:1");
    if (header.at("message") != "connecting") {
      EXPECT_NE(header.at("message").get<std::string>().find("tcp://127.0.0.1:1"),
                std::string::npos);
      return;
    }
  }
  ADD_FAILURE() << "the page was never told why the stream is missing";
}

}  // namespace
}  // namespace sonoshape::publish::view_server_test
