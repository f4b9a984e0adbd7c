// OpenIGTLink out (issue 22, point 3): `sonoshape scan --igtl-serve` during a simulated scan,
// watched by Debian's ReceiveClient example (built from its shipped source) together with
// clients written with the OpenIGTLink library, one of which vanishes mid-scan; IgtlServer
// answering Debian's PolyDataClient. Loopback only, ports picked by the system, every wait bounded.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>

#include "sonoshape/publish/igtl_server.hpp"
#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/igtl_client.hpp"
#include "sonoshape/testing/sanitizer_slowdown.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace igtl_peer_test {
namespace {

namespace fs = std::filesystem;
using sonoshape::testing::contains;
using sonoshape::testing::file_text;
using sonoshape::testing::spawn;
using sonoshape::testing::wait_exit;
// Scans and peers run several times slower in sanitizer builds: their time bounds scale.
constexpr double kSlowdown = sonoshape::testing::kSanitizerSlowdown;
using sonoshape::testing::IgtlClient;
using sonoshape::testing::Received;

// The default simulated sweep (50 slices, three labels) played as fast as the pipeline goes
// (deterministic slices), with 128-pixel frames and a coarser octree: the same traffic for the
// peers at a quarter of the default scan's CPU time.
const std::string kScan =
    std::string(SONOSHAPE_BINARY) +
    " scan --source sim:default --fast --width-px 128 --height-px 128 --depth 5 ";

// The port a scan's log announces ("OpenIGTLink server on 127.0.0.1:PORT"), waiting up to
// `timeout_s`; 0 when it never does.
int announced_port(const fs::path& log, double timeout_s) {
  const std::regex line("OpenIGTLink server on 127\\.0\\.0\\.1:([0-9]+)");
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    std::smatch match;
    const std::string text = file_text(log);
    if (std::regex_search(text, match, line)) return std::stoi(match[1]);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return 0;
}

std::size_t count(const std::string& text, const std::string& part) {
  std::size_t n = 0;
  for (auto at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
  return n;
}

std::string summary_slices(const std::string& log) {
  std::smatch match;
  return std::regex_search(log, match, std::regex("\n  slices ([0-9]+),")) ? match[1].str() : "?";
}

// Receives until the server closes (or nothing comes for the client's timeout): the POLYDATA
// names, those with at least one triangle, and how many IMAGE and STATUS messages came;
// `last_status` the error name (state) of the newest STATUS.
struct Watched {
  std::set<std::string> names, surfaces;
  std::size_t images = 0, statuses = 0;
  std::string last_status;
  int image_width = 0;
};

Watched watch(IgtlClient& client) {
  Watched w;
  for (Received r = client.next(); !r.type.empty(); r = client.next()) {
    if (r.type == "POLYDATA") w.names.insert(r.name);
    if (r.type == "POLYDATA" && sonoshape::testing::triangles(r) > 0) w.surfaces.insert(r.name);
    if (r.type == "IMAGE") {
      ++w.images;
      int size[3];
      r.image->GetDimensions(size);
      w.image_width = size[0];
    }
    if (r.type == "STATUS") {
      ++w.statuses;
      w.last_status = r.status->GetErrorName();
    }
  }
  return w;
}

TEST(IgtlPeers, DebiansReceiveClientAndALibraryClientGetEveryLabelAndTheImageDuringAScan) {
  sonoshape::testing::TempDir dir;
  const fs::path scan_log = dir.path() / "scan.log", client_log = dir.path() / "client.log";
  const pid_t scan = spawn(kScan + "--igtl-serve 0 -o " + (dir.path() / "out").string(), scan_log);
  const int port = announced_port(scan_log, 30.0 * kSlowdown);
  ASSERT_GT(port, 0) << file_text(scan_log);
  // Debian's example prints what it receives and exits when the server closes the connection.
  const pid_t receiver =
      spawn(std::string(RECEIVE_CLIENT) + " 127.0.0.1 " + std::to_string(port), client_log);
  // The watch ends when the scan closes the connection; its bound must outlast the scan's
  // longest silence, the final full-depth update after the last frame (a few seconds; 47 s in an
  // ASan build, longer than the 5 s x 10 it had, so the client stopped before the final status).
  IgtlClient library_client(port, 30.0);
  ASSERT_TRUE(library_client.connected());
  const Watched watched = watch(library_client);
  ASSERT_EQ(wait_exit(scan, 60.0 * kSlowdown), 0) << file_text(scan_log);
  EXPECT_EQ(wait_exit(receiver, 10.0 * kSlowdown), 0);
  const std::string scan_text = file_text(scan_log), received = file_text(client_log);

  // Every label of the scan (slices.json names them) arrived as a POLYDATA named after it; in
  // this sweep the probe never cuts the third one (its mesh file is empty too), so only the
  // others have triangles.
  const auto slices = nlohmann::json::parse(file_text(dir.path() / "out" / "slices.json"));
  std::set<std::string> labels;
  for (const auto& label : slices["labels"]) labels.insert(label["name"].get<std::string>());
  ASSERT_EQ(labels.size(), 3u) << scan_text;
  EXPECT_EQ(watched.names, labels);
  EXPECT_GE(watched.surfaces.size(), 2u);
  for (const std::string& name : watched.surfaces) EXPECT_TRUE(labels.count(name)) << name;
  EXPECT_GT(watched.images, 0u);
  EXPECT_EQ(watched.image_width, 128);
  EXPECT_EQ(watched.last_status, "idle");  // the final status reaches the clients

  // Debian's ReceiveClient: the surfaces (it skips POLYDATA bodies, naming the type), the frames
  // decoded as 128 x 128 images with CRC checked, and the statuses down to the final one.
  EXPECT_GE(count(received, "Receiving : POLYDATA"), labels.size()) << received.substr(0, 2000);
  EXPECT_TRUE(contains(received, "Receiving IMAGE data type."));
  EXPECT_TRUE(contains(received, "Device Name           : Image"));
  EXPECT_TRUE(contains(received, "Dimensions            : (128, 128, 1)"));
  EXPECT_TRUE(contains(received, "Receiving STATUS data type."));
  EXPECT_TRUE(contains(received, " Error Name: idle"));
  EXPECT_TRUE(contains(scan_text, "2 clients served")) << scan_text;
}

TEST(IgtlPeers, AClientThatVanishesMidScanChangesNothingForTheScan) {
  sonoshape::testing::TempDir dir;
  // The same sweep without any client: --fast makes its slices deterministic.
  const fs::path alone_log = dir.path() / "alone.log";
  ASSERT_EQ(wait_exit(spawn(kScan, alone_log), 60.0 * kSlowdown), 0) << file_text(alone_log);

  const fs::path scan_log = dir.path() / "scan.log", client_log = dir.path() / "client.log";
  const pid_t scan = spawn(kScan + "--igtl-serve 0", scan_log);
  const int port = announced_port(scan_log, 30.0 * kSlowdown);
  ASSERT_GT(port, 0) << file_text(scan_log);
  const pid_t receiver =
      spawn(std::string(RECEIVE_CLIENT) + " 127.0.0.1 " + std::to_string(port), client_log);
  {
    IgtlClient vanishing(port);
    ASSERT_TRUE(vanishing.connected());
    ASSERT_FALSE(vanishing.next().type.empty());
  }  // closed after one message, with the rest of the scan's messages unread
  // Debian's client killed mid-scan, as a crashed viewer would be.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  kill(receiver, SIGKILL);
  waitpid(receiver, nullptr, 0);

  ASSERT_EQ(wait_exit(scan, 60.0 * kSlowdown), 0) << file_text(scan_log);
  const std::string scan_text = file_text(scan_log);
  EXPECT_TRUE(contains(scan_text, "scan summary (source ended"));
  EXPECT_EQ(summary_slices(scan_text), summary_slices(file_text(alone_log))) << scan_text;
  EXPECT_NE(summary_slices(scan_text), "?");
  EXPECT_FALSE(contains(scan_text, "error:"));
  EXPECT_TRUE(contains(file_text(client_log), "Receiving IMAGE data type."));
}

TEST(IgtlPeers, DebiansPolyDataClientGetsTheSurfacesItAsksFor) {
  sonoshape::publish::IgtlServerOptions options;
  options.port = 0;
  auto server = sonoshape::publish::IgtlServer::start(options);
  ASSERT_TRUE(server) << server.message();
  sonoshape::MeshSet meshes;
  sonoshape::TriangleMesh tetrahedron;
  tetrahedron.vertices = {sonoshape::Vec3(0, 0, 0), sonoshape::Vec3(10, 0, 0),
                          sonoshape::Vec3(0, 10, 0), sonoshape::Vec3(0, 0, 10)};
  tetrahedron.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  meshes.meshes.push_back({1, "liver", tetrahedron});
  ASSERT_TRUE(server->publish_meshes(meshes));

  sonoshape::testing::TempDir dir;
  const fs::path log = dir.path() / "polydata.log";
  // The example sends GET_POLYDATA ten times, half a second apart, and reads one reply each.
  const pid_t client =
      spawn(std::string(POLYDATA_CLIENT) + " 127.0.0.1 " + std::to_string(server->port()), log);
  // Its first read is the surface the server sends on connection; its requests are answered.
  ASSERT_EQ(wait_exit(client, 20.0 * kSlowdown), 0) << file_text(log);
  const std::string text = file_text(log);
  EXPECT_EQ(count(text, "Receiving POLYDATA data type."), 10u) << text;
  EXPECT_FALSE(contains(text, "Invalid response"));
  EXPECT_TRUE(contains(text, "point[1] = (10, 0, 0)"));
  EXPECT_TRUE(contains(text, "cell[3] = (1, 1, 2, 3)"));  // its print repeats the first index
  EXPECT_GE(server->stats().requests_answered, 9u);
}

}  // namespace
}  // namespace igtl_peer_test
