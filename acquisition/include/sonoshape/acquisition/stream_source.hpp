#pragma once
// The base of every device source (design.md, "Devices"): FrameSource (images) and
// tracking::PoseSource (tracker samples). The base class owns the thread, the receive
// timestamps, the buffer and the playback clock; a backend implements open / poll / close only.
// A backend that fails or ends says so through state() and message(): nothing it throws
// crosses the thread (exceptions become a kFailed state with their message).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>

#include "sonoshape/core/bounded_queue.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acq {

/// Seconds on the monotonic clock (std::chrono::steady_clock, arbitrary epoch): the clock of
/// receive times and of every latency sonoshape measures.
inline double monotonic_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Where a source is in its life.
enum class SourceState {
  kIdle,     ///< not started
  kRunning,  ///< open and delivering
  kEnded,    ///< the stream ended normally (end of file, simulation over, stop())
  kFailed,   ///< the backend failed (device vanished, corrupt file): see message()
};

/// "idle", "running", "ended", "failed".
inline const char* to_string(SourceState state) {
  switch (state) {
    case SourceState::kIdle:
      return "idle";
    case SourceState::kRunning:
      return "running";
    case SourceState::kEnded:
      return "ended";
    case SourceState::kFailed:
      return "failed";
  }
  return "unknown";
}

/// How recorded and simulated backends (is_playback()) deliver their items. Live devices
/// deliver as the device does and ignore this.
struct Playback {
  /// true: an item stamped t (device clock) is delivered at monotonic_origin_s +
  /// (t - device_origin_s) / speed; false: as fast as the consumer takes them.
  bool real_time = false;
  double speed = 1.0;            ///< real-time factor (2: twice as fast); must be positive
  double device_origin_s = 0.0;  ///< the device time that plays at monotonic_origin_s
  /// The monotonic time (monotonic_s()) playback starts; 0: when start() is called. Give the
  /// frame and pose sources of one scan the same origins so their streams stay aligned.
  double monotonic_origin_s = 0.0;
};

/// How a source buffers its items for the consumer.
struct SourceOptions {
  std::size_t buffer_capacity = 64;  ///< items held for the consumer (at least 1)
  /// true: the source waits while its buffer is full (recorded data played fast: nothing is
  /// lost, the consumer sets the pace); false: the oldest item is dropped and counted (live).
  bool wait_when_full = false;
  Playback playback;
};

/// An item with the monotonic time (s) the source delivered it: the capture time latencies
/// are measured from (the best estimate without a synchronised device clock).
template <typename T>
struct Received {
  T item;
  double received_s = 0.0;
};

/// What one poll() produced.
enum class Polled {
  kItem,     ///< `item` was filled
  kNothing,  ///< nothing yet; poll again (the backend should block a little, not spin)
  kEnd,      ///< the stream is over
};

/// A stream of T from a device, a file or a simulation, delivered by a thread of its own.
/// Thread-safe: the consumer calls next() from any one thread while the source runs.
/// Backends must call stop() in their destructor (the thread calls their poll()).
template <typename T>
class StreamSource {
 public:
  StreamSource() = default;
  StreamSource(const StreamSource&) = delete;
  StreamSource& operator=(const StreamSource&) = delete;
  virtual ~StreamSource() { stop(); }

  /// What the source reads, as the user named it (e.g. "replay:sweep.igs.mha").
  virtual std::string describe() const = 0;

  /// Starts the thread: open(), then poll() until the stream ends, fails, or stop() is called.
  /// Fails when already started or when the options are invalid (zero capacity, speed <= 0);
  /// a failing open() is reported through state() like any later failure.
  Status start(const SourceOptions& options = {}) {
    if (state_.load() != SourceState::kIdle || thread_.joinable())
      return Status::error(describe() + ": already started");
    if (options.buffer_capacity == 0 || !(options.playback.speed > 0.0))
      return Status::error(describe() +
                           ": invalid source options (buffer capacity must be >= 1 and the "
                           "playback speed positive)");
    options_ = options;
    if (options_.playback.monotonic_origin_s == 0.0)
      options_.playback.monotonic_origin_s = monotonic_s();
    buffer_ = std::make_unique<BoundedQueue<Received<T>>>(options.buffer_capacity);
    state_.store(SourceState::kRunning);
    thread_ = std::thread([this] { run(); });
    return Status::ok();
  }

  /// Asks the thread to finish, waits for it, and closes the backend. Items already buffered
  /// can still be taken with next(). Idempotent.
  void stop() {
    stop_requested_.store(true);
    if (buffer_) buffer_->close();  // wakes a thread waiting for room
    if (thread_.joinable()) thread_.join();
  }

  /// The next item, waiting up to `timeout_s` seconds. None on timeout, or at once when the
  /// source has finished and its buffer is empty (then finished() is true).
  std::optional<Received<T>> next(double timeout_s) {
    if (!buffer_) return std::nullopt;
    return buffer_->pop(timeout_s);
  }

  /// Ended or failed, and every buffered item taken: nothing more will come.
  bool finished() const {
    const SourceState s = state_.load();
    return (s == SourceState::kEnded || s == SourceState::kFailed) &&
           (!buffer_ || buffer_->size() == 0);
  }
  /// The current state (kEnded or kFailed may still have buffered items).
  SourceState state() const { return state_.load(); }
  /// Why the source ended or failed (empty while it runs).
  std::string message() const {
    std::lock_guard lock(message_mutex_);
    return message_;
  }
  /// Trouble a running source is riding out (e.g. "device unplugged; reopening it"); empty
  /// when all is well. Thread-safe.
  std::string condition() const {
    std::lock_guard lock(message_mutex_);
    return condition_;
  }
  /// Items the backend produced (delivered to the buffer or dropped by it).
  std::size_t produced() const { return produced_.load(); }
  /// Items dropped because the consumer fell behind (buffer full, live mode), or reported lost
  /// by the backend (count_lost: e.g. a simulation rendering slower than real time).
  std::size_t dropped() const { return lost_.load() + (buffer_ ? buffer_->dropped() : 0); }
  /// The items the backend lost (count_lost), by reason in the backend's words (a V4L2
  /// grabber: "driver_dropped", "error_frames", "undecodable"); empty when it keeps no
  /// breakdown. Thread-safe.
  virtual std::map<std::string, std::size_t> losses() const { return {}; }

 protected:
  /// Opens the device or file; a failure ends the source (kFailed) with its message.
  virtual Status open() = 0;
  /// Produces at most one item into `item`. May block briefly (up to ~0.1 s) waiting for the
  /// device; must return soon after stop_requested() becomes true. Errors end the source.
  virtual Result<Polled> poll(T& item) = 0;
  /// Releases the device; called once from the source's thread after the last poll().
  virtual void close() {}
  /// The device timestamp (s) of an item, for playback pacing.
  virtual double timestamp_s(const T& item) const = 0;
  /// true for recorded and simulated backends, which Playback paces; false for live devices.
  virtual bool is_playback() const { return false; }

  /// The device time real-time playback is at now; none when playing as fast as possible (or
  /// for live devices). Lets a simulation skip frames it could not render in time.
  std::optional<double> playback_now_s() const {
    if (!is_playback() || !options_.playback.real_time) return std::nullopt;
    return options_.playback.device_origin_s +
           (monotonic_s() - options_.playback.monotonic_origin_s) * options_.playback.speed;
  }
  /// Whether stop() was called.
  bool stop_requested() const { return stop_requested_.load(); }
  /// Records `count` items the device produced that never reached the buffer.
  void count_lost(std::size_t count) { lost_.fetch_add(count); }
  /// Sets condition() (empty: all is well again).
  void set_condition(std::string text) {
    std::lock_guard lock(message_mutex_);
    condition_ = std::move(text);
  }

 private:
  void finish(SourceState state, std::string message) {
    {
      std::lock_guard lock(message_mutex_);
      message_ = std::move(message);
    }
    state_.store(state);  // before close(): a consumer that sees the end sees the state too
    buffer_->close();
  }

  // Waits until the item's playback time (real-time playback only). False when stopped.
  bool pace(const T& item) {
    if (!is_playback() || !options_.playback.real_time) return true;
    const Playback& p = options_.playback;
    const double due_s = p.monotonic_origin_s + (timestamp_s(item) - p.device_origin_s) / p.speed;
    while (!stop_requested()) {
      const double wait_s = due_s - monotonic_s();
      if (wait_s <= 0.0) return true;
      // Short naps so that stop() is honoured quickly.
      std::this_thread::sleep_for(std::chrono::duration<double>(std::min(wait_s, 0.02)));
    }
    return false;
  }

  void run() {
    try {
      if (Status opened = open(); !opened) {
        finish(SourceState::kFailed, opened.message());
        return;
      }
    } catch (const std::exception& e) {
      finish(SourceState::kFailed, describe() + ": open failed: " + e.what());
      return;
    }
    SourceState end_state = SourceState::kEnded;
    std::string end_message = "stopped";
    try {
      while (!stop_requested()) {
        T item{};
        const Result<Polled> polled = poll(item);
        if (!polled) {
          end_state = SourceState::kFailed;
          end_message = polled.message();
          break;
        }
        if (*polled == Polled::kEnd) {
          end_message = "end of stream after " + std::to_string(produced_.load()) + " items";
          break;
        }
        if (*polled == Polled::kNothing) {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
          continue;
        }
        if (!pace(item)) break;
        produced_.fetch_add(1);
        Received<T> received{std::move(item), monotonic_s()};
        const bool kept = options_.wait_when_full ? buffer_->push_wait(std::move(received))
                                                  : buffer_->push_drop_oldest(std::move(received));
        if (!kept) break;  // closed by stop()
      }
    } catch (const std::exception& e) {
      end_state = SourceState::kFailed;
      end_message = describe() + ": " + e.what();
    }
    try {
      close();
    } catch (const std::exception& e) {
      if (end_state != SourceState::kFailed) {
        end_state = SourceState::kFailed;
        end_message = describe() + ": close failed: " + e.what();
      }
    }
    finish(end_state, std::move(end_message));
  }

  SourceOptions options_;
  std::unique_ptr<BoundedQueue<Received<T>>> buffer_;
  std::thread thread_;
  std::atomic<SourceState> state_{SourceState::kIdle};
  std::atomic<bool> stop_requested_{false};
  std::atomic<std::size_t> produced_{0};
  std::atomic<std::size_t> lost_{0};
  mutable std::mutex message_mutex_;
  std::string message_;
  std::string condition_;
};

}  // namespace sonoshape::acq
