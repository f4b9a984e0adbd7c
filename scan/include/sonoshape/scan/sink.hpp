#pragma once
// Outputs of a scan: a ScanSink receives slices, meshes and status reports. The sinks that need
// other modules implement it outside this one (apps/: the file writer, the ZeroMQ publisher,
// the OpenIGTLink server); tests add their own. Calls into sinks are serialised by the pipeline
// (never two at once) but may come from different pipeline threads; a sink should return quickly.
#include <Eigen/Core>
#include <cstddef>
#include <string>

#include "sonoshape/core/frame.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/scan/report.hpp"

namespace sonoshape::scan {

/// What came with a mesh update.
struct MeshUpdateInfo {
  std::size_t slices = 0;            ///< slices the meshes were built from
  double timestamp_s = 0.0;          ///< frame time (device clock) of the newest slice included
  recon::ReconstructionStats stats;  ///< per-stage seconds of this update
  double update_ms = 0.0;            ///< wall time of the update
};

/// Receives what a scan produces. Every call may fail (a full disk, a network error): the
/// pipeline logs the message and goes on.
class ScanSink {
 public:
  virtual ~ScanSink() = default;
  /// A frame that got a pose, before the keyframe choice; `T_reference_image` maps its pixels
  /// (column, row, 0) to reference mm (spacing included). Called from the acquisition thread for
  /// every such frame, except while another sink call is in progress (the acquisition never
  /// waits for a sink), so it must be quick; by default ignored.
  virtual Status on_frame(const TrackedFrame& /*frame*/,
                          const Eigen::Matrix4d& /*T_reference_image*/) {
    return Status::ok();
  }
  /// A slice just joined the reconstruction; `index` counts the scan's slices from 0.
  virtual Status on_slice(const LabeledSlice& slice, std::size_t index) = 0;
  /// The meshes after an update (one per material; a material may vanish).
  virtual Status on_meshes(const MeshSet& meshes, const MeshUpdateInfo& info) = 0;
  /// A status report: after every update, when a source ends or fails, and at the end.
  virtual Status on_status(const ScanStatus& status) = 0;
  /// The scan is over: the final meshes, the slices they came from, and the summary. Called
  /// once, after everything else, also when the scan was interrupted.
  virtual Status on_finish(const MeshSet& meshes, const SliceSet& slices,
                           const ScanSummary& summary) = 0;
};

/// The JSON form of a summary (what `scan.json` holds), for tools and tests.
std::string summary_json(const ScanSummary& summary);

}  // namespace sonoshape::scan
