// MeshPublisher: PUB socket, stored newest state, and the snapshot thread.
#include "sonoshape/publish/publisher.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <deque>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <set>
#include <thread>

#include "sonoshape/core/log.hpp"
#include "sonoshape/publish/curve.hpp"
#include "zmq_support.hpp"

namespace sonoshape::publish {
namespace {

// Each publisher has its own context, so one fixed name serves every publisher.
constexpr const char* kStopEndpoint = "inproc://sonoshape-publisher-stop";
// Snapshot replies queued per client before dropping: every slice kept, and room for many
// labels (a ROUTER drops what is over its high-water mark, the end included).
constexpr int kSnapshotSendHwm = static_cast<int>(kMaxSnapshotSlices) + 1024;

using Clock = std::chrono::steady_clock;

// Snapshot requests answered: `burst` at once, then `rate_hz` a second. One bucket for every
// client together: a client that floods (or reconnects to get a fresh routing id) cannot make
// the snapshot thread take the state lock, or fill the network, more often than this.
class TokenBucket {
 public:
  TokenBucket(int burst, double rate_hz)
      : burst_(std::max(1, burst)), rate_hz_(rate_hz), tokens_(burst_), last_(Clock::now()) {}

  // Takes a token if there is one; otherwise the milliseconds until the next.
  std::optional<std::int64_t> take() {
    const Clock::time_point now = Clock::now();
    tokens_ = std::min<double>(
        burst_, tokens_ + rate_hz_ * std::chrono::duration<double>(now - last_).count());
    last_ = now;
    if (tokens_ >= 1.0) {
      tokens_ -= 1.0;
      return std::nullopt;
    }
    const double wait_s = rate_hz_ > 0.0 ? (1.0 - tokens_) / rate_hz_ : 1.0;
    return static_cast<std::int64_t>(std::ceil(wait_s * 1000.0));
  }

 private:
  int burst_;
  double rate_hz_;
  double tokens_;
  Clock::time_point last_;
};

// Refuses an endpoint other machines can reach unless the user asked for it and it is
// encrypted: the stream carries a patient's anatomy.
Status check_reachable(const PublisherOptions& options, const std::string& endpoint,
                       const std::string& option) {
  if (is_local_endpoint(endpoint)) return Status::ok();
  const bool keyed = !options.curve_secret_key.empty();
  if (options.allow_remote && keyed) return Status::ok();
  const std::string missing = !options.allow_remote && !keyed
                                  ? "--allow-remote and --curve-secret-key FILE"
                              : !keyed ? "--curve-secret-key FILE"
                                       : "--allow-remote";
  return Status::error(
      "refusing to publish on " + endpoint + " (" + option +
      "): other machines can reach it, and the stream carries the patient's anatomy; add " +
      missing +
      " (CURVE encryption: make a key pair with `sonoshape keys -o NAME`, give NAME.key here "
      "and NAME.pub to each subscriber's --server-key), or bind loopback only "
      "(tcp://127.0.0.1:PORT)");
}

// Makes `socket` a CURVE server with `secret_key` (before it binds).
void make_curve_server(zmq::socket_t& socket, const std::string& secret_key) {
  socket.set(zmq::sockopt::curve_server, true);
  socket.set(zmq::sockopt::curve_secretkey, secret_key);
}

}  // namespace

std::string random_uuid() {
  std::random_device device;
  std::mt19937_64 engine((static_cast<std::uint64_t>(device()) << 32) ^ device());
  std::array<unsigned char, 16> bytes{};
  for (unsigned char& b : bytes) b = static_cast<unsigned char>(engine() & 0xffu);
  bytes[6] = static_cast<unsigned char>((bytes[6] & 0x0fu) | 0x40u);  // version 4
  bytes[8] = static_cast<unsigned char>((bytes[8] & 0x3fu) | 0x80u);  // RFC 4122 variant
  std::string text;
  for (std::size_t k = 0; k < bytes.size(); ++k) {
    if (k == 4 || k == 6 || k == 8 || k == 10) text += '-';
    char hex[3];
    std::snprintf(hex, sizeof hex, "%02x", bytes[k]);
    text += hex;
  }
  return text;
}

std::vector<Vec3> vertex_normals(const TriangleMesh& mesh) {
  std::vector<Vec3> normals(mesh.vertices.size(), Vec3::Zero());
  for (const auto& t : mesh.triangles) {
    // The cross product's length is twice the area: larger triangles weigh more.
    const Vec3 n = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                       .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    for (std::uint32_t index : t) normals[index] += n;
  }
  for (Vec3& n : normals) {
    const double length = n.norm();
    n = length > 0.0 ? Vec3(n / length) : Vec3::Zero();
  }
  return normals;
}

struct MeshPublisher::Impl {
  PublisherOptions options;
  zmq::context_t context{1};  // declared first: destroyed after every socket
  zmq::socket_t pub;
  zmq::socket_t stop;  // PAIR, this side tells the snapshot thread to end
  std::thread snapshot_thread;
  std::string endpoint;
  std::string snapshot_endpoint;
  std::string scan = random_uuid();

  // Touched by the publishing thread only.
  std::uint64_t next_seq = 1;
  std::map<int, std::string> published_labels;  // label -> name, every label ever sent

  // Shared with the snapshot thread.
  mutable std::mutex mutex;
  std::map<int, std::shared_ptr<const Frames>> latest_meshes;
  std::shared_ptr<const Frames> latest_status;
  std::shared_ptr<const Frames> latest_frame;
  std::deque<std::shared_ptr<const Frames>> slices;  // the scan's, the newest kMaxSnapshotSlices
  std::uint64_t last_seq = 0;
  std::atomic<std::uint64_t> snapshots_served{0};
  std::atomic<std::uint64_t> snapshots_refused{0};
  std::optional<TokenBucket> snapshot_budget;  // the snapshot thread's only

  ~Impl() {
    if (snapshot_thread.joinable()) {
      try {
        stop.send(zmq::str_buffer("stop"), zmq::send_flags::none);
      } catch (const zmq::error_t& e) {
        log_warning(std::string("mesh stream: cannot stop the snapshot thread: ") + e.what());
      }
      snapshot_thread.join();
    }
  }

  // The snapshot thread: owns `router` and `stop_in` from its start.
  void serve_snapshots(zmq::socket_t router, zmq::socket_t stop_in) {
    try {
      std::array<zmq::pollitem_t, 2> items{
          {{router.handle(), 0, ZMQ_POLLIN, 0}, {stop_in.handle(), 0, ZMQ_POLLIN, 0}}};
      Frames request;
      while (true) {
        zmq::poll(items, std::chrono::milliseconds(-1));
        if (items[1].revents & ZMQ_POLLIN) break;
        while (detail::receive_frames(router, request)) answer(router, request);
      }
    } catch (const std::exception& e) {
      // Exceptions never cross threads: the stream goes on without snapshots.
      log_warning(std::string("mesh stream: the snapshot server stopped: ") + e.what());
    }
  }

  void answer(zmq::socket_t& router, const Frames& request) {
    if (request.size() < 2) return;  // no identity and body: not from a DEALER or REQ
    // A REQ client (or a DEALER imitating one) puts an empty delimiter before its request; the
    // replies carry it back.
    const bool delimited = request.size() >= 3 && request[1].empty();
    Frames envelope{request[0]};
    if (delimited) envelope.emplace_back();
    const std::size_t body = delimited ? 2 : 1;
    if (request.size() != body + 1 || request[body] != kSnapshotRequest) {
      const std::string reply =
          "{\"v\":1,\"message\":\"unknown request; send one frame holding the 8 bytes "
          "snapshot\"}";
      detail::send_frames(router,
                          std::make_shared<const Frames>(Frames{std::string(kErrorTopic), reply}),
                          envelope);
      return;
    }
    if (const std::optional<std::int64_t> wait_ms = snapshot_budget->take()) {
      // Over the rate: a small reply instead of a snapshot, no lock taken.
      nlohmann::ordered_json busy;
      busy["v"] = 1;
      busy["busy"] = true;
      busy["retry_after_ms"] = *wait_ms;
      busy["message"] =
          "busy: too many snapshot requests; retry in " + std::to_string(*wait_ms) + " ms";
      ++snapshots_refused;
      detail::send_frames(
          router, std::make_shared<const Frames>(Frames{std::string(kErrorTopic), busy.dump()}),
          envelope);
      return;
    }
    std::vector<std::shared_ptr<const Frames>> messages;
    std::uint64_t seq = 0;
    {
      const std::lock_guard<std::mutex> lock(mutex);
      messages.assign(slices.begin(), slices.end());
      for (const auto& [label, frames] : latest_meshes) messages.push_back(frames);
      if (latest_status) messages.push_back(latest_status);
      if (latest_frame) messages.push_back(latest_frame);
      seq = last_seq;
    }
    StreamMessage end{seq, scan, SnapshotEnd{}};
    messages.push_back(std::make_shared<const Frames>(std::move(*encode_message(end))));
    ++snapshots_served;  // before the reply: a client that has it sees the count too
    for (const auto& frames : messages) detail::send_frames(router, frames, envelope);
  }

  // Assigns seqs, stores the newest state and sends. All or nothing: encoding happens first.
  Status publish(std::vector<StreamMessage> messages) {
    std::vector<std::shared_ptr<const Frames>> encoded;
    for (std::size_t k = 0; k < messages.size(); ++k) {
      messages[k].seq = next_seq + k;
      messages[k].scan = scan;
      Result<Frames> frames = encode_message(messages[k]);
      if (!frames) return Status::error("mesh stream: " + frames.message());
      encoded.push_back(std::make_shared<const Frames>(std::move(*frames)));
    }
    // Sending under the lock: a snapshot's end seq never names a message PUB has not sent yet.
    const std::lock_guard<std::mutex> lock(mutex);
    try {
      // Reading ZMQ_EVENTS makes the socket take in new subscribers and subscriptions now; a send
      // looks at them at most once a millisecond, and a late joiner whose snapshot ended at N
      // would miss the messages after N sent in that window.
      (void)pub.get(zmq::sockopt::events);
      for (std::size_t k = 0; k < messages.size(); ++k) {
        if (const auto* mesh = std::get_if<MeshUpdate>(&messages[k].body))
          latest_meshes[mesh->label] = encoded[k];
        else if (std::holds_alternative<StatusReport>(messages[k].body))
          latest_status = encoded[k];
        else if (std::holds_alternative<SliceUpdate>(messages[k].body))
          slices.push_back(encoded[k]);
        else if (std::holds_alternative<FrameImage>(messages[k].body))
          latest_frame = encoded[k];
        if (slices.size() > kMaxSnapshotSlices) slices.pop_front();
        last_seq = messages[k].seq;
        ++next_seq;
        // A PUB socket drops instead of blocking: a false here is not an error.
        detail::send_frames(pub, encoded[k]);
      }
    } catch (const zmq::error_t& e) {
      return Status::error("mesh stream: cannot send on " + endpoint + ": " + e.what());
    }
    return Status::ok();
  }
};

MeshPublisher::MeshPublisher(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MeshPublisher::MeshPublisher(MeshPublisher&&) noexcept = default;
MeshPublisher& MeshPublisher::operator=(MeshPublisher&&) noexcept = default;
MeshPublisher::~MeshPublisher() = default;

Result<MeshPublisher> MeshPublisher::bind(const PublisherOptions& options) {
  if (options.send_hwm < 1)
    return Status::error("mesh stream: the send high-water mark must be at least 1 message");
  if (!(options.snapshot_rate_hz >= 0.0) || options.snapshot_burst < 1)
    return Status::error("mesh stream: the snapshot rate must be >= 0 a second and the burst >= 1");
  if (Status port = detail::check_tcp_port(options.endpoint, "the mesh stream (PUB)",
                                           options.endpoint_option);
      !port)
    return port;
  if (Status port = detail::check_tcp_port(
          options.snapshot_endpoint, "mesh-stream snapshots (ROUTER)", options.snapshot_option);
      !port)
    return port;
  if (Status reachable = check_reachable(options, options.endpoint, options.endpoint_option);
      !reachable)
    return reachable;
  const bool curve = !options.curve_secret_key.empty();
  if (curve) {
    if (Status available = curve_available(); !available) return available;
    if (Result<std::string> valid = curve_public_key_of(options.curve_secret_key); !valid)
      return Status::error("mesh stream: " + valid.message());
  }
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->snapshot_budget.emplace(options.snapshot_burst, options.snapshot_rate_hz);
  zmq::socket_t router;
  zmq::socket_t stop_in;
  try {
    impl->pub = zmq::socket_t(impl->context, zmq::socket_type::pub);
    impl->pub.set(zmq::sockopt::sndhwm, options.send_hwm);
    impl->pub.set(zmq::sockopt::linger, options.linger_ms);
    if (curve) make_curve_server(impl->pub, options.curve_secret_key);
    try {
      impl->pub.bind(options.endpoint);
    } catch (const zmq::error_t& e) {
      return Status::error(detail::endpoint_error(e, "publish", "the mesh stream (PUB)",
                                                  options.endpoint, options.endpoint_option));
    }
    impl->endpoint = detail::bound_endpoint(impl->pub, options.endpoint);

    std::string snapshot = options.snapshot_endpoint;
    if (snapshot.empty()) {
      Result<std::string> next =
          detail::next_port_endpoint(impl->endpoint, options.snapshot_option);
      if (!next) return next.status();
      snapshot = *next;
    }
    if (Status reachable = check_reachable(options, snapshot, options.snapshot_option); !reachable)
      return reachable;
    router = zmq::socket_t(impl->context, zmq::socket_type::router);
    if (curve) make_curve_server(router, options.curve_secret_key);
    router.set(zmq::sockopt::sndhwm, kSnapshotSendHwm);
    router.set(zmq::sockopt::linger, 0);  // a snapshot nobody reads is worth no wait at exit
    try {
      router.bind(snapshot);
    } catch (const zmq::error_t& e) {
      return Status::error(detail::endpoint_error(e, "serve", "mesh-stream snapshots (ROUTER)",
                                                  snapshot, options.snapshot_option));
    }
    impl->snapshot_endpoint = detail::bound_endpoint(router, snapshot);

    stop_in = zmq::socket_t(impl->context, zmq::socket_type::pair);
    stop_in.bind(kStopEndpoint);
    impl->stop = zmq::socket_t(impl->context, zmq::socket_type::pair);
    impl->stop.connect(kStopEndpoint);
  } catch (const zmq::error_t& e) {
    return Status::error(std::string("mesh stream: cannot set up the sockets: ") + e.what());
  }
  Impl* raw = impl.get();
  raw->snapshot_thread =
      std::thread([raw, router = std::move(router), stop_in = std::move(stop_in)]() mutable {
        raw->serve_snapshots(std::move(router), std::move(stop_in));
      });
  return MeshPublisher(std::move(impl));
}

Status MeshPublisher::publish_meshes(const MeshSet& meshes, double timestamp_s,
                                     std::uint64_t slices) {
  std::map<int, const MeshSet::Entry*> by_label;
  for (const MeshSet::Entry& entry : meshes.meshes)
    if (!by_label.emplace(entry.label, &entry).second)
      return Status::error("mesh stream: label " + std::to_string(entry.label) +
                           " appears twice in the mesh set; give each material one mesh");
  // Labels sent before and absent now go out empty: receivers learn that they vanished.
  std::set<int> labels;
  for (const auto& [label, name] : impl_->published_labels) labels.insert(label);
  for (const auto& [label, entry] : by_label) labels.insert(label);

  std::vector<StreamMessage> messages;
  for (int label : labels) {
    MeshUpdate update;
    update.label = label;
    update.units = impl_->options.units;
    update.frame = impl_->options.frame;
    update.timestamp_s = timestamp_s;
    update.slices = slices;
    if (const auto it = by_label.find(label); it != by_label.end()) {
      update.name = it->second->name;
      update.mesh = it->second->mesh;
      if (impl_->options.normals) update.normals = vertex_normals(update.mesh);
    } else {
      update.name = impl_->published_labels[label];
      if (impl_->options.normals) update.normals.emplace();
    }
    messages.push_back(StreamMessage{0, {}, std::move(update)});
  }
  Status status = impl_->publish(std::move(messages));
  if (status)
    for (const auto& [label, entry] : by_label) impl_->published_labels[label] = entry->name;
  return status;
}

Status MeshPublisher::publish_slice(const LabeledSlice& slice, std::uint64_t index) {
  return impl_->publish({StreamMessage{0, {}, SliceUpdate{index, slice}}});
}

Status MeshPublisher::publish_frame(const FrameImage& frame) {
  return impl_->publish({StreamMessage{0, {}, frame}});
}

Status MeshPublisher::publish_status(const StatusReport& status) {
  return impl_->publish({StreamMessage{0, {}, status}});
}

const std::string& MeshPublisher::scan() const { return impl_->scan; }

std::uint64_t MeshPublisher::last_seq() const { return impl_->next_seq - 1; }

const std::string& MeshPublisher::endpoint() const { return impl_->endpoint; }

const std::string& MeshPublisher::snapshot_endpoint() const { return impl_->snapshot_endpoint; }

std::uint64_t MeshPublisher::snapshots_served() const { return impl_->snapshots_served.load(); }

std::uint64_t MeshPublisher::snapshots_refused() const { return impl_->snapshots_refused.load(); }

}  // namespace sonoshape::publish
