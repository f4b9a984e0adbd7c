#pragma once
// The reference client of the live mesh stream (docs/formats/mesh-stream.md): subscribes, joins
// late through a snapshot, and checks every message against the format.
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/status.hpp"
#include "sonoshape/publish/mesh_stream.hpp"

namespace sonoshape::publish {

/// Where MeshSubscriber listens and what it asks for.
struct SubscriberOptions {
  /// The publisher's PUB endpoint.
  std::string endpoint = "tcp://127.0.0.1:5556";
  /// The publisher's snapshot endpoint; empty: no snapshot, live messages only.
  std::string snapshot_endpoint;
  /// Topic prefixes to receive ("mesh.", "slice", "status"); empty: every topic.
  std::vector<std::string> topics;
  /// How long connect() waits for the publisher and its snapshot, in ms.
  int snapshot_timeout_ms = 5000;
  /// Messages queued in this process before ZeroMQ stops reading (ZMQ_RCVHWM). Small, like the
  /// publisher's: a slow reader then loses intermediate updates at the publisher instead of
  /// working through a long backlog of stale ones.
  int receive_hwm = 16;
  /// The publisher's CURVE public key (Z85, 40 characters; read_curve_key), for a publisher
  /// that has a CURVE secret key: both connections are then encrypted, with a key pair of this
  /// subscriber's own drawn per connect(). Empty: plain ZeroMQ, which a CURVE publisher refuses.
  std::string server_public_key;
};

/// Subscribes to a mesh stream. With a snapshot endpoint it follows the late-joiner protocol:
/// subscribe, wait until the subscription reaches the publisher, ask for a snapshot, then drop
/// live messages of that scan with seq <= the snapshot's end seq.
class MeshSubscriber {
 public:
  /// Connects (and, with a snapshot endpoint, fetches the snapshot). Fails for an invalid
  /// endpoint, when no snapshot arrives within snapshot_timeout_ms (no publisher there), when
  /// the publisher refuses the handshake (a wrong or missing server key), or for a server key
  /// on a libzmq without CURVE. A `busy` reply is retried after the time it names.
  static Result<MeshSubscriber> connect(const SubscriberOptions& options);

  MeshSubscriber(MeshSubscriber&&) noexcept;
  MeshSubscriber& operator=(MeshSubscriber&&) noexcept;
  ~MeshSubscriber();

  /// The next message, waiting at most `timeout`: first the snapshot's messages (newest mesh of
  /// every label, newest status) closed by its `end` message, then live ones. None when the time
  /// runs out. An error when the received message breaks the format: the error names its topic,
  /// seq and what is wrong; the next call goes on with the following message.
  Result<std::optional<StreamMessage>> receive(std::chrono::milliseconds timeout);

  /// Whether the publisher has closed the connection since connect() (its scan exited) and not
  /// come back; known with a snapshot endpoint over tcp or ipc (the connection is watched from
  /// its handshake on), always false otherwise.
  bool publisher_gone();

  /// The frames of the message the last receive() returned or rejected (empty after a timeout).
  const Frames& last_frames() const;
  /// The end seq of the snapshot; none without one.
  std::optional<std::uint64_t> snapshot_seq() const;
  /// Live messages dropped because the snapshot already covered them (seq <= snapshot seq).
  std::uint64_t covered_by_snapshot() const;

 private:
  struct Impl;
  explicit MeshSubscriber(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::publish
