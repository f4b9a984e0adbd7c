// Who may read the mesh stream: CURVE key files, the refusal of reachable endpoints without
// --allow-remote and a key, subscribers with and without the right server key, and the bound
// on snapshot requests. Every socket binds loopback port "*" unless the test is about others.
#include "sonoshape/publish/curve.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <thread>
#include <zmq.hpp>
#include <zmq_addon.hpp>

#include "sonoshape/publish/publisher.hpp"
#include "sonoshape/publish/subscriber.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::publish::curve_test {
namespace {

using namespace std::chrono_literals;
using sonoshape::testing::contains;
using sonoshape::testing::TempDir;
using Clock = std::chrono::steady_clock;

CurveKeyPair keys_or_fail() {
  Result<CurveKeyPair> keys = generate_curve_keypair();
  if (!keys) throw std::runtime_error(keys.message());
  return *keys;
}

PublisherOptions curve_options(const CurveKeyPair& keys) {
  PublisherOptions options;
  options.endpoint = "tcp://127.0.0.1:*";
  options.snapshot_endpoint = "tcp://127.0.0.1:*";
  options.send_hwm = 100000;
  options.linger_ms = 0;
  options.curve_secret_key = keys.secret_key;
  return options;
}

MeshPublisher bind_or_fail(const PublisherOptions& options) {
  Result<MeshPublisher> publisher = MeshPublisher::bind(options);
  if (!publisher) throw std::runtime_error(publisher.message());
  return std::move(*publisher);
}

StatusReport status_of(std::uint64_t slices) {
  StatusReport status;
  status.slices = slices;
  status.frames_received = 2 * slices;
  return status;
}

LabeledSlice square_slice(double z) {
  LabeledSlice slice;
  slice.origin_mm = Vec3(0, 0, z);
  Region region;
  region.outer = {Vec2(-1, -1), Vec2(1, -1), Vec2(1, 1), Vec2(-1, 1)};
  slice.regions = {region};
  return slice;
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  std::ofstream(path) << text;
}

// Every message `subscriber` has within `quiet` of the one before, until none comes.
std::vector<StreamMessage> drain(MeshSubscriber& subscriber, std::chrono::milliseconds quiet) {
  std::vector<StreamMessage> messages;
  while (true) {
    auto received = subscriber.receive(quiet);
    if (!received) throw std::runtime_error("invalid message: " + received.message());
    if (!*received) return messages;
    messages.push_back(std::move(**received));
  }
}

TEST(CurveKeys, KeyFilesRoundTripAndTheSecretIsPrivate) {
  TempDir dir;
  const CurveKeyPair keys = keys_or_fail();
  ASSERT_TRUE(write_curve_keypair(dir.path() / "scanner", keys));
  Result<std::string> secret = read_curve_key(dir.path() / "scanner.key", "secret");
  Result<std::string> pub = read_curve_key(dir.path() / "scanner.pub", "public");
  ASSERT_TRUE(secret.is_ok()) << secret.message();
  ASSERT_TRUE(pub.is_ok()) << pub.message();
  EXPECT_EQ(*secret, keys.secret_key);
  EXPECT_EQ(*pub, keys.public_key);
  EXPECT_EQ(*curve_public_key_of(*secret), *pub);
  struct stat info {};
  ASSERT_EQ(::stat((dir.path() / "scanner.key").c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0777, 0600u);

  // Never replaced: a second pair under the same name would orphan every subscriber's key.
  Status again = write_curve_keypair(dir.path() / "scanner", keys_or_fail());
  ASSERT_FALSE(again.is_ok());
  EXPECT_TRUE(contains(again.message(), "scanner.pub"));
  EXPECT_TRUE(contains(again.message(), "exists already"));
  EXPECT_EQ(*read_curve_key(dir.path() / "scanner.key", "secret"), keys.secret_key);
}

// Issue 40, S6: a secret key others can read or write is used, but never without a warning.
TEST(CurveKeys, ASecretKeyFileOthersCanReadOrWriteIsReadWithAWarningNamingTheFix) {
  TempDir dir;
  const CurveKeyPair keys = keys_or_fail();
  ASSERT_TRUE(write_curve_keypair(dir.path() / "scanner", keys));
  const std::filesystem::path key = dir.path() / "scanner.key";
  ::testing::internal::CaptureStderr();
  EXPECT_EQ(*read_curve_key(key, "secret"), keys.secret_key);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "") << "a 0600 key warned";
  EXPECT_FALSE(secret_key_file_exposure(key));

  ASSERT_EQ(::chmod(key.c_str(), 0644), 0);
  ::testing::internal::CaptureStderr();
  EXPECT_EQ(*read_curve_key(key, "secret"), keys.secret_key);
  const std::string said = ::testing::internal::GetCapturedStderr();
  EXPECT_TRUE(contains(said, "warning: the CURVE secret key " + key.string() + " has mode 0644"))
      << said;
  EXPECT_TRUE(contains(said, "can read it")) << said;
  EXPECT_TRUE(contains(said, "chmod 600 " + key.string())) << said;

  ASSERT_EQ(::chmod(key.c_str(), 0620), 0);  // writable by the group
  const auto writable = secret_key_file_exposure(key);
  ASSERT_TRUE(writable);
  EXPECT_TRUE(contains(*writable, "mode 0620")) << *writable;
  EXPECT_TRUE(contains(*writable, "can change it")) << *writable;

  // A public key is for sharing: no warning.
  ::testing::internal::CaptureStderr();
  EXPECT_TRUE(read_curve_key(dir.path() / "scanner.pub", "public"));
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
}

TEST(CurveKeys, BadKeyFilesAreErrorsNamingTheFile) {
  TempDir dir;
  const CurveKeyPair keys = keys_or_fail();
  struct Case {
    const char* name;
    std::string text;
    const char* says;
  };
  const std::vector<Case> cases = {
      {"short.pub", keys.public_key.substr(0, 39) + "\n", "has 39 characters, a Z85 key has 40"},
      {"long.pub", keys.public_key + "A\n", "has 41 characters"},
      {"quote.pub", "\"" + keys.public_key.substr(1) + "\n", "character 1 of the key is not Z85"},
      {"comma.pub", keys.public_key.substr(0, 20) + "," + keys.public_key.substr(21) + "\n",
       "character 21 of the key is not Z85"},
      {"empty.pub", "# nothing here\n\n", "holds no key line"},
      {"two.pub", keys.public_key + "\n" + keys.public_key + "\n", "line 2: a second key line"},
      {"secret.pub", "# sonoshape CURVE secret key\n" + keys.secret_key + "\n",
       "holds a CURVE secret key, not a public key"},
  };
  for (const Case& c : cases) {
    write_text(dir.path() / c.name, c.text);
    Result<std::string> key = read_curve_key(dir.path() / c.name, "public");
    ASSERT_FALSE(key.is_ok()) << c.name;
    EXPECT_TRUE(contains(key.message(), (dir.path() / c.name).string())) << c.name;
    EXPECT_TRUE(contains(key.message(), c.says)) << c.name;
    EXPECT_TRUE(contains(key.message(), "NAME.pub")) << c.name;  // the fix
  }
  Result<std::string> missing = read_curve_key(dir.path() / "absent.key", "secret");
  ASSERT_FALSE(missing.is_ok());
  EXPECT_TRUE(contains(missing.message(), "absent.key"));
  // Comments, blank lines, surrounding blanks and CRLF are fine around the one key line.
  write_text(dir.path() / "ok.pub", "# a comment\r\n\r\n  " + keys.public_key + " \r\n");
  EXPECT_EQ(*read_curve_key(dir.path() / "ok.pub", "public"), keys.public_key);
}

TEST(StreamAccess, OnlyLoopbackIpcAndInprocAreLocal) {
  for (const char* local : {"tcp://127.0.0.1:5556", "tcp://127.8.9.10:*", "tcp://localhost:5556",
                            "tcp://[::1]:5556", "ipc:///tmp/stream", "inproc://stream"})
    EXPECT_TRUE(is_local_endpoint(local)) << local;
  for (const char* remote :
       {"tcp://*:5556", "tcp://0.0.0.0:5556", "tcp://192.168.1.4:5556", "tcp://eth0:5556",
        "tcp://[::]:5556", "tcp://128.0.0.1:5556", "tcp://127.0.0.1.evil:5556", "ws://*:5556",
        "pgm://eth0;239.1.1.1:5555"})
    EXPECT_FALSE(is_local_endpoint(remote)) << remote;
}

TEST(StreamAccess, ReachableBindIsRefusedWithoutAllowRemoteAndAKey) {
  const CurveKeyPair keys = keys_or_fail();
  PublisherOptions options = curve_options(keys);
  options.curve_secret_key.clear();
  options.endpoint = "tcp://*:*";
  Result<MeshPublisher> plain = MeshPublisher::bind(options);
  ASSERT_FALSE(plain.is_ok());
  EXPECT_TRUE(contains(plain.message(), "refusing to publish on tcp://*:* (--publish)"));
  EXPECT_TRUE(contains(plain.message(), "add --allow-remote and --curve-secret-key FILE"));
  EXPECT_TRUE(contains(plain.message(), "sonoshape keys -o NAME"));

  options.allow_remote = true;
  Result<MeshPublisher> unkeyed = MeshPublisher::bind(options);
  ASSERT_FALSE(unkeyed.is_ok());
  EXPECT_TRUE(contains(unkeyed.message(), "add --curve-secret-key FILE"));

  options.allow_remote = false;
  options.curve_secret_key = keys.secret_key;
  Result<MeshPublisher> not_allowed = MeshPublisher::bind(options);
  ASSERT_FALSE(not_allowed.is_ok());
  EXPECT_TRUE(contains(not_allowed.message(), "add --allow-remote ("));

  // The snapshot server is checked too, with its own option in the message.
  PublisherOptions snapshot = curve_options(keys);
  snapshot.curve_secret_key.clear();
  snapshot.snapshot_endpoint = "tcp://0.0.0.0:*";
  Result<MeshPublisher> open_snapshot = MeshPublisher::bind(snapshot);
  ASSERT_FALSE(open_snapshot.is_ok());
  EXPECT_TRUE(contains(open_snapshot.message(), "tcp://0.0.0.0:* (--snapshot)"));

  // Both given: it binds, as a CURVE server.
  options.allow_remote = true;
  options.snapshot_endpoint = "tcp://*:*";
  Result<MeshPublisher> allowed = MeshPublisher::bind(options);
  EXPECT_TRUE(allowed.is_ok()) << allowed.message();

  // Loopback stays plain unless a key is given.
  PublisherOptions loopback = curve_options(keys);
  loopback.curve_secret_key.clear();
  EXPECT_TRUE(MeshPublisher::bind(loopback).is_ok());
}

TEST(StreamAccess, BadServerSecretKeyIsRefusedAtBind) {
  PublisherOptions options = curve_options(keys_or_fail());
  options.curve_secret_key = "too short";
  Result<MeshPublisher> publisher = MeshPublisher::bind(options);
  ASSERT_FALSE(publisher.is_ok());
  EXPECT_TRUE(contains(publisher.message(), "not a CURVE secret key"));
}

TEST(StreamAccess, SubscriberWithTheServerKeyReceivesEveryMessage) {
  const CurveKeyPair keys = keys_or_fail();
  MeshPublisher publisher = bind_or_fail(curve_options(keys));
  ASSERT_TRUE(publisher.publish_slice(square_slice(0.0), 0));
  SubscriberOptions options;
  options.endpoint = publisher.endpoint();
  options.snapshot_endpoint = publisher.snapshot_endpoint();
  options.server_public_key = keys.public_key;
  options.receive_hwm = 100000;
  Result<MeshSubscriber> subscriber = MeshSubscriber::connect(options);
  ASSERT_TRUE(subscriber.is_ok()) << subscriber.message();

  constexpr std::uint64_t kLive = 200;
  for (std::uint64_t k = 1; k <= kLive; ++k) {
    if (k % 2)
      ASSERT_TRUE(publisher.publish_slice(square_slice(double(k)), k));
    else
      ASSERT_TRUE(publisher.publish_status(status_of(k)));
  }
  const std::vector<StreamMessage> messages = drain(*subscriber, 1s);
  // The snapshot (the first slice, then its end at seq 1), then every live message in order.
  ASSERT_EQ(messages.size(), 2 + kLive);
  EXPECT_EQ(messages[0].topic(), "slice");
  EXPECT_EQ(messages[1].topic(), "end");
  EXPECT_EQ(messages[1].seq, 1u);
  for (std::uint64_t k = 1; k <= kLive; ++k) {
    EXPECT_EQ(messages[1 + k].seq, 1 + k);
    EXPECT_EQ(messages[1 + k].topic(), k % 2 ? "slice" : "status");
  }
}

TEST(StreamAccess, SubscribersWithoutTheRightKeyReceiveNothing) {
  const CurveKeyPair keys = keys_or_fail();
  const CurveKeyPair other = keys_or_fail();
  MeshPublisher publisher = bind_or_fail(curve_options(keys));

  // Through the snapshot, connect() itself says that the handshake was refused.
  for (const std::string& server_key : {std::string(), other.public_key}) {
    SubscriberOptions options;
    options.endpoint = publisher.endpoint();
    options.snapshot_endpoint = publisher.snapshot_endpoint();
    options.server_public_key = server_key;
    options.snapshot_timeout_ms = 1500;
    Result<MeshSubscriber> refused = MeshSubscriber::connect(options);
    ASSERT_FALSE(refused.is_ok()) << "server key '" << server_key << "'";
    EXPECT_TRUE(contains(refused.message(), "refused the handshake")) << refused.message();
    EXPECT_TRUE(contains(refused.message(), "--server-key")) << refused.message();
  }

  // Live only: connected (as far as they know) while the right subscriber receives everything.
  SubscriberOptions plain;
  plain.endpoint = publisher.endpoint();
  SubscriberOptions wrong = plain;
  wrong.server_public_key = other.public_key;
  SubscriberOptions right = plain;
  right.server_public_key = keys.public_key;
  right.receive_hwm = 100000;
  std::vector<MeshSubscriber> outsiders;
  for (const SubscriberOptions& o : {plain, wrong}) {
    Result<MeshSubscriber> s = MeshSubscriber::connect(o);
    ASSERT_TRUE(s.is_ok()) << s.message();
    outsiders.push_back(std::move(*s));
  }
  // A raw socket with no security at all, as any program on the network could open.
  zmq::context_t context;
  zmq::socket_t raw(context, zmq::socket_type::sub);
  raw.set(zmq::sockopt::linger, 0);
  raw.set(zmq::sockopt::subscribe, "");
  raw.connect(publisher.endpoint());
  zmq::socket_t raw_snapshot(context, zmq::socket_type::dealer);
  raw_snapshot.set(zmq::sockopt::linger, 0);
  raw_snapshot.connect(publisher.snapshot_endpoint());
  raw_snapshot.send(zmq::str_buffer("snapshot"), zmq::send_flags::dontwait);

  Result<MeshSubscriber> insider = MeshSubscriber::connect(right);
  ASSERT_TRUE(insider.is_ok()) << insider.message();
  // Statuses until the right subscriber has one: the others had as long to connect.
  const auto deadline = Clock::now() + 10s;
  std::uint64_t first = 0;
  while (!first && Clock::now() < deadline) {
    ASSERT_TRUE(publisher.publish_status(status_of(0)));
    auto received = insider->receive(20ms);
    ASSERT_TRUE(received.is_ok());
    if (*received) first = (*received)->seq;
  }
  ASSERT_GT(first, 0u);
  constexpr std::uint64_t kLive = 100;
  for (std::uint64_t k = 0; k < kLive; ++k)
    ASSERT_TRUE(publisher.publish_slice(square_slice(k), k));
  const std::vector<StreamMessage> received = drain(*insider, 1s);
  ASSERT_EQ(received.size(), publisher.last_seq() - first);
  for (std::size_t k = 0; k < received.size(); ++k) EXPECT_EQ(received[k].seq, first + 1 + k);

  for (MeshSubscriber& outsider : outsiders) EXPECT_TRUE(drain(outsider, 300ms).empty());
  std::vector<zmq::pollitem_t> items{{raw.handle(), 0, ZMQ_POLLIN, 0},
                                     {raw_snapshot.handle(), 0, ZMQ_POLLIN, 0}};
  EXPECT_EQ(zmq::poll(items, 300ms), 0);
  EXPECT_EQ(publisher.snapshots_served(), 0u);
}

TEST(StreamAccess, SnapshotFloodGetsBusyRepliesAndLiveUpdatesGoOnWithoutGaps) {
  PublisherOptions options = curve_options(keys_or_fail());
  options.curve_secret_key.clear();  // the bound holds with or without CURVE
  options.snapshot_burst = 4;
  options.snapshot_rate_hz = 5.0;
  MeshPublisher publisher = bind_or_fail(options);
  // A scan's worth of slices: every snapshot answered is a large reply.
  for (std::uint64_t k = 0; k < 1000; ++k) ASSERT_TRUE(publisher.publish_slice(square_slice(k), k));

  SubscriberOptions live;
  live.endpoint = publisher.endpoint();
  live.receive_hwm = 100000;
  Result<MeshSubscriber> keeping_up = MeshSubscriber::connect(live);
  ASSERT_TRUE(keeping_up.is_ok());
  const auto deadline = Clock::now() + 10s;
  std::uint64_t first = 0;
  while (!first && Clock::now() < deadline) {
    ASSERT_TRUE(publisher.publish_status(status_of(0)));
    auto received = keeping_up->receive(20ms);
    ASSERT_TRUE(received.is_ok());
    if (*received) first = (*received)->seq;
  }
  ASSERT_GT(first, 0u);

  // The flood: a client asking for snapshots as fast as it can, reading what comes back.
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> busy{0};
  std::atomic<std::uint64_t> ends{0};
  std::atomic<std::uint64_t> sent{0};
  std::string busy_reply;
  std::thread flood([&] {
    zmq::context_t context;
    zmq::socket_t dealer(context, zmq::socket_type::dealer);
    dealer.set(zmq::sockopt::linger, 0);
    dealer.connect(publisher.snapshot_endpoint());
    std::vector<zmq::message_t> parts;
    while (!stop) {
      if (dealer.send(zmq::str_buffer("snapshot"), zmq::send_flags::dontwait)) ++sent;
      while (true) {
        parts.clear();
        if (!zmq::recv_multipart(dealer, std::back_inserter(parts), zmq::recv_flags::dontwait))
          break;
        if (parts[0].to_string_view() == "end") ++ends;
        if (parts[0].to_string_view() == "error") {
          if (busy_reply.empty()) busy_reply = parts[1].to_string();
          ++busy;
        }
      }
    }
  });

  const auto start = Clock::now();
  double slowest_s = 0.0;
  constexpr std::uint64_t kLive = 1000;
  for (std::uint64_t k = 0; k < kLive; ++k) {
    const auto before = Clock::now();
    ASSERT_TRUE(publisher.publish_status(status_of(k)));
    slowest_s = std::max(slowest_s, std::chrono::duration<double>(Clock::now() - before).count());
    std::this_thread::sleep_for(1ms);
  }
  const double flood_s = std::chrono::duration<double>(Clock::now() - start).count();
  stop = true;
  flood.join();

  // The subscriber keeping up saw every live update, in order.
  const std::vector<StreamMessage> received = drain(*keeping_up, 1s);
  ASSERT_EQ(received.size(), publisher.last_seq() - first);
  for (std::size_t k = 0; k < received.size(); ++k) ASSERT_EQ(received[k].seq, first + 1 + k);
  EXPECT_LT(slowest_s, 0.5);  // sub-millisecond unloaded; room for sanitizer builds
  // Snapshots: the burst and the rate, no more; the rest were told to wait.
  EXPECT_GT(sent.load(), 100u);
  EXPECT_LE(publisher.snapshots_served(), 4 + static_cast<std::uint64_t>(5.0 * flood_s) + 2);
  EXPECT_GT(publisher.snapshots_refused(), 0u);
  EXPECT_GT(busy.load(), 0u);
  EXPECT_LE(ends.load(), publisher.snapshots_served());
  EXPECT_TRUE(contains(busy_reply, "\"busy\":true"));
  EXPECT_TRUE(contains(busy_reply, "retry in"));

  // A polite client asking now is told to wait, waits, and gets its snapshot.
  SubscriberOptions late = live;
  late.snapshot_endpoint = publisher.snapshot_endpoint();
  Result<MeshSubscriber> joined = MeshSubscriber::connect(late);
  ASSERT_TRUE(joined.is_ok()) << joined.message();
  EXPECT_EQ(joined->snapshot_seq(), publisher.last_seq());
}

}  // namespace
}  // namespace sonoshape::publish::curve_test

namespace sonoshape::publish::curve_test {
namespace {

// Issue 40: a key file saved by an editor that starts UTF-8 files with a byte-order mark was
// refused as "43 characters"; the mark is not part of the key.
TEST(CurveKeys, AKeyFileWithAUtf8ByteOrderMarkReadsTheKey) {
  const testing::TempDir dir;
  const CurveKeyPair keys = keys_or_fail();
  std::ofstream(dir.path() / "bom.pub") << "\xEF\xBB\xBF" << keys.public_key << "\r\n";
  const Result<std::string> key = read_curve_key(dir.path() / "bom.pub", "public");
  ASSERT_TRUE(key) << key.message();
  EXPECT_EQ(*key, keys.public_key);
}

}  // namespace
}  // namespace sonoshape::publish::curve_test
