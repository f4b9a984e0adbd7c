#pragma once
// The live scan pipeline: three threads joined by bounded queues.
//
//   FrameSource ─┐ acquisition thread: sync (pose at the frame's time), keyframe choice
//   PoseSource ──┘        │ queue (segmentation_queue frames)
//                  segmentation thread: frame -> slice (SegmentationStage)
//                         │ queue (reconstruction_queue slices)
//                  reconstruction thread: add_slice..., update -> sinks (meshes, slices, status)
//
// Frames that cannot keep up are dropped and counted, never queued without bound: in real-time
// mode a full queue drops its oldest entry; when playing as fast as possible every queue
// waits instead (backpressure to the source: nothing is lost, the slowest stage sets the
// pace). The reconstruction thread takes every slice queued since its last update, so a slow
// update batches slices rather than losing them. A source that fails or ends is reported in
// the status; the scan finishes what it has, and sinks get the final meshes.
#include <array>
#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "sonoshape/acquisition/frame_source.hpp"
#include "sonoshape/core/bounded_queue.hpp"
#include "sonoshape/scan/journal.hpp"
#include "sonoshape/scan/label_maps.hpp"
#include "sonoshape/scan/report.hpp"
#include "sonoshape/scan/setup.hpp"
#include "sonoshape/scan/sink.hpp"
#include "sonoshape/scan/stages.hpp"
#include "sonoshape/tracking/keyframes.hpp"
#include "sonoshape/tracking/pose_source.hpp"
#include "sonoshape/tracking/time_sync.hpp"

namespace sonoshape::scan {

/// The sources of a scan and what is known about them (see sources.hpp for the factory).
struct ScanSource {
  std::unique_ptr<acquisition::FrameSource> frames;
  std::unique_ptr<tracking::PoseSource> poses;
  ScanSetup setup;
  /// Device time of the first frame: real-time playback of recorded or simulated data starts
  /// there.
  double device_origin_s = 0.0;
  /// The tracker latency when the source knows it (a simulated tracker); none: unknown.
  std::optional<double> tracker_latency_s;
  std::string description;  ///< one line for the log
  /// A simulated source's truth label frame by frame index (none once it is gone), for scoring
  /// the segmentation as the scan goes; empty for real sources.
  std::function<std::optional<LabelImage>(std::int64_t frame_index)> truth_of_frame;
  /// With SourceRequest::labels: the site's label maps, for a LabelMapStage (not started).
  std::unique_ptr<LabelMapFeed> labels;
};

/// How the pipeline runs.
struct ScanOptions {
  tracking::SyncOptions sync;           ///< tracker latency, largest gap, extrapolation
  tracking::KeyframeOptions keyframes;  ///< when a frame is a new slice (degrees, mm)
  /// Recorded and simulated sources: true plays them at their own pace (real time), false as
  /// fast as the pipeline goes.
  bool real_time = true;
  double speed = 1.0;  ///< real-time factor of recorded sources
  /// true: full queues drop their oldest entry (live); false: they wait (nothing is lost).
  bool drop_when_behind = true;
  std::size_t frame_buffer = 16;          ///< frames the frame source buffers
  std::size_t pose_buffer = 1024;         ///< samples the pose source buffers
  std::size_t segmentation_queue = 4;     ///< keyframes waiting for segmentation
  std::size_t reconstruction_queue = 32;  ///< slices waiting for the reconstruction
  /// How long a frame waits for the tracker sample after its time (s) before it is dropped
  /// as extrapolation: the tracker's period plus its latency, with margin.
  double pose_wait_s = 0.5;
  double duration_s = 0.0;     ///< stop after this much wall time (s); 0: no limit
  std::size_t max_slices = 0;  ///< stop once this many slices are in; 0: no limit
};

/// Runs one scan. Use: construct, add_sink, start, (poll counters, request_stop), finish.
class ScanPipeline {
 public:
  /// Takes the sources and the stages. Throws std::invalid_argument for missing sources or
  /// stages, zero queue sizes, or invalid sync / keyframe options.
  ScanPipeline(ScanSource source, std::unique_ptr<SegmentationStage> segmentation,
               std::unique_ptr<ReconstructionStage> reconstruction, const ScanOptions& options);
  /// Stops a running scan and finishes it when finish() was not called, so that sinks always
  /// get the end.
  ~ScanPipeline();
  ScanPipeline(const ScanPipeline&) = delete;
  ScanPipeline& operator=(const ScanPipeline&) = delete;

  /// Adds an output (before start()); sinks are called in the order added.
  void add_sink(std::shared_ptr<ScanSink> sink);
  /// Appends every keyframe the reconstruction accepts to `journal` (before start()), right
  /// after the update that took it and before the sinks hear of it, and its end record at
  /// finish(). A failing append is reported once (kError) and retried with the next keyframe;
  /// the scan goes on.
  void set_journal(std::shared_ptr<KeyframeJournal> journal);
  /// A resumed scan (before start()): puts `keyframes` (a journal's) into the reconstruction in
  /// one update and into the keyframe choice, so that the scan goes on where it stopped. The
  /// sinks get these slices and meshes when the scan starts. Fails when the reconstruction
  /// refuses a slice or the update fails (the message names the keyframe).
  Status restore(const std::vector<JournalKeyframe>& keyframes);

  /// Starts the sources and the three threads. Fails when already started or when a source
  /// cannot start.
  Status start();
  /// Asks the scan to stop: the sources stop, queued work is finished. Thread-safe; returns
  /// at once.
  void request_stop();
  /// Waits up to `timeout_s` for the scan to end by itself or after request_stop(); true when
  /// it has.
  bool wait_for(double timeout_s);
  /// Waits for the end, joins the threads, sends the final status and on_finish to the sinks,
  /// and returns the summary. Idempotent (later calls return the same summary).
  ScanSummary finish();

  /// A snapshot of the counters (thread-safe; for a live status line).
  ScanCounters counters() const;
  /// The meshes of the last update (a copy; thread-safe).
  MeshSet meshes() const;

 private:
  struct Candidate;
  struct SliceItem;
  void acquisition_loop();
  // The steps of acquisition_loop: why to stop before the next frame (none: go on); the frames
  // until a reason to stop; the drops of a frame without a pose; the keyframe choice (false: not
  // a keyframe, or a degenerate plane, reported once); the queue to segmentation.
  std::optional<StopReason> stop_before_next_frame();
  StopReason acquire_frames();
  void count_sync_failure(tracking::SyncFailure failure);
  bool choose_keyframe(Candidate& candidate, const Eigen::Matrix4d& T_reference_image,
                       bool& degenerate_reported);
  void queue_for_segmentation(std::unique_ptr<Candidate> candidate);
  /// Reports each change of a live source's condition() (into trouble, and back), however
  /// brief: `changes` from its take_condition_changes().
  void report_condition_changes(const std::vector<std::string>& changes, const std::string& name,
                                const std::string& when_back, const std::string& meanwhile);
  void report_frame_source_trouble();
  void report_pose_source_trouble();
  void segmentation_loop();
  void reconstruction_loop();
  // The steps of reconstruction_loop: the batch's slices into the reconstruction (those it
  // refuses are withdrawn); the update (none when it failed: its slices are withdrawn and the
  // meshes kept); the update's stages in the debug log; the counters, meshes and sinks.
  std::vector<const SliceItem*> add_batch(const std::vector<std::unique_ptr<SliceItem>>& batch);
  std::optional<recon::UpdateStats> update_with(const std::vector<const SliceItem*>& added);
  void log_update(const recon::UpdateStats& stats, std::size_t added, double seconds) const;
  void publish_update(const std::vector<const SliceItem*>& added, const recon::UpdateStats& stats,
                      double update_start_s, double ready_s, std::size_t first_slice_index);
  // After the last update: the one-shot meshes of all the slices where the online ones only
  // approach them (ReconstructionStage::settle), published as the scan's last meshes.
  void settle_meshes();
  tracking::SyncedPose synchronise(const Frame& frame);
  void report(ScanState state, const std::string& message);
  void withdraw(int key);
  void stage_done();
  template <typename F>
  void each_sink(const char* what, F&& call);
  void offer_frame(const TrackedFrame& frame, const Eigen::Matrix4d& T_reference_image);
  void journal_added(const std::vector<const SliceItem*>& added);
  void publish_restored();

  ScanSource source_;
  std::unique_ptr<SegmentationStage> segmentation_;
  std::unique_ptr<ReconstructionStage> reconstruction_;
  ScanOptions options_;
  std::array<Vec2, 4> corners_px_;
  std::vector<std::shared_ptr<ScanSink>> sinks_;
  std::mutex sink_mutex_;

  tracking::PoseBuffer poses_;         // acquisition thread only
  bool pose_source_reported_ = false;  // acquisition thread only
  std::mutex selector_mutex_;
  tracking::KeyframeSelector selector_;

  // Queues of pointers: a move through a queue is a pointer copy, whatever a frame weighs.
  std::unique_ptr<BoundedQueue<std::unique_ptr<Candidate>>> to_segmentation_;
  std::unique_ptr<BoundedQueue<std::unique_ptr<SliceItem>>> to_reconstruction_;
  std::thread acquisition_thread_, segmentation_thread_, reconstruction_thread_;

  mutable std::mutex state_mutex_;  // guards everything below
  std::condition_variable done_cv_;
  ScanCounters counters_;
  recon::ReconstructionStats last_update_;
  std::vector<double> latencies_s_;
  std::vector<double> update_ms_;
  std::vector<std::string> errors_;
  RepairReport repairs_;
  std::optional<StopReason> stop_reason_;
  MeshSet meshes_;
  int stages_running_ = 0;
  bool started_ = false;
  bool acquiring_ = false;
  std::optional<ScanSummary> summary_;
  double start_s_ = 0.0;
  double end_s_ = 0.0;
  std::atomic<bool> stop_requested_{false};

  std::shared_ptr<KeyframeJournal> journal_;  // reconstruction thread once started
  bool journal_failing_ = false;              // reconstruction thread only
  std::size_t restored_ = 0;                  // slices restore() put in
};

}  // namespace sonoshape::scan
