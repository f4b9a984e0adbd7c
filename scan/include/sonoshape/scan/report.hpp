#pragma once
// What a scan reports while it runs and when it ends: counters of frames and slices, drops by
// reason, frame-to-mesh latencies and update times.
#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/repairs.hpp"
#include "sonoshape/core/scan_state.hpp"
#include "sonoshape/recon/reconstruct.hpp"
#include "sonoshape/segmentation/scoring.hpp"

namespace sonoshape::scan {

/// Frames that never became a slice, by reason (keyframe skips are not drops: see
/// ScanCounters::keyframes_skipped).
struct DropCounts {
  std::size_t source = 0;                 ///< lost in the source (its buffer full, rendering late)
  std::size_t pose_missing = 0;           ///< no tracker sample at all
  std::size_t pose_invalid = 0;           ///< an INVALID tracker sample next to the frame's time
  std::size_t pose_gap = 0;               ///< tracker samples lost around the frame's time
  std::size_t pose_extrapolation = 0;     ///< the frame's time outside the tracker samples
  std::size_t segmentation_behind = 0;    ///< the segmentation queue was full
  std::size_t segmentation_failed = 0;    ///< no valid slice from the frame
  std::size_t reconstruction_behind = 0;  ///< the reconstruction queue was full
  std::size_t reconstruction_rejected = 0;  ///< refused by the reconstruction (see the log)

  /// Every drop.
  std::size_t total() const {
    return source + pose_missing + pose_invalid + pose_gap + pose_extrapolation +
           segmentation_behind + segmentation_failed + reconstruction_behind +
           reconstruction_rejected;
  }
};

/// Counters of a running scan (a consistent snapshot).
struct ScanCounters {
  std::size_t frames_received = 0;      ///< frames taken from the frame source
  DropCounts dropped;                   ///< frames dropped, by reason
  std::size_t keyframes_skipped = 0;    ///< near-duplicates of a slice already in
  std::size_t slices = 0;               ///< slices in the reconstruction
  std::size_t updates = 0;              ///< reconstruction updates done
  double last_update_ms = 0.0;          ///< wall time of the last update
  double last_latency_s = 0.0;          ///< frame-to-mesh latency of the newest slice
  double last_slice_timestamp_s = 0.0;  ///< frame time (device clock) of the newest slice
};

/// What a status report says about the scan (mesh-stream.md `state`).
using sonoshape::ScanState;
using sonoshape::to_string;

/// A status report for sinks (the `status` message of the mesh stream).
struct ScanStatus {
  ScanState state = ScanState::kScanning;
  std::string message;  ///< what happened (required for kError)
  ScanCounters counters;
  recon::ReconstructionStats last_update;  ///< per-stage seconds of the last update
};

/// Percentiles of a set of durations (s); all 0 when there are none.
struct LatencyStats {
  std::size_t count = 0;
  double p50_s = 0.0, p95_s = 0.0, max_s = 0.0;
};

/// Nearest-rank percentiles of `samples_s` (copied and sorted).
LatencyStats latency_stats(std::vector<double> samples_s);

/// What the segmentation repaired to make frames' polygons valid (segmentation::make_slice): counts
/// by kind, and the first few repairs with their frame index.
struct RepairReport {
  /// Repairs listed in `first`; the counts go on beyond it.
  static constexpr std::size_t kMaxListed = 20;
  std::map<std::string, std::size_t> counts;  ///< by Repair::kind
  struct Entry {
    std::size_t frame = 0;  ///< the frame's index in its source
    Repair repair;
  };
  std::vector<Entry> first;

  void add(std::size_t frame, const Repair& repair);
  std::size_t total() const;
};

/// Why the scan stopped.
enum class StopReason { kSourceEnded, kSourceFailed, kStopRequested, kDuration, kMaxSlices };

/// "source ended", "source failed", "stop requested", "duration reached", "max slices reached".
const char* to_string(StopReason reason);

/// The end of a scan.
struct ScanSummary {
  ScanCounters counters;
  StopReason stop_reason = StopReason::kSourceEnded;
  std::string frame_source;  ///< the frame source's final state and message
  std::string pose_source;   ///< the pose source's final state and message
  /// Frames the frame source lost, by reason (StreamSource::losses; empty: no breakdown).
  std::map<std::string, std::size_t> frame_source_losses;
  std::vector<std::string> errors;  ///< everything reported as kError, in order
  LatencyStats latency;             ///< frame capture (monotonic) -> mesh ready, per slice
  double update_ms_median = 0.0;    ///< wall time of the reconstruction updates
  double update_ms_p95 = 0.0;       ///< nearest rank, as the latency's
  double update_ms_max = 0.0;
  double duration_s = 0.0;  ///< wall time from start() to the last stage's end
  RepairReport repairs;     ///< what the segmentation repaired
  /// Simulated sources: the keyframes' label maps against the simulator's truth, summed.
  std::optional<segmentation::LabelComparison> segmentation_scores;
  std::map<int, std::string> label_names;  ///< for the scores' table
  /// Every material of the setup without a mesh at the end, with why: "label 3 (rib): ...".
  std::vector<std::string> labels_without_mesh;
  /// What the end of the scan failed to write, each with where and why (a final save that did
  /// not fit on the disk, a journal without its last keyframes or its end record): the scan
  /// then exits non-zero (issue 40, D1). Empty when every output is whole.
  std::vector<std::string> incomplete_outputs;
};

}  // namespace sonoshape::scan
