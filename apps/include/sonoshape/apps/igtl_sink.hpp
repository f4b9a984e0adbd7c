#pragma once
// OpenIGTLink as a scan output (`scan --igtl-serve`): 3D Slicer's OpenIGTLinkIF, or any
// OpenIGTLink client, connects and watches the surfaces grow over the live image.
// Built only with SONOSHAPE_WITH_OPENIGTLINK (publish::IgtlServer).
#include <memory>
#include <string>

#include "sonoshape/core/status.hpp"
#include "sonoshape/scan/sink.hpp"

namespace sonoshape::apps {

/// Serves a scan over OpenIGTLink: every mesh update as one POLYDATA per label (named after the
/// label), every tracked frame as IMAGE with its pose (T_reference_image), every status as
/// STATUS; GET_POLYDATA answered with the current surfaces. Never blocks the pipeline: a slow
/// client misses intermediate messages, a vanished one is forgotten.
class IgtlSink final : public scan::ScanSink {
 public:
  /// Listens on `host`:`port` (port 0: a free one, see port()). Fails with a message naming
  /// --igtl-serve, the address and how to fix it.
  static Result<std::shared_ptr<IgtlSink>> start(const std::string& host, int port);
  ~IgtlSink() override;

  Status on_frame(const TrackedFrame& frame, const Eigen::Matrix4d& T_reference_image) override;
  Status on_slice(const LabeledSlice& slice, std::size_t index) override;
  Status on_meshes(const MeshSet& meshes, const scan::MeshUpdateInfo& info) override;
  Status on_status(const scan::ScanStatus& status) override;
  Status on_finish(const MeshSet& meshes, const SliceSet& slices,
                   const scan::ScanSummary& summary) override;

  /// The port listened on.
  int port() const;
  /// One line for the log: clients served, messages sent and dropped.
  std::string describe() const;

 private:
  struct Impl;
  explicit IgtlSink(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::apps
