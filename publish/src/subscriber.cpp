// MeshSubscriber: SUB socket, late-joiner snapshot over a DEALER, validation of every message.
#include "sonoshape/publish/subscriber.hpp"

#include <cstring>
#include <deque>

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

}  // namespace

// Fresh snapshots a late joiner asks for when live messages resume past the snapshot's end.
constexpr int kMaxResyncs = 3;

struct MeshSubscriber::Impl {
  zmq::context_t context{1};  // declared first: destroyed after every socket
  zmq::socket_t sub;
  std::deque<Frames> pending;  // the snapshot, delivered before live messages
  Frames last_frames;
  std::optional<std::uint64_t> snapshot_seq;
  std::string snapshot_scan;
  std::uint64_t covered = 0;
  SubscriberOptions options;    // kept to ask for a fresh snapshot
  bool awaiting_first_live = false;  // the first live message after a snapshot is checked
  int resyncs = 0;

  // Waits until the SUB connection has finished its handshake: the subscription goes out right
  // after it, ahead of the snapshot request, which has a connection and handshake of its own to
  // make first. That order is what lets the snapshot's end seq mark where live messages resume.
  Status wait_for_handshake(zmq::socket_t& monitor, const std::string& endpoint,
                            Clock::time_point deadline) {
    Frames event;
    while (true) {
      while (detail::receive_frames(monitor, event)) {
        std::uint16_t id = 0;
        if (!event.empty() && event[0].size() >= sizeof id)
          std::memcpy(&id, event[0].data(), sizeof id);
        if (id == ZMQ_EVENT_HANDSHAKE_SUCCEEDED) return Status::ok();
      }
      if (!detail::wait_readable(monitor, remaining(deadline)))
        return Status::error("no mesh-stream publisher answered at " + endpoint +
                             " in time; check that sonoshape is publishing there (its "
                             "--publish endpoint), or leave out the snapshot to wait for a scan "
                             "that has not started");
    }
  }

  Status fetch_snapshot(const SubscriberOptions& options, Clock::time_point deadline) {
    zmq::socket_t dealer(context, zmq::socket_type::dealer);
    dealer.set(zmq::sockopt::linger, 0);
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
      if (!frames.empty() && frames[0] == kErrorTopic)
        return Status::error("the snapshot server at " + options.snapshot_endpoint +
                             " refused the request: " + (frames.size() > 1 ? frames[1] : ""));
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
  try {
    impl->sub = zmq::socket_t(impl->context, zmq::socket_type::sub);
    impl->sub.set(zmq::sockopt::linger, 0);
    impl->sub.set(zmq::sockopt::rcvhwm, options.receive_hwm);
    // Subscriptions set before connecting travel with the handshake.
    if (options.topics.empty()) impl->sub.set(zmq::sockopt::subscribe, "");
    for (const std::string& topic : options.topics) impl->sub.set(zmq::sockopt::subscribe, topic);

    // inproc connections have no handshake to wait for: they are complete once connected.
    zmq::socket_t monitor;
    if (snapshot && options.endpoint.rfind("inproc://", 0) != 0) {
      if (zmq_socket_monitor(impl->sub.handle(), kMonitorEndpoint, ZMQ_EVENT_HANDSHAKE_SUCCEEDED) !=
          0)
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
        zmq_socket_monitor(impl->sub.handle(), nullptr, 0);
        if (!ready) return ready;
      }
      if (Status fetched = impl->fetch_snapshot(options, deadline); !fetched) return fetched;
      impl->awaiting_first_live = true;
    }
    impl->options = options;
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
                  impl.options, Clock::now() + std::chrono::milliseconds(impl.options.snapshot_timeout_ms));
              !fetched)
            return fetched;
          impl.awaiting_first_live = true;
          if (message->seq <= *impl.snapshot_seq) ++impl.covered;
          else impl.pending.push_back(impl.last_frames);
          return receive(timeout);
        }
      }
      return std::optional<StreamMessage>(std::move(*message));
    }
  } catch (const zmq::error_t& e) {
    return Status::error(std::string("mesh stream: cannot receive: ") + e.what());
  }
}

const Frames& MeshSubscriber::last_frames() const { return impl_->last_frames; }

std::optional<std::uint64_t> MeshSubscriber::snapshot_seq() const { return impl_->snapshot_seq; }

std::uint64_t MeshSubscriber::covered_by_snapshot() const { return impl_->covered; }

}  // namespace sonoshape::publish
