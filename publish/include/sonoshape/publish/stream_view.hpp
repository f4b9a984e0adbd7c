#pragma once
// `sonoshape view` and `scan --view` as a library: a MeshSubscriber thread that relays the mesh
// stream to a ViewServer (docs/viewer.md).
#include <chrono>
#include <memory>
#include <string>

#include "sonoshape/core/status.hpp"
#include "sonoshape/publish/subscriber.hpp"
#include "sonoshape/publish/view_server.hpp"

namespace sonoshape::publish {

/// What StreamView subscribes to and serves.
struct StreamViewOptions {
  /// The stream to follow; its topics are ignored (the view takes `mesh.` and `status`). With a
  /// snapshot endpoint the view joins a running scan with its current meshes.
  SubscriberOptions stream;
  /// Where the page is served.
  ViewServerOptions server;
  /// How long to wait between attempts to reach a publisher that is not there yet, in ms.
  int retry_ms = 1000;
};

/// Serves the page and relays the stream to it from a thread of its own until destroyed. It waits
/// for a publisher that is not up yet (telling the pages so), and joins again through a snapshot
/// when a new scan appears mid-way (a restarted scan on the same endpoint).
class StreamView {
 public:
  /// Starts the server (see ViewServer::start for its errors) and the relay thread. A stream
  /// endpoint that cannot be reached is not an error: the relay keeps trying.
  static Result<StreamView> start(const StreamViewOptions& options);

  StreamView(StreamView&&) noexcept;
  StreamView& operator=(StreamView&&) noexcept;
  /// Stops the relay thread (within about 2 s: a snapshot request in flight is waited for), then
  /// the server.
  ~StreamView();

  /// Waits until the relay has passed on the last status of `scan` (`"finished": true`) and
  /// the server has written everything to the pages open now, at most `timeout`; true when all
  /// went. The end of `scan --view`: its pages show the finished scan, not a lost one.
  bool drain(const std::string& scan, std::chrono::milliseconds timeout);

  /// The page's address.
  std::string url() const;
  /// The server, for its counters.
  const ViewServer& server() const;
  /// Stream messages relayed to the server so far (snapshot ones included).
  std::uint64_t messages_relayed() const;

 private:
  struct Impl;
  explicit StreamView(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::publish
