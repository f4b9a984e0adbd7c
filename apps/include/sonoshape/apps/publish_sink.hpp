#pragma once
// The live mesh stream as a scan output: every slice, mesh update and status of a scan goes to
// a ZeroMQ publisher (docs/formats/mesh-stream.md).
#include <memory>
#include <string>

#include "sonoshape/core/status.hpp"
#include "sonoshape/scan/sink.hpp"

namespace sonoshape::apps {

/// Which B-mode frames go out as `frame` messages (small grey previews for live views).
struct FramePreviewOptions {
  /// At most this many previews a second (the first frame after each period); 0: none.
  double rate_hz = 0.0;
  /// The preview's longest side, in pixels (downsampled by area averaging, never enlarged).
  int max_side_px = 256;
};

/// Who may read the stream (docs/formats/mesh-stream.md, "Who may read the stream").
struct StreamAccess {
  /// The server's CURVE secret key (Z85 text, from --curve-secret-key); empty: plain ZeroMQ.
  std::string curve_secret_key;
  /// --allow-remote: an endpoint other machines can reach may be bound (with a CURVE key).
  bool allow_remote = false;
};

/// Publishes a scan on `endpoint` (PUB) with its snapshot server on `snapshot_endpoint`
/// (empty: the PUB port + 1). Sending never blocks the pipeline: a slow subscriber only misses
/// intermediate updates.
class PublishSink final : public scan::ScanSink {
 public:
  /// Binds both sockets; fails with a message naming the endpoint and how to fix it (an
  /// endpoint other machines can reach needs `access` to allow it and hold a CURVE key).
  /// `previews`: which posed frames are also published as `frame` messages.
  static Result<std::shared_ptr<PublishSink>> bind(const std::string& endpoint,
                                                   const std::string& snapshot_endpoint = {},
                                                   const FramePreviewOptions& previews = {},
                                                   const StreamAccess& access = {});
  ~PublishSink() override;

  /// Publishes a downsampled copy of the frame on its plane, at most previews.rate_hz a second.
  Status on_frame(const TrackedFrame& frame, const Eigen::Matrix4d& T_reference_image) override;
  Status on_slice(const LabeledSlice& slice, std::size_t index) override;
  Status on_meshes(const MeshSet& meshes, const scan::MeshUpdateInfo& info) override;
  Status on_status(const scan::ScanStatus& status) override;
  Status on_finish(const MeshSet& meshes, const SliceSet& slices,
                   const scan::ScanSummary& summary) override;

  /// The endpoints as bound (a port "*" resolved) and the scan's uuid.
  std::string endpoint() const;
  std::string snapshot_endpoint() const;
  std::string scan_id() const;

 private:
  struct Impl;
  explicit PublishSink(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::apps
