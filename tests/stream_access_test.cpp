// Who may read the stream, as a user runs it (issue 27): `sonoshape keys`, `scan --publish`
// refusing an endpoint other machines can reach without --allow-remote and a key, and an
// encrypted scan that a listener with the key follows to the end while listeners without it
// (no key, another scan's key) receive nothing.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "sonoshape/testing/command.hpp"
#include "sonoshape/testing/json_file.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace stream_access_test {
namespace {

namespace fs = std::filesystem;
using sonoshape::testing::contains;
using sonoshape::testing::file_text;
using sonoshape::testing::read_json;
using sonoshape::testing::run_command;
using sonoshape::testing::spawn;
using sonoshape::testing::wait_exit;

// A small, quick simulated scan (160 x 160 px, 5 fps, coarse reconstruction).
const std::string kSmallSim =
    "scan --source sim:default --width-px 160 --height-px 160 --frame-rate 5 --depth 5 ";

TEST(StreamAccessCommand, KeysWritesAPairAndNeverReplacesIt) {
  sonoshape::testing::TempDir dir;
  const fs::path base = dir.path() / "scanner";
  const auto made = run_command(SONOSHAPE_BINARY, "keys -o " + base.string(), dir.path() / "a");
  ASSERT_EQ(made.exit_code, 0) << made.output;
  EXPECT_EQ(fs::status(base.string() + ".key").permissions() & fs::perms::all,
            fs::perms::owner_read | fs::perms::owner_write);
  const std::string secret = file_text(base.string() + ".key");
  const auto again = run_command(SONOSHAPE_BINARY, "keys -o " + base.string(), dir.path() / "b");
  EXPECT_EQ(again.exit_code, 1);
  EXPECT_TRUE(contains(again.output, "exists already"));
  EXPECT_EQ(file_text(base.string() + ".key"), secret);
}

TEST(StreamAccessCommand, ScanRefusesAReachableEndpointWithoutAllowRemoteAndAKey) {
  sonoshape::testing::TempDir dir;
  const fs::path base = dir.path() / "scanner";
  ASSERT_EQ(run_command(SONOSHAPE_BINARY, "keys -o " + base.string(), dir.path() / "k").exit_code,
            0);
  struct Case {
    std::string extra;
    const char* says;
  };
  for (const Case& c :
       {Case{"", "add --allow-remote and --curve-secret-key FILE"},
        Case{"--allow-remote", "add --curve-secret-key FILE"},
        Case{"--curve-secret-key " + base.string() + ".key", "add --allow-remote ("}}) {
    const auto refused = run_command(
        SONOSHAPE_BINARY, kSmallSim + "--sweep-s 1 --fast --publish tcp://*:5651 " + c.extra,
        dir.path() / "scan.log");
    EXPECT_EQ(refused.exit_code, 1) << c.extra;
    EXPECT_TRUE(contains(refused.output, "refusing to publish on tcp://*:5651 (--publish)"))
        << refused.output;
    EXPECT_TRUE(contains(refused.output, c.says)) << refused.output;
  }
  // A key file that is no key is named, with the fix.
  std::ofstream(dir.path() / "bad.key") << "not a key\n";
  const auto bad = run_command(
      SONOSHAPE_BINARY,
      kSmallSim + "--sweep-s 1 --fast --publish tcp://127.0.0.1:5653 --curve-secret-key " +
          (dir.path() / "bad.key").string(),
      dir.path() / "bad.log");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_TRUE(contains(bad.output, "--curve-secret-key: " + (dir.path() / "bad.key").string()))
      << bad.output;
}

TEST(StreamAccessCommand, OnlyTheListenerWithTheServerKeyReadsAnEncryptedScan) {
  sonoshape::testing::TempDir dir;
  const std::string bin = SONOSHAPE_BINARY;
  for (const char* name : {"scanner", "other"})
    ASSERT_EQ(
        run_command(bin, "keys -o " + (dir.path() / name).string(), dir.path() / "k").exit_code, 0);
  const std::string pub = "tcp://127.0.0.1:5655", snapshot = "tcp://127.0.0.1:5656";
  const pid_t scan =
      spawn(bin + " " + kSmallSim + "--sweep-s 3 --realtime --publish " + pub + " --snapshot " +
                snapshot + " --curve-secret-key " + (dir.path() / "scanner.key").string() + " -o " +
                (dir.path() / "out").string(),
            dir.path() / "scan.log");
  for (int k = 0; k < 400 && !contains(file_text(dir.path() / "scan.log"), "publishing scan"); ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  ASSERT_TRUE(contains(file_text(dir.path() / "scan.log"), "publishing scan"))
      << file_text(dir.path() / "scan.log");
  auto listen = [&](const std::string& name, const std::string& extra) {
    return spawn(bin + " listen " + pub + " -o " + (dir.path() / name).string() + " " + extra,
                 dir.path() / (name + ".log"));
  };
  const pid_t keyed = listen("keyed", "--snapshot " + snapshot + " --until-idle --duration 60 " +
                                          "--server-key " + (dir.path() / "scanner.pub").string());
  // Live only (no snapshot to be refused): they wait, and get nothing.
  const pid_t plain = listen("plain", "--no-snapshot --duration 60");
  const pid_t wrong = listen(
      "wrong", "--no-snapshot --duration 60 --server-key " + (dir.path() / "other.pub").string());
  const pid_t wrong_snapshot =
      listen("wrong_snapshot", "--snapshot " + snapshot + " --duration 60 --server-key " +
                                   (dir.path() / "other.pub").string());

  ASSERT_EQ(wait_exit(scan, 60.0), 0) << file_text(dir.path() / "scan.log");
  EXPECT_EQ(wait_exit(keyed, 20.0), 0) << file_text(dir.path() / "keyed.log");
  EXPECT_EQ(wait_exit(wrong_snapshot, 20.0), 1);
  EXPECT_TRUE(contains(file_text(dir.path() / "wrong_snapshot.log"), "refused the handshake"))
      << file_text(dir.path() / "wrong_snapshot.log");
  // The scan has ended: whatever they were going to get, they had.
  EXPECT_EQ(wait_exit(plain, 0.2, SIGTERM), 0);
  EXPECT_EQ(wait_exit(wrong, 0.2, SIGTERM), 0);

  const auto got = read_json(dir.path() / "keyed" / "summary.json");
  EXPECT_EQ(got["invalid"], 0);
  EXPECT_EQ(got["seq_gaps"], 0);
  EXPECT_EQ(got["last_state"], "idle");
  EXPECT_TRUE(got["meshes"].contains("1") && got["meshes"].contains("2")) << got.dump();
  for (const char* name : {"plain", "wrong"}) {
    const auto none = read_json(dir.path() / name / "summary.json");
    EXPECT_EQ(none["messages"], 0) << name << ": " << none.dump();
  }
}

}  // namespace
}  // namespace stream_access_test
