// `sonoshape view` and `scan --view` end to end: the command as a child process (against a
// publisher in this process, or its own simulated scan), and a page's WebSocket and HTTP requests.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "sonoshape/publish/publisher.hpp"
#include "sonoshape/testing/child_process.hpp"
#include "sonoshape/testing/temp_dir.hpp"
#include "view_client.hpp"

namespace sonoshape::publish::view_command_test {
namespace {

using namespace std::chrono_literals;
using namespace sonoshape::testing::view;
using sonoshape::testing::TempDir;
using Clock = std::chrono::steady_clock;

std::vector<std::string> with_binary(const std::string& command,
                                     const std::vector<std::string>& arguments) {
  std::vector<std::string> argv{SONOSHAPE_BINARY, command};
  argv.insert(argv.end(), arguments.begin(), arguments.end());
  return argv;
}

// A running `sonoshape view` (or another subcommand), its output captured in a file.
class ViewProcess : public sonoshape::testing::ChildProcess {
 public:
  ViewProcess(const std::vector<std::string>& arguments, std::filesystem::path log,
              const std::string& command = "view")
      : ChildProcess(with_binary(command, arguments), std::move(log)) {}

  /// The page's address the command printed after `lead` ("open " for view, "live view at " for
  /// scan); empty when it printed none within `timeout`.
  std::string url(std::chrono::seconds timeout, const std::string& lead = "open ") const {
    const std::regex address(lead + R"((http://127\.0\.0\.1:[0-9]+/))");
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
      std::smatch match;
      const std::string text = output();
      if (std::regex_search(text, match, address)) return match[1];
      std::this_thread::sleep_for(20ms);
    }
    return {};
  }
};

TriangleMesh triangle(double size_mm) {
  TriangleMesh mesh;
  mesh.vertices = {Vec3(0, 0, 0), Vec3(size_mm, 0, 0), Vec3(0, size_mm, 0)};
  mesh.triangles = {{0, 1, 2}};
  return mesh;
}

TEST(ViewCommand, ServesThePageAndRelaysARunningScanUntilInterrupted) {
  TempDir dir;
  write_web_root(dir.path() / "web", true);
  PublisherOptions options;
  options.endpoint = "tcp://127.0.0.1:*";
  options.snapshot_endpoint = "tcp://127.0.0.1:*";
  options.linger_ms = 0;
  MeshPublisher publisher = MeshPublisher::bind(options).value();
  MeshSet meshes;
  meshes.meshes = {{1, "liver", triangle(10.0)}, {3, "bone", triangle(4.0)}};
  ASSERT_TRUE(publisher.publish_meshes(meshes, 0.5, 2));

  ViewProcess view({publisher.endpoint(), "--snapshot", publisher.snapshot_endpoint(), "--http",
                    "127.0.0.1:0", "--duration", "60", "--web-root", (dir.path() / "web").string()},
                   dir.path() / "view.log");
  const std::string url = view.url(20s);
  ASSERT_FALSE(url.empty()) << view.output();
  EXPECT_EQ(http_get(url, "/").status, 200u);

  Page page(url);
  const Frames liver = page.read_topic("mesh.1");
  EXPECT_NE(liver.at(1).find("\"liver\""), std::string::npos);
  page.read_topic("mesh.3");
  StatusReport status;
  status.frames_received = 77;
  ASSERT_TRUE(publisher.publish_status(status));
  const Frames live = page.read_topic("status");
  EXPECT_NE(live.at(1).find("\"frames_received\":77"), std::string::npos) << live.at(1);

  view.signal(SIGINT);
  EXPECT_EQ(view.wait(10s), 0) << view.output();
  EXPECT_NE(view.output().find("view: relayed"), std::string::npos) << view.output();
}

TEST(ViewCommand, RefusesAnAddressItCannotServeOn) {
  TempDir dir;
  ViewProcess view({"tcp://127.0.0.1:5556", "--http", "127.0.0.1:http"}, dir.path() / "view.log");
  EXPECT_EQ(view.wait(20s), 1);
  EXPECT_NE(view.output().find("error: viewer address '127.0.0.1:http'"), std::string::npos)
      << view.output();
}

TEST(ViewCommand, NeedsASnapshotEndpointItCannotGuess) {
  TempDir dir;
  ViewProcess view({"ipc:///tmp/sonoshape-view-test", "--http", "127.0.0.1:0"},
                   dir.path() / "view.log");
  EXPECT_EQ(view.wait(20s), 1);
  EXPECT_NE(view.output().find("--snapshot"), std::string::npos) << view.output();
}

TEST(ScanView, ServesTheScanItselfAndHoldsTheFinishedOneUntilInterrupted) {
  TempDir dir;
  const std::filesystem::path out = dir.path() / "out";
  ViewProcess scan({"--source",
                    "sim:default",
                    "--width-px",
                    "160",
                    "--height-px",
                    "160",
                    "--frame-rate",
                    "5",
                    "--depth",
                    "5",
                    "--sweep-s",
                    "2",
                    "--fast",
                    "--publish",
                    "tcp://127.0.0.1:*",
                    "--snapshot",
                    "tcp://127.0.0.1:*",
                    "--view",
                    "127.0.0.1:0",
                    "--view-hold",
                    "-o",
                    out.string()},
                   dir.path() / "scan.log", "scan");
  const std::string url = scan.url(60s, "live view at ");
  ASSERT_FALSE(url.empty()) << scan.output();
  ASSERT_TRUE(scan.shows("shows it until Ctrl-C", 120s)) << scan.output();
  EXPECT_EQ(http_get(url, "/").status, 200u);

  // A page opened after the scan: every slice, the finished surfaces, the final status and the
  // newest B-mode frame (--view publishes frame previews).
  Page page(url);
  const nlohmann::json summary = nlohmann::json::parse(std::ifstream(out / "scan.json"));
  const auto slices = summary["slices"].get<std::size_t>();
  std::map<std::string, Frames> newest;
  std::set<std::uint64_t> slice_indices;
  // The newest of every topic (viewer, mesh.1 to mesh.3, status, frame) and every slice, in the
  // order they first came.
  for (int i = 0; i < 1000 && !(newest.count("status") && newest.count("mesh.2") &&
                                newest.count("frame") && slice_indices.size() == slices);
       ++i) {
    Frames frames = page.read();
    ASSERT_FALSE(frames.empty());
    if (frames[0] == "slice") {
      Result<StreamMessage> slice = decode_message(frames);
      ASSERT_TRUE(slice) << slice.message();
      slice_indices.insert(std::get<SliceUpdate>(slice->body).index);
    }
    newest[frames[0]] = std::move(frames);
  }
  EXPECT_EQ(slice_indices.size(), slices);
  EXPECT_TRUE(newest.count("frame"));
  ASSERT_TRUE(newest.count("mesh.1") && newest.count("mesh.2")) << newest.begin()->first;
  EXPECT_TRUE(decode_message(newest["mesh.2"]));
  // The scan prints its hold line as it publishes its final (idle) status, which reaches the
  // page through the subscriber a moment later: a page may first get the last scanning status.
  Result<StreamMessage> decoded = decode_message(newest["status"]);
  ASSERT_TRUE(decoded) << decoded.message();
  for (int i = 0; i < 100 && std::get<StatusReport>(decoded->body).state != ScanState::kIdle; ++i) {
    Frames frames = page.read();
    ASSERT_FALSE(frames.empty());
    if (frames[0] != "status") continue;
    decoded = decode_message(frames);
    ASSERT_TRUE(decoded) << decoded.message();
  }
  const auto& report = std::get<StatusReport>(decoded->body);
  EXPECT_EQ(report.state, ScanState::kIdle);
  EXPECT_EQ(report.frames_received, summary["frames_received"].get<std::uint64_t>());
  EXPECT_EQ(report.slices, summary["slices"].get<std::uint64_t>());

  scan.signal(SIGINT);
  EXPECT_EQ(scan.wait(10s), 0) << scan.output();
}

// Issue 40, "a finished scan reads as finished": without --view-hold, `scan --view` lets the
// scan's last status (`"finished": true`, its final counts) reach a page open during the scan
// before its server goes, and says what a page opened later gets.
TEST(ScanView, WithoutHoldAnOpenPageGetsTheFinishedStatusBeforeTheServerGoes) {
  TempDir dir;
  const std::filesystem::path out = dir.path() / "out";
  ViewProcess scan({"--source",
                    "sim:default",
                    "--width-px",
                    "160",
                    "--height-px",
                    "160",
                    "--frame-rate",
                    "5",
                    "--depth",
                    "5",
                    "--sweep-s",
                    "2",
                    "--realtime",
                    "--publish",
                    "tcp://127.0.0.1:*",
                    "--snapshot",
                    "tcp://127.0.0.1:*",
                    "--publish-frames",
                    "0",
                    "--view",
                    "127.0.0.1:0",
                    "-o",
                    out.string()},
                   dir.path() / "scan.log", "scan");
  const std::string url = scan.url(60s, "live view at ");
  ASSERT_FALSE(url.empty()) << scan.output();
  Page page(url);
  const std::vector<Frames> messages = page.read_until_closed(120s);
  EXPECT_EQ(scan.wait(30s), 0) << scan.output();
  EXPECT_TRUE(
      scan.shows("closes with the scan: pages open now keep showing the finished scan, "
                 "a page opened later finds no server (--view-hold keeps serving it",
                 1s))
      << scan.output();

  const nlohmann::json summary = nlohmann::json::parse(std::ifstream(out / "scan.json"));
  std::optional<StatusReport> last_status;
  bool mesh = false;
  for (const Frames& frames : messages) {
    mesh = mesh || frames.at(0) == "mesh.1";
    if (frames.at(0) != "status") continue;
    Result<StreamMessage> decoded = decode_message(frames);
    ASSERT_TRUE(decoded) << decoded.message();
    last_status = std::get<StatusReport>(decoded->body);
  }
  EXPECT_TRUE(mesh);
  ASSERT_TRUE(last_status.has_value()) << messages.size() << " messages, no status";
  EXPECT_TRUE(last_status->finished) << scan.output();
  EXPECT_EQ(last_status->state, ScanState::kIdle);
  EXPECT_EQ(last_status->frame_rate_hz, 0.0);  // --publish-frames 0: the page says why none
  EXPECT_EQ(last_status->slices, summary["slices"].get<std::uint64_t>());
  EXPECT_EQ(last_status->frames_received, summary["frames_received"].get<std::uint64_t>());
}

}  // namespace
}  // namespace sonoshape::publish::view_command_test
