#pragma once
// An OpenIGTLink (protocol v2) server for 3D Slicer's OpenIGTLinkIF and other OpenIGTLink
// clients: the surfaces as POLYDATA, the current frame as IMAGE, the scan's state as STATUS.
// Built only with SONOSHAPE_WITH_OPENIGTLINK; no OpenIGTLink type appears here.
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "sonoshape/core/image.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/publish/mesh_stream.hpp"

namespace sonoshape::publish {

/// Where and how IgtlServer serves.
struct IgtlServerOptions {
  /// Address to listen on: loopback by default (a scan's images stay on this machine);
  /// "0.0.0.0" serves every interface.
  std::string host = "127.0.0.1";
  /// TCP port; 18944 is OpenIGTLink's (and Slicer's) default; 0 picks a free one (read it back
  /// with IgtlServer::port()).
  int port = 18944;
  /// Messages queued per client before the oldest unsent ones are dropped for it: a slow client
  /// misses intermediate updates, it never holds back the publisher.
  std::size_t max_queued_messages = 32;
  /// Clients served at once; a connection beyond them is closed as soon as it is accepted
  /// (counted in IgtlServerStats::clients_refused): a flood of connections cannot take the
  /// server's memory or its thread's time from the clients it serves.
  std::size_t max_clients = 16;
  /// How long closing the server waits to deliver what is still queued, in ms.
  int linger_ms = 1000;
  /// Device names of the IMAGE and STATUS messages (POLYDATA carry the label's name).
  std::string image_device = "Image";
  std::string status_device = "Scan";
  /// Option name quoted by errors, so that they point at what the user typed.
  std::string option = "--igtl-serve";
};

/// What the server has done so far (for tests and the scan summary).
struct IgtlServerStats {
  std::size_t clients = 0;              ///< connected now
  std::size_t clients_accepted = 0;     ///< connections accepted since the start
  std::uint64_t messages_sent = 0;      ///< messages written whole to a client
  std::uint64_t messages_dropped = 0;   ///< messages a slow client missed (replaced or evicted)
  std::uint64_t requests_answered = 0;  ///< GET_POLYDATA / GET_IMAGE / GET_STATUS answered
  std::size_t clients_refused = 0;      ///< connections closed at once: max_clients reached
  std::size_t clients_expelled = 0;     ///< clients closed for a message over the size limit
};

/// The largest message body a client may announce (1 MiB): requests have empty bodies and the
/// messages 3D Slicer sends unasked (STATUS, capabilities) a few hundred bytes. A client that
/// announces more is closed, with a warning naming it and the size.
inline constexpr std::uint64_t kIgtlMaxClientBodyBytes = 1u << 20;

/// Serves one scan over OpenIGTLink. Each connected client gets, on connection, the newest
/// surface of every label, the newest image and status, and then every update as it is
/// published: one POLYDATA per label (device name = the label's name, or "label_<id>" when it
/// has none; an empty one when a label vanished), an IMAGE (8-bit, its matrix the image's pose
/// in the reference frame, origin at the image centre as OpenIGTLink defines it) and a STATUS.
/// GET_POLYDATA is answered with the surface it names, or every surface when the name matches
/// none (e.g. the Debian example's "Client"); GET_IMAGE and GET_STATUS with the newest ones.
///
/// Publishing never blocks: messages are packed in the caller's thread and queued per client; a
/// thread of the server's own writes them with non-blocking sends. A queued, unsent message is
/// replaced by a newer one of the same device, and beyond max_queued_messages the oldest unsent
/// ones are dropped (counted). A client that disconnects or fails is closed and forgotten.
///
/// Clients are not trusted (docs/security.md): the server thread reads, parses and writes
/// without the lock the publish functions take (it takes it only to queue), keeps at most one
/// message header per client (bodies are skipped, never stored), reads at most 64 KiB per
/// client per turn, answers a burst of identical requests once, closes a client announcing a
/// body over kIgtlMaxClientBodyBytes, and serves at most max_clients at once.
///
/// Thread safety: the publish functions may be called from any one thread at a time (or
/// serialised); stats() and port() from any thread.
class IgtlServer {
 public:
  /// Listens on host:port and starts the server thread. Errors (port in use, bad host) name the
  /// option, the address and how to fix it.
  static Result<IgtlServer> start(const IgtlServerOptions& options = {});

  IgtlServer(IgtlServer&&) noexcept;
  IgtlServer& operator=(IgtlServer&&) noexcept;
  /// Waits up to linger_ms for the queues to drain, then closes every connection.
  ~IgtlServer();

  /// Sends every entry of `meshes` as POLYDATA (points in mm, triangles as polygons), and an
  /// empty POLYDATA for a label sent before that `meshes` no longer holds. Fails without
  /// sending anything for a non-finite vertex or a triangle index out of range.
  Status publish_meshes(const MeshSet& meshes);

  /// Sends `image` as IMAGE; `T_reference_image` maps pixel (column, row, 0) to reference mm
  /// (it holds the pixel spacing as the lengths of its first two columns). Fails for an empty
  /// image or a matrix that is not finite or whose first two columns are (nearly) parallel.
  Status publish_image(const GreyImage& image, const Eigen::Matrix4d& T_reference_image);

  /// Sends a STATUS: code OK while scanning or idle, an error code in state error; the error
  /// name is the state, the status string the message and counters.
  Status publish_status(const StatusReport& status);

  /// The port listened on (a port 0 resolved).
  int port() const;
  IgtlServerStats stats() const;

 private:
  struct Impl;
  explicit IgtlServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::publish
