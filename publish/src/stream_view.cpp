// StreamView: a MeshSubscriber thread that hands the stream's messages, as received, to a
// ViewServer.
#include "sonoshape/publish/stream_view.hpp"

#include <algorithm>
#include <atomic>
#include <mutex>
#include <thread>

#include "sonoshape/core/log.hpp"

namespace sonoshape::publish {
namespace {

// How long one receive waits before looking at the stop flag again.
constexpr std::chrono::milliseconds kPollInterval{200};
// The longest a connect waits for a snapshot: bounds how long stopping can take.
constexpr int kMaxSnapshotWaitMs = 2000;
// After this long without a message, the view takes a fresh snapshot if the stream went on past
// its last refresh: the PUB socket drops what a slow reader cannot take (its high-water mark),
// and the end of a burst (the last meshes and the final status of a scan) has no later
// message whose seq would show the gap.
constexpr std::chrono::milliseconds kQuietRefresh{1000};
// The least time between two fresh snapshots taken for a gap in the seqs: a reader that keeps
// falling behind does not ask for one after every message.
constexpr std::chrono::milliseconds kGapRefreshInterval{1000};

}  // namespace

struct StreamView::Impl {
  explicit Impl(const StreamViewOptions& view_options, ViewServer view_server)
      : options(view_options), server(std::move(view_server)) {}

  StreamViewOptions options;
  ViewServer server;
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> relayed{0};
  // The scan followed, the highest seq seen of it, and the seq up to which a refresh (a fresh
  // snapshot after a quiet spell) has been taken: at most one refresh per stretch of messages.
  std::string followed_scan;
  std::uint64_t highest_seq = 0;
  std::uint64_t refreshed_up_to = 0;
  std::chrono::steady_clock::time_point last_gap_refresh{};
  // The scans whose last status ("finished") the relay has passed on, and what it said: a
  // publisher gone after it ended normally, not lost.
  mutable std::mutex finished_mutex;
  std::string finished_scan;
  std::string finished_summary;
  std::thread thread;  // declared last: started once the members above exist

  void sleep_unless_stopped(std::chrono::milliseconds duration) {
    const auto until = std::chrono::steady_clock::now() + duration;
    while (!stop && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::min(duration, std::chrono::milliseconds(50)));
  }

  // A scan's last status: said once per scan.
  void note_finished(const std::string& scan, const StatusReport& status) {
    const std::string summary = std::to_string(status.slices) + " slices, " +
                                std::to_string(status.frames_received) + " frames in (" +
                                std::to_string(status.frames_dropped) + " dropped)";
    {
      const std::lock_guard lock(finished_mutex);
      if (finished_scan == scan) return;
      finished_scan = scan;
      finished_summary = summary;
    }
    log_info("view: scan " + scan + " finished: " + summary +
             "; the page keeps showing its result");
  }

  // No publisher answers: after the end of the scan followed that is its normal end (the scan
  // exited), said as such; otherwise a problem, and the view keeps trying.
  void say_unreachable(const std::string& endpoint, const std::string& problem) {
    std::string summary;
    {
      const std::lock_guard lock(finished_mutex);
      if (!finished_scan.empty() && finished_scan == followed_scan) summary = finished_summary;
    }
    const std::string retry = " (trying again every " + std::to_string(options.retry_ms) + " ms)";
    if (summary.empty()) {
      log_warning("view: " + problem + retry);
      server.post_stream_state(StreamState::kWaiting, endpoint, problem);
      return;
    }
    const std::string ended = "scan " + followed_scan + " finished (" + summary +
                              ") and its publisher has closed; the page keeps its result";
    log_info("view: " + ended + "; a new scan at " + endpoint + " will be shown" + retry);
    server.post_stream_state(StreamState::kFinished, endpoint, ended);
  }

  void run() {
    SubscriberOptions stream = options.stream;
    // Every topic, slices included: seqs then run without gaps, so a scan that started while
    // the view was away shows (its first message seen is not seq 1).
    stream.topics.clear();
    stream.snapshot_timeout_ms = std::min(stream.snapshot_timeout_ms, kMaxSnapshotWaitMs);
    std::string last_problem;
    bool following = false;
    while (!stop) {
      Result<MeshSubscriber> subscriber = MeshSubscriber::connect(stream);
      if (!subscriber) {
        if (subscriber.message() != last_problem) {
          last_problem = subscriber.message();
          say_unreachable(stream.endpoint, last_problem);
        }
        sleep_unless_stopped(std::chrono::milliseconds(options.retry_ms));
        continue;
      }
      // Said once per connection (a refresh after a quiet spell joins again without a word).
      if (!following || !last_problem.empty()) {
        log_info("view: following the mesh stream at " + stream.endpoint);
        server.post_stream_state(StreamState::kConnected, stream.endpoint, "");
      }
      following = true;
      last_problem.clear();
      relay(*subscriber, !stream.snapshot_endpoint.empty());
    }
  }

  // Relays until stopped, or until a fresh snapshot is called for (returns then, and run()
  // joins again): a scan that began while the view was away, or a quiet spell after messages
  // the view may have lost (kQuietRefresh).
  void relay(MeshSubscriber& subscriber, bool can_rejoin) {
    std::string scan;
    auto quiet = std::chrono::milliseconds(0);
    // Live: past the snapshot's end (whose messages come with old, scattered seqs).
    bool live = !can_rejoin;
    while (!stop) {
      auto received = subscriber.receive(kPollInterval);
      if (!received) {
        log_warning("view: skipped an invalid message: " + received.message());
        continue;
      }
      if (!*received) {
        quiet += kPollInterval;
        // The scan's publisher closed (its process ended): run() says whether that was the end
        // of a finished scan or a lost one, and waits for the next.
        if (subscriber.publisher_gone()) return;
        if (can_rejoin && quiet >= kQuietRefresh && highest_seq > refreshed_up_to) {
          refreshed_up_to = highest_seq;
          return;  // run() joins again: the snapshot holds the newest meshes and status
        }
        continue;
      }
      quiet = std::chrono::milliseconds(0);
      const StreamMessage& message = **received;
      if (message.scan != followed_scan) {
        followed_scan = message.scan;
        highest_seq = refreshed_up_to = 0;
      }
      // The publisher dropped messages for this reader (its high-water mark, when the relay falls
      // behind). A lost mesh is replaced by the next one, but a lost slice only comes back with
      // a snapshot, and the page draws every slice: join again now (after this message).
      const bool gap = live && highest_seq > 0 && message.seq > highest_seq + 1;
      highest_seq = std::max(highest_seq, message.seq);
      if (message.scan != scan) {
        if (!scan.empty() && message.seq > 1 && can_rejoin) {
          log_info("view: scan " + message.scan + " began while away; joining it afresh");
          return;
        }
        if (!scan.empty()) log_info("view: new scan " + message.scan);
        scan = message.scan;
      }
      // The page draws surfaces, slices, frames and status; the snapshot's end stays here.
      if (std::holds_alternative<SnapshotEnd>(message.body)) {
        live = true;
        continue;
      }
      ++relayed;  // first: a page that has the message sees it counted
      server.post(subscriber.last_frames());
      if (const auto* status = std::get_if<StatusReport>(&message.body); status && status->finished)
        note_finished(message.scan, *status);
      const auto now = std::chrono::steady_clock::now();
      if (gap && can_rejoin && now - last_gap_refresh >= kGapRefreshInterval) {
        last_gap_refresh = now;
        refreshed_up_to = highest_seq;
        log_debug("view: messages lost before seq " + std::to_string(message.seq) +
                  "; joining again for the slices among them");
        return;
      }
    }
  }
};

StreamView::StreamView(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
StreamView::StreamView(StreamView&&) noexcept = default;
StreamView& StreamView::operator=(StreamView&&) noexcept = default;

StreamView::~StreamView() {
  if (!impl_) return;
  impl_->stop = true;
  if (impl_->thread.joinable()) impl_->thread.join();
}

Result<StreamView> StreamView::start(const StreamViewOptions& options) {
  Result<ViewServer> server = ViewServer::start(options.server);
  if (!server) return server.status();
  auto impl = std::make_unique<Impl>(options, std::move(*server));
  impl->server.post_stream_state(StreamState::kWaiting, options.stream.endpoint, "connecting");
  Impl* raw = impl.get();
  impl->thread = std::thread([raw] { raw->run(); });
  return StreamView(std::move(impl));
}

bool StreamView::drain(const std::string& scan, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    {
      const std::lock_guard lock(impl_->finished_mutex);
      if (impl_->finished_scan == scan) break;
    }
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      deadline - std::chrono::steady_clock::now());
  return impl_->server.flush(std::max(left, std::chrono::milliseconds(0)));
}

std::string StreamView::url() const { return impl_->server.url(); }

const ViewServer& StreamView::server() const { return impl_->server; }

std::uint64_t StreamView::messages_relayed() const { return impl_->relayed.load(); }

}  // namespace sonoshape::publish
