#pragma once
// The live mesh stream as a scan output: every slice, mesh update and status of a scan goes to
// a ZeroMQ publisher (docs/formats/mesh-stream.md).
#include <memory>
#include <string>

#include "sonoshape/core/status.hpp"
#include "sonoshape/scan/sink.hpp"

namespace sonoshape::scan {

/// Publishes a scan on `endpoint` (PUB) with its snapshot server on `snapshot_endpoint`
/// (empty: the PUB port + 1). Sending never blocks the pipeline: a slow subscriber only misses
/// intermediate updates.
class PublishSink final : public ScanSink {
 public:
  /// Binds both sockets; fails with a message naming the endpoint and how to fix it.
  static Result<std::shared_ptr<PublishSink>> bind(const std::string& endpoint,
                                                   const std::string& snapshot_endpoint = {});
  ~PublishSink() override;

  Status on_slice(const LabeledSlice& slice, std::size_t index) override;
  Status on_meshes(const MeshSet& meshes, const MeshUpdateInfo& info) override;
  Status on_status(const ScanStatus& status) override;
  Status on_finish(const MeshSet& meshes, const SliceSet& slices, const ScanSummary& summary) override;

  /// The endpoints as bound (a port "*" resolved) and the scan's uuid.
  std::string endpoint() const;
  std::string snapshot_endpoint() const;
  std::string scan_id() const;

 private:
  struct Impl;
  explicit PublishSink(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::scan
