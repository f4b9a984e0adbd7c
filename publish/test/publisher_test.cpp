// MeshPublisher and MeshSubscriber over loopback: gapless delivery, the late-joiner snapshot, a
// slow subscriber that must not slow the publisher, and bind errors. Every test binds port "*"
// (a free port picked by the system), so parallel runs never collide.
#include "sonoshape/publish/publisher.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <regex>
#include <zmq.hpp>
#include <zmq_addon.hpp>

#include "sonoshape/publish/subscriber.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::publish::publisher_test {
namespace {

using namespace std::chrono_literals;
using sonoshape::testing::contains;
using Clock = std::chrono::steady_clock;

// Loopback on free ports; messages never dropped (the tests that check order read as fast as
// the publisher sends, but a loaded machine must not turn that into gaps).
PublisherOptions loopback_options(int send_hwm = 100000) {
  PublisherOptions options;
  options.endpoint = "tcp://127.0.0.1:*";
  options.snapshot_endpoint = "tcp://127.0.0.1:*";
  options.send_hwm = send_hwm;
  options.linger_ms = 0;
  return options;
}

MeshPublisher bind_or_fail(const PublisherOptions& options) {
  Result<MeshPublisher> publisher = MeshPublisher::bind(options);
  if (!publisher) throw std::runtime_error(publisher.message());
  return std::move(*publisher);
}

// An octahedron scaled by `size`: a closed mesh per label that changes from call to call.
TriangleMesh octahedron(double size, const Vec3& centre = Vec3::Zero()) {
  TriangleMesh mesh;
  for (const Vec3& d : {Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1),
                        Vec3(0, 0, -1)})
    mesh.vertices.push_back(centre + size * d);
  mesh.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                    {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  return mesh;
}

MeshSet two_organs(double size) {
  MeshSet set;
  set.meshes.push_back({1, "liver", octahedron(size)});
  set.meshes.push_back({2, "kidney", octahedron(size / 2, Vec3(10, 0, 0))});
  return set;
}

LabeledSlice square_slice(double z) {
  LabeledSlice slice;
  slice.origin_mm = Vec3(0, 0, z);
  Region region;
  region.outer = {Vec2(-1, -1), Vec2(1, -1), Vec2(1, 1), Vec2(-1, 1)};
  slice.regions = {region};
  return slice;
}

StatusReport scanning_status(std::uint64_t slices) {
  StatusReport status;
  status.slices = slices;
  status.frames_received = 2 * slices;
  status.total_ms = 12.5;
  return status;
}

StreamMessage receive_or_fail(MeshSubscriber& subscriber, std::chrono::milliseconds timeout = 5s) {
  auto received = subscriber.receive(timeout);
  if (!received) throw std::runtime_error("invalid message: " + received.message());
  if (!*received) throw std::runtime_error("no message within the timeout");
  return std::move(**received);
}

// Whether a raw socket has a message within `timeout`.
bool readable(zmq::socket_t& socket, std::chrono::milliseconds timeout) {
  std::vector<zmq::pollitem_t> items{{socket.handle(), 0, ZMQ_POLLIN, 0}};
  return zmq::poll(items, timeout) > 0;
}

// Publishes statuses until the subscriber gets one: from then on its subscription is live.
// Returns the seq of the status it got; later statuses of the warm-up are drained.
std::uint64_t warm_up(MeshPublisher& publisher, MeshSubscriber& subscriber) {
  const auto deadline = Clock::now() + 10s;
  while (Clock::now() < deadline) {
    EXPECT_TRUE(publisher.publish_status(scanning_status(0)));
    auto received = subscriber.receive(20ms);
    if (received && *received) {
      std::uint64_t seq = (*received)->seq;
      // Drain the rest so the caller starts right after the publisher's last seq.
      while (seq < publisher.last_seq()) seq = receive_or_fail(subscriber).seq;
      return seq;
    }
  }
  throw std::runtime_error("the subscriber never received the warm-up statuses");
}

TEST(MeshPublisher, ScanIsARandomV4UuidPerPublisher) {
  MeshPublisher a = bind_or_fail(loopback_options());
  MeshPublisher b = bind_or_fail(loopback_options());
  const std::regex v4("[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}");
  EXPECT_TRUE(std::regex_match(a.scan(), v4)) << a.scan();
  EXPECT_NE(a.scan(), b.scan());
  EXPECT_EQ(a.last_seq(), 0u);
  EXPECT_TRUE(contains(a.endpoint(), "tcp://127.0.0.1:"));
  EXPECT_EQ(a.endpoint().find('*'), std::string::npos);
}

TEST(MeshPublisher, SubscriberReceivesEveryMessageInSeqOrder) {
  MeshPublisher publisher = bind_or_fail(loopback_options());
  SubscriberOptions options;
  options.endpoint = publisher.endpoint();
  Result<MeshSubscriber> subscriber = MeshSubscriber::connect(options);
  ASSERT_TRUE(subscriber.is_ok()) << subscriber.message();
  std::uint64_t seq = warm_up(publisher, *subscriber);

  constexpr int kRounds = 100;
  for (int k = 0; k < kRounds; ++k) {
    ASSERT_TRUE(publisher.publish_slice(square_slice(k), static_cast<std::uint64_t>(k)));
    ASSERT_TRUE(publisher.publish_meshes(two_organs(1.0 + k), 0.1 * k, k + 1));
    ASSERT_TRUE(publisher.publish_status(scanning_status(k + 1)));
  }
  EXPECT_EQ(publisher.last_seq(), seq + 4 * kRounds);
  for (int k = 0; k < kRounds; ++k) {
    const StreamMessage slice = receive_or_fail(*subscriber);
    EXPECT_EQ(slice.seq, ++seq);
    EXPECT_EQ(slice.scan, publisher.scan());
    ASSERT_TRUE(std::holds_alternative<SliceUpdate>(slice.body));
    EXPECT_EQ(std::get<SliceUpdate>(slice.body).index, static_cast<std::uint64_t>(k));
    EXPECT_EQ(std::get<SliceUpdate>(slice.body).slice.origin_mm.z(), k);
    for (int label : {1, 2}) {
      const StreamMessage mesh = receive_or_fail(*subscriber);
      EXPECT_EQ(mesh.seq, ++seq);
      ASSERT_EQ(mesh.topic(), "mesh." + std::to_string(label));
      const auto& update = std::get<MeshUpdate>(mesh.body);
      EXPECT_EQ(update.slices, static_cast<std::uint64_t>(k + 1));
      EXPECT_EQ(update.mesh.triangles.size(), 8u);
      EXPECT_EQ(update.name, label == 1 ? "liver" : "kidney");
    }
    const StreamMessage status = receive_or_fail(*subscriber);
    EXPECT_EQ(status.seq, ++seq);
    EXPECT_EQ(std::get<StatusReport>(status.body).slices, static_cast<std::uint64_t>(k + 1));
  }
  auto nothing = subscriber->receive(50ms);
  ASSERT_TRUE(nothing.is_ok());
  EXPECT_FALSE(nothing->has_value());
}

TEST(MeshPublisher, VanishedLabelIsSentEmptyAndNormalsOnRequest) {
  PublisherOptions publisher_options = loopback_options();
  publisher_options.normals = true;
  MeshPublisher publisher = bind_or_fail(publisher_options);
  SubscriberOptions options;
  options.endpoint = publisher.endpoint();
  options.topics = {"mesh."};
  Result<MeshSubscriber> subscriber = MeshSubscriber::connect(options);
  ASSERT_TRUE(subscriber.is_ok()) << subscriber.message();
  // The warm-up statuses are filtered out here: wait for the first mesh instead.
  const auto deadline = Clock::now() + 10s;
  bool live = false;
  while (!live && Clock::now() < deadline) {
    ASSERT_TRUE(publisher.publish_meshes(two_organs(1.0), 0.0, 1));
    auto received = subscriber->receive(20ms);
    ASSERT_TRUE(received.is_ok()) << received.message();
    live = received->has_value();
  }
  ASSERT_TRUE(live);
  while (subscriber->receive(50ms)->has_value()) {
  }

  MeshSet only_liver;
  only_liver.meshes.push_back({1, "liver", octahedron(2.0)});
  ASSERT_TRUE(publisher.publish_meshes(only_liver, 1.0, 2));
  const StreamMessage liver = receive_or_fail(*subscriber);
  const StreamMessage kidney = receive_or_fail(*subscriber);
  EXPECT_EQ(kidney.seq, liver.seq + 1);
  ASSERT_EQ(kidney.topic(), "mesh.2");
  const auto& gone = std::get<MeshUpdate>(kidney.body);
  EXPECT_TRUE(gone.mesh.vertices.empty());
  EXPECT_EQ(gone.name, "kidney");
  const auto& normals = std::get<MeshUpdate>(liver.body).normals;
  ASSERT_TRUE(normals.has_value());
  ASSERT_EQ(normals->size(), 6u);
  EXPECT_NEAR((*normals)[0].x(), 1.0, 1e-6);  // the +x corner of the octahedron points along +x
  for (const Vec3& n : *normals) EXPECT_NEAR(n.norm(), 1.0, 1e-6);
}

TEST(MeshPublisher, LateJoinerGetsTheSnapshotThenContinuesWithoutGaps) {
  MeshPublisher publisher = bind_or_fail(loopback_options());
  ASSERT_TRUE(publisher.publish_meshes(two_organs(1.0), 0.5, 1));
  ASSERT_TRUE(publisher.publish_slice(square_slice(0.0), 0));
  ASSERT_TRUE(publisher.publish_status(scanning_status(1)));
  ASSERT_TRUE(publisher.publish_meshes(two_organs(3.0), 1.5, 2));  // newest meshes: size 3
  ASSERT_TRUE(publisher.publish_slice(square_slice(1.0), 1));
  FrameImage frame;
  frame.index = 40;
  frame.image = GreyImage(2, 2, 9);
  frame.size_mm = Vec2(20, 20);
  ASSERT_TRUE(publisher.publish_frame(frame));
  const std::uint64_t n = publisher.last_seq();
  ASSERT_EQ(n, 8u);

  SubscriberOptions options;
  options.endpoint = publisher.endpoint();
  options.snapshot_endpoint = publisher.snapshot_endpoint();
  Result<MeshSubscriber> subscriber = MeshSubscriber::connect(options);
  ASSERT_TRUE(subscriber.is_ok()) << subscriber.message();
  EXPECT_EQ(subscriber->snapshot_seq(), n);
  EXPECT_EQ(publisher.snapshots_served(), 1u);

  // The snapshot: every slice in order (seqs 3 and 7), newest mesh of each label (seqs 5 and
  // 6), newest status (seq 4), newest frame (seq 8), then end. Live messages with seq <= 8 are
  // dropped as covered: the snapshot must hold every slice.
  for (std::uint64_t index : {0u, 1u}) {
    const StreamMessage slice = receive_or_fail(*subscriber);
    ASSERT_EQ(slice.topic(), "slice");
    EXPECT_EQ(slice.seq, index == 0 ? 3u : 7u);
    EXPECT_EQ(std::get<SliceUpdate>(slice.body).index, index);
  }
  const StreamMessage liver = receive_or_fail(*subscriber);
  EXPECT_EQ(liver.topic(), "mesh.1");
  EXPECT_EQ(liver.seq, 5u);
  EXPECT_EQ(std::get<MeshUpdate>(liver.body).mesh.vertices[0], Vec3(3, 0, 0));
  const StreamMessage kidney = receive_or_fail(*subscriber);
  EXPECT_EQ(kidney.topic(), "mesh.2");
  EXPECT_EQ(kidney.seq, 6u);
  const StreamMessage status = receive_or_fail(*subscriber);
  EXPECT_EQ(status.topic(), "status");
  EXPECT_EQ(status.seq, 4u);
  const StreamMessage preview = receive_or_fail(*subscriber);
  EXPECT_EQ(preview.topic(), "frame");
  EXPECT_EQ(std::get<FrameImage>(preview.body).index, 40);
  const StreamMessage end = receive_or_fail(*subscriber);
  EXPECT_EQ(end.topic(), "end");
  EXPECT_EQ(end.seq, n);
  EXPECT_EQ(end.scan, publisher.scan());

  for (int k = 0; k < 30; ++k) {
    ASSERT_TRUE(publisher.publish_slice(square_slice(2.0 + k), 2 + k));
    ASSERT_TRUE(publisher.publish_meshes(two_organs(4.0 + k), 2.0 + k, 3 + k));
  }
  for (std::uint64_t seq = n + 1; seq <= publisher.last_seq(); ++seq)
    EXPECT_EQ(receive_or_fail(*subscriber).seq, seq);
}

TEST(MeshPublisher, SnapshotBeforeAnyMessageIsJustTheEnd) {
  MeshPublisher publisher = bind_or_fail(loopback_options());
  SubscriberOptions options;
  options.endpoint = publisher.endpoint();
  options.snapshot_endpoint = publisher.snapshot_endpoint();
  Result<MeshSubscriber> subscriber = MeshSubscriber::connect(options);
  ASSERT_TRUE(subscriber.is_ok()) << subscriber.message();
  const StreamMessage end = receive_or_fail(*subscriber);
  EXPECT_EQ(end.topic(), "end");
  EXPECT_EQ(end.seq, 0u);
  ASSERT_TRUE(publisher.publish_status(scanning_status(0)));
  EXPECT_EQ(receive_or_fail(*subscriber).seq, 1u);
}

TEST(MeshPublisher, SnapshotServerKeepsTheRequestEnvelopeAndRefusesUnknownRequests) {
  MeshPublisher publisher = bind_or_fail(loopback_options());
  ASSERT_TRUE(publisher.publish_status(scanning_status(0)));
  zmq::context_t context;
  zmq::socket_t dealer(context, zmq::socket_type::dealer);
  dealer.set(zmq::sockopt::linger, 0);
  dealer.set(zmq::sockopt::rcvtimeo, 5000);
  dealer.connect(publisher.snapshot_endpoint());
  auto receive_all = [&] {
    std::vector<zmq::message_t> parts;
    EXPECT_TRUE(zmq::recv_multipart(dealer, std::back_inserter(parts)).has_value());
    std::vector<std::string> frames;
    for (const auto& p : parts) frames.push_back(p.to_string());
    return frames;
  };

  // REQ-style: an empty delimiter first; every reply carries it back.
  std::array<zmq::const_buffer, 2> delimited{zmq::str_buffer(""), zmq::str_buffer("snapshot")};
  ASSERT_TRUE(zmq::send_multipart(dealer, delimited));
  Frames status = receive_all();
  ASSERT_EQ(status.size(), 3u);
  EXPECT_EQ(status[0], "");
  EXPECT_EQ(status[1], "status");
  Frames end = receive_all();
  ASSERT_EQ(end.size(), 3u);
  EXPECT_EQ(end[1], "end");
  Result<StreamMessage> decoded = decode_message(Frames(end.begin() + 1, end.end()));
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  EXPECT_EQ(decoded->seq, 1u);

  ASSERT_TRUE(dealer.send(zmq::str_buffer("hello"), zmq::send_flags::none));
  Frames refusal = receive_all();
  ASSERT_EQ(refusal.size(), 2u);
  EXPECT_EQ(refusal[0], "error");
  EXPECT_TRUE(contains(refusal[1], "snapshot"));
}

TEST(MeshPublisher, SlowSubscriberDoesNotBlockPublishing) {
  MeshPublisher publisher = bind_or_fail(loopback_options(16));
  // A subscriber that stops reading: a tiny receive queue, so that it holds few messages.
  zmq::context_t context;
  zmq::socket_t sub(context, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, 4);
  sub.set(zmq::sockopt::subscribe, "");
  sub.connect(publisher.endpoint());
  // Make sure it is connected (else the publisher would trivially drop everything).
  const auto deadline = Clock::now() + 10s;
  bool connected = false;
  while (!connected && Clock::now() < deadline) {
    ASSERT_TRUE(publisher.publish_status(scanning_status(0)));
    connected = readable(sub, 20ms);
  }
  ASSERT_TRUE(connected);

  // About 50 KB per mesh message: 2000 of them are 100 MB, far beyond every buffer on the way.
  MeshSet big;
  TriangleMesh mesh;
  for (int k = 0; k < 4000; ++k) mesh.vertices.emplace_back(k, 0.5 * k, 0.25 * k);
  for (std::uint32_t k = 0; k + 2 < 4000; k += 3) mesh.triangles.push_back({k, k + 1, k + 2});
  big.meshes.push_back({1, "liver", mesh});
  constexpr int kMessages = 2000;
  double slowest_s = 0.0;
  const auto start = Clock::now();
  for (int k = 0; k < kMessages; ++k) {
    const auto before = Clock::now();
    ASSERT_TRUE(publisher.publish_meshes(big, k, k));
    slowest_s = std::max(slowest_s, std::chrono::duration<double>(Clock::now() - before).count());
  }
  const double total_s = std::chrono::duration<double>(Clock::now() - start).count();
  // Encoding costs a fraction of a millisecond per message; a blocked send would stall forever.
  EXPECT_LT(total_s, 10.0);
  EXPECT_LT(slowest_s, 1.0);

  // The subscriber got some of them, in order, and lost the rest.
  std::uint64_t received = 0;
  std::uint64_t last = 0;
  Frames frames;
  std::vector<zmq::message_t> parts;
  while (readable(sub, 300ms)) {
    parts.clear();
    ASSERT_TRUE(zmq::recv_multipart(sub, std::back_inserter(parts)).has_value());
    frames.clear();
    for (const auto& p : parts) frames.push_back(p.to_string());
    Result<StreamMessage> message = decode_message(frames);
    ASSERT_TRUE(message.is_ok()) << message.message();
    EXPECT_GT(message->seq, last);
    last = message->seq;
    ++received;
  }
  EXPECT_LT(received, static_cast<std::uint64_t>(kMessages));
}

TEST(MeshPublisher, BindOnAPortInUseSaysWhatAndHowToFix) {
  MeshPublisher first = bind_or_fail(loopback_options());
  PublisherOptions same_pub = loopback_options();
  same_pub.endpoint = first.endpoint();
  Result<MeshPublisher> second = MeshPublisher::bind(same_pub);
  ASSERT_FALSE(second.is_ok());
  EXPECT_TRUE(contains(second.message(), "(PUB) at " + first.endpoint()));
  EXPECT_TRUE(contains(second.message(), "already in use"));
  EXPECT_TRUE(contains(second.message(), "--publish"));

  PublisherOptions same_snapshot = loopback_options();
  same_snapshot.snapshot_endpoint = first.snapshot_endpoint();
  Result<MeshPublisher> third = MeshPublisher::bind(same_snapshot);
  ASSERT_FALSE(third.is_ok());
  EXPECT_TRUE(contains(third.message(), "snapshots (ROUTER) at " + first.snapshot_endpoint()));
  EXPECT_TRUE(contains(third.message(), "already in use"));
  EXPECT_TRUE(contains(third.message(), "--snapshot"));
}

TEST(MeshPublisher, BadEndpointsSayHowToFix) {
  for (const char* endpoint : {"127.0.0.1:5556", "tcp://127.0.0.1", "udp://127.0.0.1:5556"}) {
    PublisherOptions options = loopback_options();
    options.endpoint = endpoint;
    Result<MeshPublisher> publisher = MeshPublisher::bind(options);
    ASSERT_FALSE(publisher.is_ok()) << endpoint;
    EXPECT_TRUE(contains(publisher.message(), "not a valid ZeroMQ endpoint")) << endpoint;
    EXPECT_TRUE(contains(publisher.message(), "tcp://HOST:PORT"));
  }
  PublisherOptions foreign = loopback_options();
  foreign.endpoint = "tcp://192.0.2.1:*";  // TEST-NET-1: never an address of this machine
  // Allowed and keyed (curve_test.cpp has the refusal otherwise), so that the bind is tried;
  // the key is zmq_curve(7)'s example.
  foreign.allow_remote = true;
  foreign.curve_secret_key = "JTKVSB%%)wK0E.X)V>+}o?pNmC{O&4W4b!Ni{Lh6";
  Result<MeshPublisher> publisher = MeshPublisher::bind(foreign);
  ASSERT_FALSE(publisher.is_ok());
  EXPECT_TRUE(contains(publisher.message(), "not an address of this machine"));

  PublisherOptions inproc = loopback_options();
  inproc.endpoint = "inproc://stream";
  inproc.snapshot_endpoint.clear();
  Result<MeshPublisher> no_default = MeshPublisher::bind(inproc);
  ASSERT_FALSE(no_default.is_ok());
  EXPECT_TRUE(contains(no_default.message(), "no default snapshot endpoint"));
}

TEST(MeshPublisher, DefaultSnapshotEndpointIsTheNextPort) {
  PublisherOptions options = loopback_options();
  options.snapshot_endpoint.clear();
  // The port after a free one may be taken by chance: a few tries.
  for (int attempt = 0; attempt < 5; ++attempt) {
    Result<MeshPublisher> publisher = MeshPublisher::bind(options);
    if (!publisher) continue;
    const std::string pub = publisher->endpoint();
    const int port = std::stoi(pub.substr(pub.rfind(':') + 1));
    EXPECT_EQ(publisher->snapshot_endpoint(), "tcp://127.0.0.1:" + std::to_string(port + 1));
    return;
  }
  FAIL() << "could not bind a PUB port with a free next port in 5 tries";
}

TEST(MeshSubscriber, SnapshotFromNobodyTimesOutWithAHint) {
  std::string endpoint;
  {
    MeshPublisher gone = bind_or_fail(loopback_options());
    endpoint = gone.endpoint();
  }
  SubscriberOptions options;
  options.endpoint = endpoint;
  options.snapshot_endpoint = endpoint;
  options.snapshot_timeout_ms = 300;
  Result<MeshSubscriber> subscriber = MeshSubscriber::connect(options);
  ASSERT_FALSE(subscriber.is_ok());
  EXPECT_TRUE(contains(subscriber.message(), "no mesh-stream publisher answered at " + endpoint));
}

TEST(MeshSubscriber, ReportsAnInvalidMessageAndGoesOn) {
  zmq::context_t context;
  zmq::socket_t pub(context, zmq::socket_type::pub);
  pub.set(zmq::sockopt::linger, 0);
  pub.bind("tcp://127.0.0.1:*");
  SubscriberOptions options;
  options.endpoint = pub.get(zmq::sockopt::last_endpoint);
  Result<MeshSubscriber> subscriber = MeshSubscriber::connect(options);
  ASSERT_TRUE(subscriber.is_ok()) << subscriber.message();

  StatusReport status = scanning_status(0);
  Frames good = *encode_message(StreamMessage{1, "scan-a", status});
  auto send = [&](const Frames& frames) {
    std::vector<zmq::const_buffer> parts;
    for (const std::string& f : frames) parts.push_back(zmq::buffer(f));
    ASSERT_TRUE(zmq::send_multipart(pub, parts));
  };
  // Warm up until the subscription is live.
  const auto deadline = Clock::now() + 10s;
  bool live = false;
  while (!live && Clock::now() < deadline) {
    send(good);
    auto received = subscriber->receive(20ms);
    ASSERT_TRUE(received.is_ok()) << received.message();
    live = received->has_value();
  }
  ASSERT_TRUE(live);
  while (subscriber->receive(50ms)->has_value()) {
  }

  Frames bad = good;
  bad[1] = R"({"v": 2, "seq": 2, "scan": "scan-a"})";
  send(bad);
  send(*encode_message(StreamMessage{3, "scan-a", status}));
  auto rejected = subscriber->receive(5s);
  ASSERT_FALSE(rejected.is_ok());
  EXPECT_TRUE(contains(rejected.message(), "status"));
  EXPECT_TRUE(contains(rejected.message(), "unknown format version"));
  EXPECT_EQ(subscriber->last_frames(), bad);
  EXPECT_EQ(receive_or_fail(*subscriber).seq, 3u);
}

}  // namespace
}  // namespace sonoshape::publish::publisher_test

namespace sonoshape::publish::publisher_test {
namespace {

// Issue 40: ZeroMQ takes a TCP port modulo 65536, so --publish tcp://127.0.0.1:99999 bound port
// 34463 and said nothing. A port out of 0..65535 is refused, naming the option.
TEST(MeshPublisher, APortBeyond65535IsRefusedNamingTheOption) {
  PublisherOptions options;
  options.endpoint = "tcp://127.0.0.1:99999";
  options.snapshot_endpoint = "tcp://127.0.0.1:*";
  const Result<MeshPublisher> publisher = MeshPublisher::bind(options);
  ASSERT_FALSE(publisher);
  EXPECT_TRUE(contains(publisher.message(), "tcp://127.0.0.1:99999"));
  EXPECT_TRUE(contains(publisher.message(), "'99999' is not a TCP port"));
  EXPECT_TRUE(contains(publisher.message(), "--publish"));
  options.endpoint = "tcp://127.0.0.1:*";
  options.snapshot_endpoint = "tcp://127.0.0.1:-1";
  const Result<MeshPublisher> snapshot = MeshPublisher::bind(options);
  ASSERT_FALSE(snapshot);
  EXPECT_TRUE(contains(snapshot.message(), "--snapshot"));

  SubscriberOptions subscriber;
  subscriber.endpoint = "tcp://127.0.0.1:70000";
  const Result<MeshSubscriber> connected = MeshSubscriber::connect(subscriber);
  ASSERT_FALSE(connected);
  EXPECT_TRUE(contains(connected.message(), "'70000' is not a TCP port"));
}

}  // namespace
}  // namespace sonoshape::publish::publisher_test
