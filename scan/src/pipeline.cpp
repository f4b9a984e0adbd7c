#include "sonoshape/scan/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <stdexcept>
#include <utility>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/heap.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::scan {

// A keyframe on its way to segmentation: the frame, when it arrived, and its selector key
// (withdrawn when the frame is dropped or fails, so a later frame can replace it).
struct ScanPipeline::Candidate {
  TrackedFrame frame;
  double received_s = 0.0;
  int key = 0;
  tracking::FramePlane plane;  // for the journal
};

// A segmented keyframe on its way to the reconstruction.
struct ScanPipeline::SliceItem {
  LabeledSlice slice;
  double received_s = 0.0;
  int key = 0;
  std::int64_t frame_index = 0;
  tracking::FramePlane plane;
};

namespace {

// Every material of `labels` without a mesh in `meshes`, with why: none of the slices holds it,
// or its regions were thinner than the octree's cells.
std::vector<std::string> labels_without_mesh(const std::vector<LabelInfo>& labels,
                                             const SliceSet& slices, const MeshSet& meshes) {
  std::vector<std::string> out;
  for (const LabelInfo& l : labels) {
    const bool meshed = std::any_of(meshes.meshes.begin(), meshes.meshes.end(), [&](const auto& e) {
      return e.label == l.id && !e.mesh.triangles.empty();
    });
    if (meshed) continue;
    std::size_t holding = 0;
    for (const LabeledSlice& slice : slices.slices)
      holding += std::any_of(slice.regions.begin(), slice.regions.end(),
                             [&](const Region& r) { return r.label == l.id; });
    out.push_back("label " + std::to_string(l.id) + " (" + l.name + "): no mesh: " +
                  (holding == 0 ? std::string("no slice holds it (the segmentation never gave "
                                              "it a region)")
                                : "its regions in " + std::to_string(holding) +
                                      " slices are thinner than the octree's cells (raise "
                                      "--depth)"));
  }
  return out;
}

// How long a stage waits on its input before it looks at its stop conditions again.
constexpr double kPollS = 0.05;

template <typename T>
std::string source_state(const acquisition::StreamSource<T>& s) {
  const std::string message = s.message();
  const std::string condition = s.condition();
  std::string lost;
  for (const auto& [reason, count] : s.losses())
    if (count > 0) lost += (lost.empty() ? "; lost " : ", ") + reason + " " + std::to_string(count);
  return std::string(acquisition::to_string(s.state())) + (message.empty() ? "" : ": " + message) +
         (condition.empty() ? "" : " (" + condition + ")") + lost;
}

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const std::size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid), values.end());
  double m = values[mid];
  if (values.size() % 2 == 0) {
    const double below =
        *std::max_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid));
    m = 0.5 * (m + below);
  }
  return m;
}

}  // namespace

ScanPipeline::ScanPipeline(ScanSource source, std::unique_ptr<SegmentationStage> segmentation,
                           std::unique_ptr<ReconstructionStage> reconstruction,
                           const ScanOptions& options)
    : source_(std::move(source)),
      segmentation_(std::move(segmentation)),
      reconstruction_(std::move(reconstruction)),
      options_(options),
      poses_(options.sync),
      selector_(options.keyframes) {
  if (!source_.frames || !source_.poses)
    throw std::invalid_argument("ScanPipeline: a frame source and a pose source are needed");
  if (!segmentation_ || !reconstruction_)
    throw std::invalid_argument(
        "ScanPipeline: a segmentation and a reconstruction stage are needed");
  if (options.frame_buffer == 0 || options.pose_buffer == 0 || options.segmentation_queue == 0 ||
      options.reconstruction_queue == 0)
    throw std::invalid_argument("ScanPipeline: buffer and queue sizes must be at least 1");
  if (!(options.pose_wait_s >= 0.0) || !(options.duration_s >= 0.0) || !(options.speed > 0.0))
    throw std::invalid_argument(
        "ScanPipeline: pose_wait_s and duration_s must be >= 0 and speed positive");
  corners_px_ = keyframe_corners(source_.setup);
  to_segmentation_ =
      std::make_unique<BoundedQueue<std::unique_ptr<Candidate>>>(options.segmentation_queue);
  to_reconstruction_ =
      std::make_unique<BoundedQueue<std::unique_ptr<SliceItem>>>(options.reconstruction_queue);
}

ScanPipeline::~ScanPipeline() {
  try {
    request_stop();
    finish();
  } catch (const std::exception& e) {
    log_warning(std::string("scan: finishing failed: ") + e.what());
  }
}

void ScanPipeline::add_sink(std::shared_ptr<ScanSink> sink) {
  if (!sink) return;
  std::lock_guard lock(sink_mutex_);
  sinks_.push_back(std::move(sink));
}

void ScanPipeline::set_journal(std::shared_ptr<KeyframeJournal> journal) {
  journal_ = std::move(journal);
}

Status ScanPipeline::restore(const std::vector<JournalKeyframe>& keyframes) {
  {
    std::lock_guard lock(state_mutex_);
    if (started_) return Status::error("scan: restore() after start()");
  }
  if (keyframes.empty()) return Status::ok();
  for (std::size_t i = 0; i < keyframes.size(); ++i) {
    try {
      reconstruction_->add_slice(keyframes[i].slice);
    } catch (const std::exception& e) {
      return Status::error("journalled keyframe " + std::to_string(i) + " (frame " +
                           std::to_string(keyframes[i].frame_index) +
                           ") was refused by the reconstruction: " + e.what());
    }
    // Accepted once against a superset of these planes, each is accepted again (and the slice
    // budget's coarser thresholds apply here only from as many planes on as when it was first).
    selector_.offer(keyframes[i].plane);
  }
  try {
    reconstruction_->update();
  } catch (const std::exception& e) {
    return Status::error(std::string("the reconstruction of the journalled keyframes failed: ") +
                         e.what());
  }
  restored_ = keyframes.size();
  meshes_ = reconstruction_->meshes();
  counters_.slices = reconstruction_->slice_count();
  counters_.last_slice_timestamp_s = keyframes.back().slice.timestamp_s.value_or(0.0);
  segmentation_->on_meshes(meshes_);
  return Status::ok();
}

// The restored slices and meshes to the sinks, as if they had just been reconstructed.
void ScanPipeline::publish_restored() {
  if (restored_ == 0) return;
  const SliceSet restored = reconstruction_->slice_set();
  each_sink("slice", [&](ScanSink& sink) {
    Status result;
    for (std::size_t k = 0; k < restored.slices.size() && result; ++k)
      result = sink.on_slice(restored.slices[k], k);
    return result;
  });
  MeshUpdateInfo info;
  info.slices = restored_;
  info.timestamp_s = counters().last_slice_timestamp_s;
  each_sink("meshes",
            [&](ScanSink& sink) { return sink.on_meshes(reconstruction_->meshes(), info); });
}

void ScanPipeline::journal_added(const std::vector<const SliceItem*>& added) {
  if (!journal_) return;
  std::vector<JournalKeyframe> keyframes;
  for (const SliceItem* item : added)
    keyframes.push_back({item->frame_index, item->plane, item->slice});
  const Status status = journal_->append(keyframes);
  if (!status && !journal_failing_) {
    journal_failing_ = true;
    report(ScanState::kError, status.message() + "; the scan goes on (said once)");
  } else if (status && journal_failing_) {
    journal_failing_ = false;
    report(ScanState::kScanning, "the journal " + journal_->path().string() +
                                     " is written again: every keyframe is on disk");
  }
}

Status ScanPipeline::start() {
  {
    std::lock_guard lock(state_mutex_);
    if (started_) return Status::error("scan: already started");
    start_s_ = acquisition::monotonic_s();
  }
  acquisition::SourceOptions frame_options;
  frame_options.buffer_capacity = options_.frame_buffer;
  frame_options.wait_when_full = !options_.drop_when_behind;
  frame_options.playback.real_time = options_.real_time;
  frame_options.playback.speed = options_.speed;
  frame_options.playback.device_origin_s = source_.device_origin_s;
  // One origin for both streams keeps frames and tracker samples aligned in playback.
  frame_options.playback.monotonic_origin_s = start_s_;
  acquisition::SourceOptions pose_options = frame_options;
  pose_options.buffer_capacity = options_.pose_buffer;
  if (Status started = source_.frames->start(frame_options); !started) return started;
  if (Status started = source_.poses->start(pose_options); !started) {
    source_.frames->stop();
    return started;
  }
  {
    std::lock_guard lock(state_mutex_);
    started_ = true;
    acquiring_ = true;
    stages_running_ = 3;
  }
  reconstruction_thread_ = std::thread([this] { reconstruction_loop(); });
  segmentation_thread_ = std::thread([this] { segmentation_loop(); });
  acquisition_thread_ = std::thread([this] { acquisition_loop(); });
  return Status::ok();
}

void ScanPipeline::request_stop() { stop_requested_.store(true); }

bool ScanPipeline::wait_for(double timeout_s) {
  std::unique_lock lock(state_mutex_);
  return done_cv_.wait_for(lock, std::chrono::duration<double>(std::max(0.0, timeout_s)),
                           [&] { return started_ && stages_running_ == 0; });
}

ScanCounters ScanPipeline::counters() const {
  std::lock_guard lock(state_mutex_);
  return counters_;
}

MeshSet ScanPipeline::meshes() const {
  std::lock_guard lock(state_mutex_);
  return meshes_;
}

template <typename F>
void ScanPipeline::each_sink(const char* what, F&& call) {
  std::lock_guard lock(sink_mutex_);
  for (const auto& sink : sinks_) {
    try {
      if (const Status status = call(*sink); !status)
        log_warning(std::string("scan output (") + what + "): " + status.message());
    } catch (const std::exception& e) {
      // A broken output must not take the scan down with it.
      log_warning(std::string("scan output (") + what + ") threw: " + e.what());
    }
  }
}

void ScanPipeline::offer_frame(const TrackedFrame& frame,
                               const Eigen::Matrix4d& T_reference_image) {
  // Live views (OpenIGTLink's IMAGE) show every posed frame, not only the keyframes. The
  // acquisition thread never waits for a sink: while another thread is in one (writing meshes),
  // this frame is not shown.
  std::unique_lock lock(sink_mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  for (const auto& sink : sinks_) {
    try {
      if (const Status status = sink->on_frame(frame, T_reference_image); !status)
        log_warning("scan output (frame): " + status.message());
    } catch (const std::exception& e) {
      log_warning(std::string("scan output (frame) threw: ") + e.what());
    }
  }
}

void ScanPipeline::report(ScanState state, const std::string& message) {
  ScanStatus status;
  {
    std::lock_guard lock(state_mutex_);
    if (state == ScanState::kError) errors_.push_back(message);
    status.state = state;
    status.message = message;
    status.counters = counters_;
    status.last_update = last_update_;
  }
  if (state == ScanState::kError)
    log_warning("scan: " + message);
  else
    log_info("scan: " + message);
  each_sink("status", [&](ScanSink& sink) { return sink.on_status(status); });
}

void ScanPipeline::withdraw(int key) {
  std::lock_guard lock(selector_mutex_);
  selector_.withdraw(key);
}

void ScanPipeline::stage_done() {
  std::lock_guard lock(state_mutex_);
  if (--stages_running_ == 0) {
    end_s_ = acquisition::monotonic_s();
    done_cv_.notify_all();
  }
}

tracking::SyncedPose ScanPipeline::synchronise(const Frame& frame) {
  report_pose_source_trouble();
  const double t = frame.timestamp_s;
  const double deadline_s = acquisition::monotonic_s() + options_.pose_wait_s;
  // Interpolation needs the tracker sample after the frame's time: wait for it, a little.
  while (poses_.latest_frame_time_s() < t) {
    if (source_.poses->finished()) {
      if (!pose_source_reported_ && source_.poses->state() == acquisition::SourceState::kFailed) {
        pose_source_reported_ = true;
        report(ScanState::kError,
               "pose source " + source_.poses->describe() + " failed (" + source_.poses->message() +
                   "); frames get no pose from now on and are dropped; the meshes so far are kept");
      }
      break;
    }
    if (stop_requested_.load()) break;
    const double remaining_s = deadline_s - acquisition::monotonic_s();
    if (remaining_s <= 0.0) break;
    if (auto sample = source_.poses->next(std::min(remaining_s, kPollS))) poses_.add(sample->item);
    report_pose_source_trouble();
  }
  tracking::SyncedPose synced = poses_.pose_at(t);
  poses_.discard_before(t);
  return synced;
}

// A live source riding out trouble (a grabber or tracker unplugged and being reopened) stays
// running: the sinks hear once when the trouble starts and once when it is over; the meshes
// are kept meanwhile.
void ScanPipeline::report_frame_source_trouble() {
  report_condition_changes(source_.frames->take_condition_changes(),
                           "frame source " + source_.frames->describe(), "the scan goes on", "");
}

void ScanPipeline::report_pose_source_trouble() {
  report_condition_changes(source_.poses->take_condition_changes(),
                           "pose source " + source_.poses->describe(), "frames get poses again",
                           "frames get no pose meanwhile and are dropped");
}

void ScanPipeline::report_condition_changes(const std::vector<std::string>& changes,
                                            const std::string& name, const std::string& when_back,
                                            const std::string& meanwhile) {
  for (const std::string& condition : changes) {
    if (condition.empty())
      report(ScanState::kScanning, name + " is back; " + when_back);
    else
      report(ScanState::kError, name + ": " + condition + (meanwhile.empty() ? "" : "; ") +
                                    meanwhile + "; the meshes so far are kept");
  }
}

std::optional<StopReason> ScanPipeline::stop_before_next_frame() {
  if (stop_requested_.load()) return StopReason::kStopRequested;
  if (options_.duration_s > 0.0 && acquisition::monotonic_s() - start_s_ >= options_.duration_s)
    return StopReason::kDuration;
  if (options_.max_slices > 0) {
    std::lock_guard lock(selector_mutex_);
    if (selector_.accepted() >= options_.max_slices) return StopReason::kMaxSlices;
  }
  return std::nullopt;
}

void ScanPipeline::count_sync_failure(tracking::SyncFailure failure) {
  std::lock_guard lock(state_mutex_);
  DropCounts& d = counters_.dropped;
  switch (failure) {
    case tracking::SyncFailure::kMissing:
      ++d.pose_missing;
      break;
    case tracking::SyncFailure::kInvalid:
      ++d.pose_invalid;
      break;
    case tracking::SyncFailure::kGap:
      ++d.pose_gap;
      break;
    case tracking::SyncFailure::kExtrapolation:
    case tracking::SyncFailure::kNone:
      ++d.pose_extrapolation;
      break;
  }
}

bool ScanPipeline::choose_keyframe(Candidate& candidate, const Eigen::Matrix4d& T_reference_image,
                                   bool& degenerate_reported) {
  tracking::FramePlane plane;
  try {
    plane = tracking::frame_plane(T_reference_image, corners_px_);
  } catch (const GeometryError& e) {
    {
      std::lock_guard lock(state_mutex_);
      ++counters_.dropped.segmentation_failed;
    }
    if (!degenerate_reported) {
      degenerate_reported = true;
      report(ScanState::kError,
             std::string("degenerate image plane (check the calibration): ") + e.what());
    }
    return false;
  }
  std::optional<int> key;
  {
    std::lock_guard lock(selector_mutex_);
    key = selector_.offer(plane);
  }
  if (!key) {
    std::lock_guard lock(state_mutex_);
    ++counters_.keyframes_skipped;
    return false;
  }
  candidate.key = *key;
  candidate.plane = plane;
  return true;
}

void ScanPipeline::queue_for_segmentation(std::unique_ptr<Candidate> candidate) {
  const int key = candidate->key;
  if (options_.drop_when_behind) {
    std::optional<std::unique_ptr<Candidate>> evicted;
    if (!to_segmentation_->push_drop_oldest(std::move(candidate), &evicted)) {
      withdraw(key);
    } else if (evicted) {
      withdraw((*evicted)->key);
      std::lock_guard lock(state_mutex_);
      ++counters_.dropped.segmentation_behind;
    }
  } else if (!to_segmentation_->push_wait(std::move(candidate))) {
    withdraw(key);
  }
}

StopReason ScanPipeline::acquire_frames() {
  bool degenerate_reported = false;
  while (true) {
    if (const std::optional<StopReason> stop = stop_before_next_frame()) return *stop;
    auto received = source_.frames->next(kPollS);
    report_frame_source_trouble();
    if (!received) {
      if (source_.frames->finished())
        return source_.frames->state() == acquisition::SourceState::kFailed
                   ? StopReason::kSourceFailed
                   : StopReason::kSourceEnded;
      continue;
    }
    {
      std::lock_guard lock(state_mutex_);
      ++counters_.frames_received;
      counters_.dropped.source = source_.frames->dropped();
    }
    const tracking::SyncedPose synced = synchronise(received->item);
    if (!synced.ok()) {
      count_sync_failure(synced.failure);
      continue;
    }
    auto candidate = std::make_unique<Candidate>(
        Candidate{TrackedFrame{std::move(received->item), synced.pose.T_reference_probe,
                               TrackingStatus::kValid},
                  received->received_s,
                  0,
                  {}});
    const Eigen::Matrix4d T_reference_image =
        candidate->frame.T_reference_probe.matrix() * source_.setup.T_probe_image;
    offer_frame(candidate->frame, T_reference_image);
    // Keyframe choice before segmentation: near-duplicates cost nothing downstream.
    if (!choose_keyframe(*candidate, T_reference_image, degenerate_reported)) continue;
    queue_for_segmentation(std::move(candidate));
  }
}

void ScanPipeline::acquisition_loop() {
  StopReason reason = StopReason::kSourceEnded;
  try {
    reason = acquire_frames();
  } catch (const std::exception& e) {
    // Nothing may escape a thread: report, and end acquisition as a failed source would.
    reason = StopReason::kSourceFailed;
    report(ScanState::kError, std::string("acquisition failed: ") + e.what());
  }
  source_.frames->stop();
  source_.poses->stop();
  // Trouble (or its end) after the last frame is still the scan's to report.
  report_frame_source_trouble();
  report_pose_source_trouble();
  std::size_t slices = 0;
  {
    std::lock_guard lock(state_mutex_);
    counters_.dropped.source = source_.frames->dropped();
    if (!stop_reason_) stop_reason_ = reason;
    acquiring_ = false;
    slices = counters_.slices;
  }
  to_segmentation_->close();
  if (reason == StopReason::kSourceFailed &&
      source_.frames->state() == acquisition::SourceState::kFailed) {
    report(ScanState::kError, "frame source " + source_.frames->describe() + " failed (" +
                                  source_.frames->message() + "); the scan goes on with the " +
                                  std::to_string(slices) +
                                  " slices it has and the frames already queued");
  } else {
    // Still "scanning": idle promises final meshes, and the queued frames are not in yet.
    report(ScanState::kScanning, std::string("acquisition over (") + to_string(reason) +
                                     "); finishing the queued frames");
  }
  stage_done();
}

void ScanPipeline::segmentation_loop() {
  try {
    while (true) {
      auto popped = to_segmentation_->pop(kPollS);
      if (!popped) {
        if (to_segmentation_->drained()) break;
        continue;
      }
      const std::unique_ptr<Candidate> candidate = std::move(*popped);
      const auto segmented = [&]() -> Result<LabeledSlice> {
        try {
          return segmentation_->segment(candidate->frame);
        } catch (const std::exception& e) {
          return Status::error(std::string("segmentation threw: ") + e.what());
        }
      }();
      if (const std::vector<Repair> repairs = segmentation_->take_repairs(); !repairs.empty()) {
        const std::size_t index = candidate->frame.frame.index;
        std::string text;
        for (const Repair& r : repairs)
          text += (text.empty() ? "" : "; ") + r.kind + " (" + r.where + "): " + r.detail;
        log_warning("scan: frame " + std::to_string(index) + ": " + text);
        std::lock_guard lock(state_mutex_);
        for (const Repair& r : repairs) repairs_.add(index, r);
      }
      if (!segmented) {
        withdraw(candidate->key);
        {
          std::lock_guard lock(state_mutex_);
          ++counters_.dropped.segmentation_failed;
        }
        log_debug("scan: frame " + std::to_string(candidate->frame.frame.index) +
                  " gave no slice: " + segmented.message());
        continue;
      }
      auto item =
          std::make_unique<SliceItem>(SliceItem{*segmented, candidate->received_s, candidate->key,
                                                candidate->frame.frame.index, candidate->plane});
      const int key = item->key;
      if (options_.drop_when_behind) {
        std::optional<std::unique_ptr<SliceItem>> evicted;
        if (!to_reconstruction_->push_drop_oldest(std::move(item), &evicted)) {
          withdraw(key);
        } else if (evicted) {
          withdraw((*evicted)->key);
          std::lock_guard lock(state_mutex_);
          ++counters_.dropped.reconstruction_behind;
        }
      } else if (!to_reconstruction_->push_wait(std::move(item))) {
        withdraw(key);
      }
    }
  } catch (const std::exception& e) {
    report(ScanState::kError, std::string("segmentation stage failed: ") + e.what());
  }
  // Close even after a failure: the reconstruction must not wait forever.
  to_segmentation_->close();
  to_reconstruction_->close();
  stage_done();
}

std::vector<const ScanPipeline::SliceItem*> ScanPipeline::add_batch(
    const std::vector<std::unique_ptr<SliceItem>>& batch) {
  std::vector<const SliceItem*> added;
  for (const auto& item : batch) {
    try {
      reconstruction_->add_slice(item->slice);
      added.push_back(item.get());
    } catch (const std::exception& e) {
      withdraw(item->key);
      {
        std::lock_guard lock(state_mutex_);
        ++counters_.dropped.reconstruction_rejected;
      }
      log_warning("scan: the slice of frame " + std::to_string(item->frame_index) +
                  " was refused by the reconstruction: " + e.what());
    }
  }
  return added;
}

std::optional<recon::UpdateStats> ScanPipeline::update_with(
    const std::vector<const SliceItem*>& added) {
  try {
    return reconstruction_->update();
  } catch (const std::exception& e) {
    for (const SliceItem* item : added) withdraw(item->key);
    {
      std::lock_guard lock(state_mutex_);
      counters_.dropped.reconstruction_rejected += added.size();
    }
    report(ScanState::kError, "reconstruction update failed (" + std::string(e.what()) + "); its " +
                                  std::to_string(added.size()) +
                                  " new slices were dropped and the meshes so far kept");
    return std::nullopt;
  }
}

void ScanPipeline::log_update(const recon::UpdateStats& stats, std::size_t added,
                              double seconds) const {
  if (log_level() < LogLevel::kDebug) return;
  const recon::ReconstructionStats& st = stats.step;
  log_debug("scan: update +" + std::to_string(added) + " slices -> " +
            std::to_string(reconstruction_->slice_count()) + " in " + std::to_string(seconds) +
            " s" + (stats.full_rebuild ? " (full rebuild)" : "") + ": cells " +
            std::to_string(st.cells) + ", changed " + std::to_string(stats.cells_changed) +
            "; arrangement " + std::to_string(st.arrangement_s) + " s, face images " +
            std::to_string(st.face_images_s) + " s (completion " + std::to_string(st.completion_s) +
            " s), field " + std::to_string(st.field_s) + " s, smoothing " +
            std::to_string(st.smoothing_s) + " s, mesh " + std::to_string(st.mesh_s) + " s" +
            (st.solve_nodes > 0
                 ? "; thin-plate data " + std::to_string(st.data_s) + " s, solve " +
                       std::to_string(st.solve_s) + " s (" + std::to_string(st.solve_iterations) +
                       " iterations, " + std::to_string(st.solve_nodes) + " nodes)"
                 : std::string()));
}

void ScanPipeline::publish_update(const std::vector<const SliceItem*>& added,
                                  const recon::UpdateStats& stats, double update_start_s,
                                  double ready_s, std::size_t first_slice_index) {
  MeshUpdateInfo info;
  ScanStatus status;
  {
    std::lock_guard lock(state_mutex_);
    ScanCounters& c = counters_;
    c.slices = reconstruction_->slice_count();
    ++c.updates;
    c.last_update_ms = 1e3 * (ready_s - update_start_s);
    for (const SliceItem* item : added) latencies_s_.push_back(ready_s - item->received_s);
    c.last_latency_s = ready_s - added.back()->received_s;
    c.last_slice_timestamp_s = added.back()->slice.timestamp_s.value_or(0.0);
    update_ms_.push_back(c.last_update_ms);
    last_update_ = stats.step;
    meshes_ = reconstruction_->meshes();
    segmentation_->on_meshes(meshes_);  // the next frames' prior (graph-cut method)
    info.slices = c.slices;
    info.timestamp_s = c.last_slice_timestamp_s;
    info.stats = stats.step;
    info.update_ms = c.last_update_ms;
    // Idle (final meshes) is reported once, by finish(), after the last update.
    status.state = ScanState::kScanning;
    status.counters = c;
    status.last_update = last_update_;
  }
  each_sink("slice", [&](ScanSink& sink) {
    Status result;
    for (std::size_t k = 0; k < added.size() && result; ++k)
      result = sink.on_slice(added[k]->slice, first_slice_index + k);
    return result;
  });
  each_sink("meshes",
            [&](ScanSink& sink) { return sink.on_meshes(reconstruction_->meshes(), info); });
  each_sink("status", [&](ScanSink& sink) { return sink.on_status(status); });
}

void ScanPipeline::settle_meshes() {
  const double start_s = acquisition::monotonic_s();
  std::optional<recon::UpdateStats> stats;
  try {
    stats = reconstruction_->settle();
  } catch (const std::exception& e) {
    log_warning("scan: solving the final meshes from all the slices at once failed (" +
                std::string(e.what()) + "); the last update's meshes are kept");
    return;
  }
  if (!stats) return;
  const double seconds = acquisition::monotonic_s() - start_s;
  log_info("scan: final meshes solved from all " + std::to_string(reconstruction_->slice_count()) +
           " slices at once in " + std::to_string(seconds) +
           " s (the online updates agree with them to the solver's "
           "tolerance)");
  MeshUpdateInfo info;
  {
    std::lock_guard lock(state_mutex_);
    meshes_ = reconstruction_->meshes();
    info.slices = counters_.slices;
    info.timestamp_s = counters_.last_slice_timestamp_s;
    info.stats = stats->step;
    info.update_ms = 1e3 * seconds;
  }
  each_sink("meshes",
            [&](ScanSink& sink) { return sink.on_meshes(reconstruction_->meshes(), info); });
}

void ScanPipeline::reconstruction_loop() {
  std::size_t slice_index = restored_;
  try {
    publish_restored();
    while (true) {
      auto first = to_reconstruction_->pop(kPollS);
      if (!first) {
        if (to_reconstruction_->drained()) break;
        continue;
      }
      // Everything queued goes into one update: a slow update batches slices, it loses none.
      std::vector<std::unique_ptr<SliceItem>> batch;
      batch.push_back(std::move(*first));
      for (auto& item : to_reconstruction_->pop_all()) batch.push_back(std::move(item));
      const std::vector<const SliceItem*> added = add_batch(batch);
      if (added.empty()) continue;
      const double update_start_s = acquisition::monotonic_s();
      const std::optional<recon::UpdateStats> stats = update_with(added);
      if (!stats) continue;
      const double ready_s = acquisition::monotonic_s();
      // On disk before anyone hears of it: what a subscriber saw, a resume restores.
      journal_added(added);
      log_update(*stats, added.size(), ready_s - update_start_s);
      publish_update(added, *stats, update_start_s, ready_s, slice_index);
      slice_index += added.size();
      // An update frees most of what it allocated (the new cells' face images, the octree's
      // levels, the mesher's buffers): without this the scan's RSS followed the largest update
      // so far (the soak's RSS rose in steps at single updates).
      release_free_heap();
    }
    settle_meshes();
  } catch (const std::exception& e) {
    report(ScanState::kError, std::string("reconstruction stage failed: ") + e.what());
    // Let the upstream stages finish instead of waiting on a full queue forever.
    to_reconstruction_->close();
    while (to_reconstruction_->try_pop()) {
    }
  }
  stage_done();
}

ScanSummary ScanPipeline::finish() {
  {
    std::lock_guard lock(state_mutex_);
    if (summary_) return *summary_;
    if (!started_) {
      summary_ = ScanSummary{};
      summary_->stop_reason = StopReason::kStopRequested;
      return *summary_;
    }
  }
  for (std::thread* t : {&acquisition_thread_, &segmentation_thread_, &reconstruction_thread_})
    if (t->joinable()) t->join();

  ScanSummary summary;
  {
    std::lock_guard lock(state_mutex_);
    summary.counters = counters_;
    summary.stop_reason = stop_reason_.value_or(StopReason::kSourceEnded);
    summary.errors = errors_;
    summary.frame_source_losses = source_.frames->losses();
    summary.latency = latency_stats(latencies_s_);
    summary.update_ms_median = median(update_ms_);
    summary.update_ms_p95 = latency_stats(update_ms_).p95_s;  // the same nearest rank, in ms
    summary.update_ms_max =
        update_ms_.empty() ? 0.0 : *std::max_element(update_ms_.begin(), update_ms_.end());
    summary.duration_s = end_s_ - start_s_;
    summary.repairs = repairs_;
    summary.segmentation_scores = segmentation_->scores();
    summary.label_names[0] = "background";
    for (const LabelInfo& l : source_.setup.labels) summary.label_names[l.id] = l.name;
  }
  summary.frame_source = source_.frames->describe() + ": " + source_state(*source_.frames);
  summary.pose_source = source_.poses->describe() + ": " + source_state(*source_.poses);
  report(ScanState::kIdle, "scan finished (" + std::string(to_string(summary.stop_reason)) +
                               "): " + std::to_string(summary.counters.slices) + " slices");
  const SliceSet slices = reconstruction_->slice_set();
  const MeshSet& meshes = reconstruction_->meshes();
  summary.labels_without_mesh = labels_without_mesh(source_.setup.labels, slices, meshes);
  each_sink("finish", [&](ScanSink& sink) {
    const Status finished = sink.on_finish(meshes, slices, summary);
    if (!finished) summary.incomplete_outputs.push_back(finished.message());
    return finished;
  });
  if (journal_ && !journal_->finish(slices.slices.size())) {
    const std::string held = "the journal " + journal_->path().string() + " holds " +
                             std::to_string(journal_->written()) + " of the " +
                             std::to_string(slices.slices.size()) + " keyframes and no end record";
    log_warning("scan: " + held + " (see above): --resume on this directory goes on after them");
    summary.incomplete_outputs.push_back(held);
  }
  std::lock_guard lock(state_mutex_);
  summary_ = summary;
  return summary;
}

}  // namespace sonoshape::scan
