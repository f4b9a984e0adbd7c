#pragma once
// The live mesh stream's server side (docs/formats/mesh-stream.md): a PUB socket for the
// messages and a snapshot server for late joiners.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/publish/mesh_stream.hpp"

namespace sonoshape::publish {

/// Where and how MeshPublisher publishes.
struct PublisherOptions {
  /// PUB endpoint. Loopback by default; "tcp://*:5556" serves every interface, and a port "*"
  /// picks a free one (read it back with MeshPublisher::endpoint()).
  std::string endpoint = "tcp://127.0.0.1:5556";
  /// Snapshot (ROUTER) endpoint; empty: the PUB port + 1 on the same host (tcp only).
  std::string snapshot_endpoint;
  /// Messages queued per subscriber before further ones are dropped for it (ZMQ_SNDHWM): small,
  /// so that a slow subscriber loses intermediate updates instead of holding memory.
  int send_hwm = 16;
  /// How long closing the publisher waits to deliver messages still queued, in ms.
  int linger_ms = 1000;
  /// Send per-vertex normals (area-weighted, unit) with every mesh.
  bool normals = false;
  /// Unit and coordinate frame named in mesh headers.
  std::string units = "mm";
  std::string frame = "reference";
  /// Option names quoted by bind errors, so that they point at what the user typed.
  std::string endpoint_option = "--publish";
  std::string snapshot_option = "--snapshot";
  /// The server's CURVE secret key (Z85, 40 characters; read_curve_key): both sockets become
  /// CURVE servers, and only clients that know the matching public key can connect. Empty:
  /// plain ZeroMQ, allowed on loopback only (is_local_endpoint).
  std::string curve_secret_key;
  /// Binding an endpoint other machines can reach needs this (--allow-remote) and a CURVE key.
  bool allow_remote = false;
  /// Snapshot requests answered, all clients together: a burst of this many, then this many a
  /// second; the others get a `busy` error reply (docs/formats/mesh-stream.md) and no snapshot.
  int snapshot_burst = 16;
  double snapshot_rate_hz = 4.0;
};

/// The most slices a snapshot carries: the scan's newest (a slice message is a few kilobytes).
constexpr std::size_t kMaxSnapshotSlices = 4096;

/// Publishes meshes, slices and status of one scan. Every message gets the next seq (one counter
/// across topics, from 1) and the scan's uuid (a random v4 uuid drawn per publisher). Publishing
/// never blocks: a slow or vanished subscriber only misses messages. A thread of its own answers
/// snapshot requests with every slice of the scan (the newest kMaxSnapshotSlices, in order), the
/// newest mesh of every label, the newest status and the newest frame preview.
///
/// Thread safety: call the publish functions from one thread (or serialise them); the snapshot
/// thread shares only state guarded inside.
class MeshPublisher {
 public:
  /// Binds the PUB and snapshot sockets and starts the snapshot thread. Errors (address in use,
  /// invalid endpoint, host not of this machine; an endpoint other machines can reach without
  /// allow_remote and a CURVE key; a libzmq without CURVE) say which socket, where, and how to
  /// fix it.
  static Result<MeshPublisher> bind(const PublisherOptions& options = {});

  MeshPublisher(MeshPublisher&&) noexcept;
  MeshPublisher& operator=(MeshPublisher&&) noexcept;
  /// Stops the snapshot thread and closes the sockets (waiting up to linger_ms to deliver).
  ~MeshPublisher();

  /// Publishes one `mesh.<label>` message per entry of `meshes`, in label order, and an empty mesh
  /// for every label published before that `meshes` no longer holds (a vanished material).
  /// `timestamp_s`: time of the newest slice included; `slices`: how many slices built them.
  /// Fails without sending anything when a mesh cannot be encoded (NaN, index out of range, a
  /// label below 1 or given twice).
  Status publish_meshes(const MeshSet& meshes, double timestamp_s, std::uint64_t slices);

  /// Publishes the slice just added; `index`: its position in the scan, from 0. Fails for
  /// non-finite numbers.
  Status publish_slice(const LabeledSlice& slice, std::uint64_t index);

  /// Publishes a B-mode frame preview (a `frame` message; keep it small and rare: the caller
  /// downsamples and rate-limits). Fails for what encode_message refuses (an empty or oversized
  /// picture, a plane that is not orthonormal, non-finite numbers).
  Status publish_frame(const FrameImage& frame);

  /// Publishes a status report. Fails for negative or non-finite times, or state error without a
  /// message.
  Status publish_status(const StatusReport& status);

  /// The scan uuid every message carries.
  const std::string& scan() const;
  /// The seq of the newest message published; 0 before the first.
  std::uint64_t last_seq() const;
  /// The PUB endpoint as bound (a wildcard port resolved).
  const std::string& endpoint() const;
  /// The snapshot endpoint as bound.
  const std::string& snapshot_endpoint() const;
  /// How many snapshot requests have been answered (for tests and statistics).
  std::uint64_t snapshots_served() const;
  /// How many snapshot requests got a `busy` reply (over the rate) instead of a snapshot.
  std::uint64_t snapshots_refused() const;

 private:
  struct Impl;
  explicit MeshPublisher(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// A random (version 4) uuid in its 36-character text form.
std::string random_uuid();

/// Area-weighted unit vertex normals (zero for a vertex no triangle uses).
std::vector<Vec3> vertex_normals(const TriangleMesh& mesh);

}  // namespace sonoshape::publish
