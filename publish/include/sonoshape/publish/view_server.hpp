#pragma once
// The browser view of a live scan (docs/viewer.md): an HTTP server for the page in viewer/ and a
// WebSocket that carries the mesh stream's messages to it, their frames byte for byte. No Beast
// or Asio type here: they stay in view_server.cpp.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "sonoshape/core/status.hpp"
#include "sonoshape/publish/mesh_stream.hpp"

namespace sonoshape::publish {

/// Topic of the messages the view server itself sends to the page (never on the ZeroMQ stream):
/// frame 1 is JSON `{"stream": "connected"|"waiting"|"finished", "endpoint": "...",
/// "message": "..."}`.
constexpr std::string_view kViewerTopic = "viewer";

/// What the view tells its pages about the stream it follows.
enum class StreamState {
  kWaiting,    ///< no publisher answers (yet): `message` says why
  kConnected,  ///< following a publisher
  kFinished,   ///< the scan followed finished and its publisher has closed: a normal end
};

/// Packs one multipart message into one WebSocket binary message (docs/viewer.md): a uint32 frame
/// count, one uint32 byte length per frame, then the frames, each padded with zeros to a multiple
/// of 4 bytes so that the page views float32/uint32 arrays in place. Little-endian.
std::string pack_frames(const Frames& frames);

/// Where the view server listens and what it serves.
struct ViewServerOptions {
  /// HOST:PORT of the HTTP server. Loopback by default (a bedside workstation must not show the
  /// scan to its network unless asked); port 0 picks a free one (read it back with url()).
  std::string http = "127.0.0.1:8080";
  /// The page's folder (viewer/ of the source tree): index.html, src/*.js, and three.js under
  /// node_modules/three (installed by `npm ci`, see scripts/install-deps).
  std::filesystem::path web_root;
};

/// Serves the page and forwards stream messages to every connected page. post() never blocks:
/// each connection keeps only the newest message of every topic that it has not yet sent, so a
/// slow browser loses intermediate meshes, never the latest, and never slows the caller; slices
/// are the exception: each one is kept (up to 4096 a scan), as the page draws them all. A page
/// that connects late first receives the newest message of every topic of the current scan and
/// its slices.
///
/// Thread safety: post() may be called from any thread; one thread of its own runs the server.
class ViewServer {
 public:
  /// Binds the HTTP address and starts the server thread. Fails for an address that is not
  /// HOST:PORT, a host that is not of this machine, a port in use, or a web root without
  /// index.html; the message names the address or folder and how to fix it.
  static Result<ViewServer> start(const ViewServerOptions& options);

  ViewServer(ViewServer&&) noexcept;
  ViewServer& operator=(ViewServer&&) noexcept;
  /// Stops the server thread and closes every connection.
  ~ViewServer();

  /// Forwards one message (frame 0 its topic) to every page. Messages of a scan other than the
  /// previous message's (header key "scan") drop the cached meshes of the old scan.
  void post(const Frames& frames);

  /// Tells the pages whether the stream is flowing (`connected`), being waited for (`waiting`,
  /// with `message` saying why) or over (`finished`: the scan ended and its publisher closed), as
  /// a `viewer` message; late pages get the newest.
  void post_stream_state(StreamState state, const std::string& endpoint,
                         const std::string& message);

  /// Waits until every message posted so far has been written to every page open now, at most
  /// `timeout`; true when all went. `scan --view` calls it at its end, so that the scan's last
  /// status reaches the pages before the server goes.
  bool flush(std::chrono::milliseconds timeout);

  /// The page's address, e.g. "http://127.0.0.1:8080/" (a port 0 resolved).
  std::string url() const;
  /// WebSocket connections open now.
  std::size_t connections() const;
  /// Connections open now, of every kind (file requests and WebSockets): at most 32, of which
  /// at most 16 WebSockets (docs/security.md).
  std::size_t open_connections() const;
  /// Connections closed to make room for a newer one at the limit of 32 (the oldest that held no
  /// WebSocket: a half-open request, a client that did not read its file, an idle keep-alive).
  std::uint64_t connections_closed_at_limit() const;
  /// Mesh messages not shown because their label was beyond the first kMaxStreamLabels of the
  /// scan (a warning says so once).
  std::uint64_t meshes_refused_over_label_limit() const;
  /// Messages dropped because a newer one of the same topic (or a new scan) replaced them before
  /// they were sent: in the server's inbox and in each connection's queue, summed.
  std::uint64_t messages_replaced() const;

 private:
  struct Impl;
  explicit ViewServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::publish
