// MeshSubscriber: SUB socket, late-joiner snapshot over a DEALER, validation of every message.
#include "sonoshape/publish/subscriber.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <deque>
#include <nlohmann/json.hpp>
#include <thread>

#include "sonoshape/publish/curve.hpp"
#include "zmq_support.hpp"

namespace sonoshape::publish {
namespace {

// Each subscriber has its own context, so one fixed name serves every subscriber.
constexpr const char* kMonitorEndpoint = "inproc://sonoshape-subscriber-monitor";

using Clock = std::chrono::steady_clock;

std::chrono::milliseconds remaining(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
  return left.count() > 0 ? left : std::chrono::milliseconds(0);
}

bool topic_wanted(const std::string& topic, const std::vector<std::string>& prefixes) {
  if (prefixes.empty()) return true;
  for (const std::string& prefix : prefixes)
    if (topic.compare(0, prefix.size(), prefix) == 0) return true;
  return false;
}

// A `busy` reply's wait (docs/formats/mesh-stream.md); none for any other error reply.
std::optional<std::chrono::milliseconds> busy_retry_after(const Frames& frames) {
  if (frames.size() < 2) return std::nullopt;
  const auto reply = nlohmann::json::parse(frames[1], nullptr, false);
  if (!reply.is_object() || !reply.value("busy", false)) return std::nullopt;
  const auto wait_ms = reply.value("retry_after_ms", std::int64_t{100});
  return std::chrono::milliseconds(std::clamp<std::int64_t>(wait_ms, 1, 10000));
}

// A server key that libzmq would refuse with a bare EINVAL.
Status check_server_key(const std::string& key) {
  std::array<std::uint8_t, 32> binary{};
  if (key.size() != 40 || zmq_z85_decode(binary.data(), key.c_str()) == nullptr)
    return Status::error(
        "the server key is not a CURVE public key (40 Z85 characters); give "
        "the scan's NAME.pub file (--server-key)");
  return Status::ok();
}

// Why a handshake failed, from a monitor event id; empty for events that are no failure.
std::string handshake_failure(std::uint16_t id, const SubscriberOptions& options) {
  const bool keyed = !options.server_public_key.empty();
  if (id != ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL && id != ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL &&
      id != ZMQ_EVENT_HANDSHAKE_FAILED_AUTH)
    return {};
  return "the publisher at " + options.endpoint + " refused the handshake: " +
         (keyed ? "--server-key is not its public key (or it publishes without CURVE); give the "
                  "NAME.pub of the scan's --curve-secret-key NAME.key"
                : "it requires CURVE encryption; give its public key with --server-key FILE");
}

}  // namespace

// Fresh snapshots a late joiner asks for when live messages resume past the snapshot's end.
constexpr int kMaxResyncs = 3;

struct MeshSubscriber::Impl {
  zmq::context_t context{1};  // declared first: destroyed after every socket
  zmq::socket_t sub;
  // Events of the SUB connection after its handshake (with a snapshot endpoint): a publisher
  // that closes (its scan exited) shows as a disconnection, one that comes back as a handshake.
  zmq::socket_t monitor;
  bool publisher_gone = false;
  std::deque<Frames> pending;  // the snapshot, delivered before live messages
  Frames last_frames;
  std::optional<std::uint64_t> snapshot_seq;
  std::string snapshot_scan;
  std::uint64_t covered = 0;
  SubscriberOptions options;         // kept to ask for a fresh snapshot
  bool awaiting_first_live = false;  // the first live message after a snapshot is checked
  int resyncs = 0;
  CurveKeyPair client_keys;  // empty without a server key

  // Makes `socket` a CURVE client of the publisher (before it connects).
  void secure(zmq::socket_t& socket) const {
    if (options.server_public_key.empty()) return;
    socket.set(zmq::sockopt::curve_serverkey, options.server_public_key);
    socket.set(zmq::sockopt::curve_publickey, client_keys.public_key);
    socket.set(zmq::sockopt::curve_secretkey, client_keys.secret_key);
  }

  // Waits until the SUB connection has finished its handshake: the subscription goes out right
  // after it, ahead of the snapshot request, which has a connection and handshake of its own to
  // make first. That order is what lets the snapshot's end seq mark where live messages resume.
  Status wait_for_handshake(zmq::socket_t& monitor, const std::string& endpoint,
                            Clock::time_point deadline) {
    Frames event;
    bool dropped = false;  // a connection closed before its handshake ended
    while (true) {
      while (detail::receive_frames(monitor, event)) {
        std::uint16_t id = 0;
        if (!event.empty() && event[0].size() >= sizeof id)
          std::memcpy(&id, event[0].data(), sizeof id);
        if (id == ZMQ_EVENT_HANDSHAKE_SUCCEEDED) return Status::ok();
        if (std::string failure = handshake_failure(id, options); !failure.empty())
          return Status::error(failure);
        dropped = dropped || id == ZMQ_EVENT_DISCONNECTED;
      }
      if (!detail::wait_readable(monitor, remaining(deadline))) {
        // A publisher whose security differs closes the connection mid-handshake, and says no
        // more (the mechanism or the key did not match).
        if (dropped)
          return Status::error(handshake_failure(ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL, options));
        return Status::error("no mesh-stream publisher answered at " + endpoint +
                             " in time; check that sonoshape is publishing there (its "
                             "--publish endpoint), or follow without a snapshot (--no-snapshot) "
                             "to wait for a scan that has not started");
      }
    }
  }

  Status fetch_snapshot(const SubscriberOptions& options, Clock::time_point deadline) {
    zmq::socket_t dealer(context, zmq::socket_type::dealer);
    dealer.set(zmq::sockopt::linger, 0);
    secure(dealer);
    try {
      dealer.connect(options.snapshot_endpoint);
    } catch (const zmq::error_t& e) {
      return Status::error(detail::endpoint_error(e, "ask", "for a snapshot",
                                                  options.snapshot_endpoint, "--snapshot"));
    }
    dealer.send(zmq::buffer(kSnapshotRequest), zmq::send_flags::dontwait);
    Frames frames;
    while (true) {
      if (!detail::receive_frames(dealer, frames)) {
        if (!detail::wait_readable(dealer, remaining(deadline)))
          return Status::error("no snapshot from " + options.snapshot_endpoint +
                               " in time; check that it is the publisher's snapshot endpoint "
                               "(--snapshot, by default the PUB port + 1)");
        continue;
      }
      if (!frames.empty() && frames[0] == kErrorTopic) {
        // Over the publisher's snapshot rate: ask again after the wait it names, in time.
        if (const auto wait = busy_retry_after(frames); wait && *wait < remaining(deadline)) {
          std::this_thread::sleep_for(*wait);
          dealer.send(zmq::buffer(kSnapshotRequest), zmq::send_flags::dontwait);
          continue;
        }
        return Status::error("the snapshot server at " + options.snapshot_endpoint +
                             " refused the request: " + (frames.size() > 1 ? frames[1] : ""));
      }
      if (!frames.empty() && frames[0] == kEndTopic) {
        Result<StreamMessage> end = decode_message(frames);
        if (!end)
          return Status::error("malformed snapshot from " + options.snapshot_endpoint + ": " +
                               end.message());
        snapshot_seq = end->seq;
        snapshot_scan = end->scan;
        pending.push_back(std::move(frames));
        return Status::ok();
      }
      // Invalid snapshot messages are kept too: receive() reports them like live ones.
      if (frames.empty() || topic_wanted(frames[0], options.topics))
        pending.push_back(std::move(frames));
    }
  }
};

MeshSubscriber::MeshSubscriber(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MeshSubscriber::MeshSubscriber(MeshSubscriber&&) noexcept = default;
MeshSubscriber& MeshSubscriber::operator=(MeshSubscriber&&) noexcept = default;
MeshSubscriber::~MeshSubscriber() = default;

Result<MeshSubscriber> MeshSubscriber::connect(const SubscriberOptions& options) {
  auto impl = std::make_unique<Impl>();
  const Clock::time_point deadline =
      Clock::now() + std::chrono::milliseconds(options.snapshot_timeout_ms);
  const bool snapshot = !options.snapshot_endpoint.empty();
  impl->options = options;
  if (Status port = detail::check_tcp_port(options.endpoint, "the mesh stream", "the endpoint");
      !port)
    return port;
  if (Status port = detail::check_tcp_port(options.snapshot_endpoint, "snapshots", "--snapshot");
      !port)
    return port;
  if (!options.server_public_key.empty()) {
    if (Status valid = check_server_key(options.server_public_key); !valid) return valid;
    Result<CurveKeyPair> keys = generate_curve_keypair();
    if (!keys) return keys.status();
    impl->client_keys = std::move(*keys);
  }
  try {
    impl->sub = zmq::socket_t(impl->context, zmq::socket_type::sub);
    impl->sub.set(zmq::sockopt::linger, 0);
    impl->sub.set(zmq::sockopt::rcvhwm, options.receive_hwm);
    impl->secure(impl->sub);
    // Subscriptions set before connecting travel with the handshake.
    if (options.topics.empty()) impl->sub.set(zmq::sockopt::subscribe, "");
    for (const std::string& topic : options.topics) impl->sub.set(zmq::sockopt::subscribe, topic);

    // inproc connections have no handshake to wait for: they are complete once connected.
    zmq::socket_t monitor;
    if (snapshot && options.endpoint.rfind("inproc://", 0) != 0) {
      constexpr int kEvents = ZMQ_EVENT_HANDSHAKE_SUCCEEDED | ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL |
                              ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                              ZMQ_EVENT_HANDSHAKE_FAILED_AUTH | ZMQ_EVENT_DISCONNECTED;
      if (zmq_socket_monitor(impl->sub.handle(), kMonitorEndpoint, kEvents) != 0)
        throw zmq::error_t();
      monitor = zmq::socket_t(impl->context, zmq::socket_type::pair);
      monitor.set(zmq::sockopt::linger, 0);
      monitor.connect(kMonitorEndpoint);
    }
    try {
      impl->sub.connect(options.endpoint);
    } catch (const zmq::error_t& e) {
      return Status::error(detail::endpoint_error(e, "subscribe", "to the mesh stream",
                                                  options.endpoint, "ENDPOINT"));
    }
    if (snapshot) {
      if (monitor) {
        Status ready = impl->wait_for_handshake(monitor, options.endpoint, deadline);
        if (!ready) {
          zmq_socket_monitor(impl->sub.handle(), nullptr, 0);
          return ready;
        }
        impl->monitor = std::move(monitor);
      }
      if (Status fetched = impl->fetch_snapshot(options, deadline); !fetched) return fetched;
      impl->awaiting_first_live = true;
    }
  } catch (const zmq::error_t& e) {
    return Status::error(std::string("mesh stream: cannot set up the subscriber: ") + e.what());
  }
  return MeshSubscriber(std::move(impl));
}

Result<std::optional<StreamMessage>> MeshSubscriber::receive(std::chrono::milliseconds timeout) {
  Impl& impl = *impl_;
  impl.last_frames.clear();
  if (!impl.pending.empty()) {
    impl.last_frames = std::move(impl.pending.front());
    impl.pending.pop_front();
    Result<StreamMessage> message = decode_message(impl.last_frames);
    if (!message) return message.status();
    return std::optional<StreamMessage>(std::move(*message));
  }
  const Clock::time_point deadline = Clock::now() + timeout;
  try {
    while (true) {
      if (!detail::receive_frames(impl.sub, impl.last_frames)) {
        if (!detail::wait_readable(impl.sub, remaining(deadline)))
          return std::optional<StreamMessage>();
        continue;
      }
      Result<StreamMessage> message = decode_message(impl.last_frames);
      if (!message) return message.status();
      // Seqs restart with every scan: only the snapshot's own scan is covered by it.
      if (impl.snapshot_seq && message->scan == impl.snapshot_scan &&
          message->seq <= *impl.snapshot_seq) {
        ++impl.covered;
        // A flood of covered messages must not hold the caller past its timeout.
        if (Clock::now() >= deadline) return std::optional<StreamMessage>();
        continue;
      }
      // The subscription travels to the publisher on its own: when it arrived after messages
      // that followed the snapshot, those are lost to this subscriber; a fresh snapshot covers
      // them (a few times at most, then the gap is reported like any other).
      if (impl.awaiting_first_live && message->scan == impl.snapshot_scan) {
        impl.awaiting_first_live = false;
        if (message->seq > *impl.snapshot_seq + 1 && impl.resyncs < kMaxResyncs) {
          ++impl.resyncs;
          if (Status fetched = impl.fetch_snapshot(
                  impl.options,
                  Clock::now() + std::chrono::milliseconds(impl.options.snapshot_timeout_ms));
              !fetched)
            return fetched;
          impl.awaiting_first_live = true;
          if (message->seq <= *impl.snapshot_seq)
            ++impl.covered;
          else
            impl.pending.push_back(impl.last_frames);
          return receive(timeout);
        }
      }
      return std::optional<StreamMessage>(std::move(*message));
    }
  } catch (const zmq::error_t& e) {
    return Status::error(std::string("mesh stream: cannot receive: ") + e.what());
  }
}

bool MeshSubscriber::publisher_gone() {
  Impl& impl = *impl_;
  if (!impl.monitor) return false;
  Frames event;
  try {
    while (detail::receive_frames(impl.monitor, event)) {
      std::uint16_t id = 0;
      if (!event.empty() && event[0].size() >= sizeof id)
        std::memcpy(&id, event[0].data(), sizeof id);
      if (id == ZMQ_EVENT_DISCONNECTED) impl.publisher_gone = true;
      if (id == ZMQ_EVENT_HANDSHAKE_SUCCEEDED) impl.publisher_gone = false;
    }
  } catch (const zmq::error_t&) {
    return impl.publisher_gone;
  }
  return impl.publisher_gone;
}

const Frames& MeshSubscriber::last_frames() const { return impl_->last_frames; }

std::optional<std::uint64_t> MeshSubscriber::snapshot_seq() const { return impl_->snapshot_seq; }

std::uint64_t MeshSubscriber::covered_by_snapshot() const { return impl_->covered; }

}  // namespace sonoshape::publish
