#pragma once
// Every device source (design.md, "Devices"): FrameSource (images) and tracking::PoseSource
// (tracker samples). A backend (StreamBackend: a file, a grabber, a tracker) implements
// open / poll / close only; the stream (StreamSource) owns the backend, the thread, the receive
// timestamps, the buffer and the playback clock. The stream joins its thread before it destroys
// the backend, so no backend has to stop a thread in its destructor.
// A backend that fails or ends says so through state() and message(): nothing it throws
// crosses the thread (exceptions become a kFailed state with their message).
#include <atomic>
#include <chrono>
#include <cstddef>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "sonoshape/core/bounded_queue.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition {

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

/// The untyped half of every stream: its thread (open, then poll until the stream ends, fails
/// or is stopped, then close), its state, counts and messages, and the playback clock. Defined
/// in stream_source.cpp; StreamSource<T> supplies the typed steps (its backend and its buffer).
class StreamThread {
 public:
  /// What the thread does with the typed backend and buffer of one stream.
  class Steps {
   public:
    virtual std::string describe() const = 0;
    virtual bool is_playback() const = 0;
    virtual void make_buffer(std::size_t capacity) = 0;
    virtual void close_buffer() = 0;
    virtual Status open() = 0;
    /// Polls the backend into a fresh pending item.
    virtual Result<Polled> poll() = 0;
    virtual double pending_timestamp_s() const = 0;
    /// Moves the pending item into the buffer; false when the buffer was closed (stop()).
    virtual bool deliver(double received_s, bool wait_when_full) = 0;
    virtual void close() = 0;

   protected:
    ~Steps() = default;
  };

  explicit StreamThread(Steps& steps) : steps_(steps) {}
  StreamThread(const StreamThread&) = delete;
  StreamThread& operator=(const StreamThread&) = delete;
  ~StreamThread() {
    if (thread_.joinable()) stop();
  }

  Status start(const SourceOptions& options);
  void stop();
  SourceState state() const { return state_.load(); }
  std::string message() const;
  std::string condition() const;
  std::vector<std::string> take_condition_changes();
  std::size_t produced() const { return produced_.load(); }
  std::size_t lost() const { return lost_.load(); }

  // The services a backend reaches through StreamBackend (thread-safe).
  bool stop_requested() const { return stop_requested_.load(); }
  void count_lost(std::size_t count) { lost_.fetch_add(count); }
  void set_condition(std::string text);
  std::optional<double> playback_now_s() const;

 private:
  void run();
  bool open_backend();
  void poll_until_done(SourceState& end_state, std::string& end_message);
  void close_backend(SourceState& end_state, std::string& end_message);
  bool pace(double timestamp_s);
  void finish(SourceState state, std::string message);

  Steps& steps_;
  SourceOptions options_;
  std::thread thread_;
  std::atomic<SourceState> state_{SourceState::kIdle};
  std::atomic<bool> stop_requested_{false};
  std::atomic<std::size_t> produced_{0};
  std::atomic<std::size_t> lost_{0};
  mutable std::mutex message_mutex_;
  std::string message_;
  std::string condition_;
  std::deque<std::string> condition_changes_;  // not yet taken, oldest first
};

template <typename T>
class StreamSource;

/// A device, file or simulation that produces T: what a backend implements. Its open(),
/// poll() and close() run on the thread of the StreamSource that owns it, never concurrently
/// and never after the stream began destroying it; its other members may be called from any
/// thread (make them thread-safe).
template <typename T>
class StreamBackend {
 public:
  using Item = T;

  StreamBackend() = default;
  StreamBackend(const StreamBackend&) = delete;
  StreamBackend& operator=(const StreamBackend&) = delete;
  virtual ~StreamBackend() = default;

  /// What the backend reads, as the user named it (e.g. "replay:sweep.igs.mha").
  virtual std::string describe() const = 0;
  /// The items the backend lost (count_lost), by reason in the backend's words (a V4L2
  /// grabber: "driver_dropped", "error_frames", "undecodable"); empty when it keeps no
  /// breakdown. Thread-safe.
  virtual std::map<std::string, std::size_t> losses() const { return {}; }
  /// true for recorded and simulated backends, which Playback paces; false for live devices.
  virtual bool is_playback() const { return false; }

 protected:
  /// Opens the device or file; a failure ends the source (kFailed) with its message.
  virtual Status open() = 0;
  /// Produces at most one item into `item`. May block briefly (up to ~0.1 s) waiting for the
  /// device; must return soon after stop_requested() becomes true. Errors end the source.
  virtual Result<Polled> poll(T& item) = 0;
  /// Releases the device; called once from the stream's thread after the last poll().
  virtual void close() {}
  /// The device timestamp (s) of an item, for playback pacing.
  virtual double timestamp_s(const T& item) const { return item.timestamp_s; }

  /// The device time real-time playback is at now; none when playing as fast as possible (or
  /// for live devices). Lets a simulation skip frames it could not render in time.
  std::optional<double> playback_now_s() const {
    return thread_ ? thread_->playback_now_s() : std::nullopt;
  }
  /// Whether the stream was asked to stop.
  bool stop_requested() const { return thread_ && thread_->stop_requested(); }
  /// Records `count` items the device produced that never reached the buffer.
  void count_lost(std::size_t count) {
    if (thread_) thread_->count_lost(count);
  }
  /// Sets the stream's condition() (empty: all is well again).
  void set_condition(std::string text) {
    if (thread_) thread_->set_condition(std::move(text));
  }

 private:
  friend class StreamSource<T>;
  StreamThread* thread_ = nullptr;  // the owning stream's, set when it takes the backend
};

/// A stream of T from a backend, delivered by a thread of its own. Owns the backend: the
/// thread is joined before the backend is destroyed. Thread-safe: the consumer calls next()
/// from any one thread while the source runs.
template <typename T>
class StreamSource : private StreamThread::Steps {
 public:
  /// Runs `backend` (not null) once start() is called.
  explicit StreamSource(std::unique_ptr<StreamBackend<T>> backend) : backend_(std::move(backend)) {
    if (!backend_) throw std::invalid_argument("StreamSource: no backend");
    backend_->thread_ = &thread_;
  }
  StreamSource(const StreamSource&) = delete;
  StreamSource& operator=(const StreamSource&) = delete;
  /// Stops and joins the thread, then destroys the backend.
  virtual ~StreamSource() { thread_.stop(); }

  /// What the source reads, as the user named it (e.g. "replay:sweep.igs.mha").
  std::string describe() const override { return backend_->describe(); }

  /// Starts the thread: open(), then poll() until the stream ends, fails, or stop() is called.
  /// Fails when already started or when the options are invalid (zero capacity, speed <= 0);
  /// a failing open() is reported through state() like any later failure.
  Status start(const SourceOptions& options = {}) { return thread_.start(options); }

  /// Asks the thread to finish, waits for it, and closes the backend. Items already buffered
  /// can still be taken with next(). Idempotent.
  void stop() { thread_.stop(); }

  /// The next item, waiting up to `timeout_s` seconds. None on timeout, or at once when the
  /// source has finished and its buffer is empty (then finished() is true).
  std::optional<Received<T>> next(double timeout_s) {
    if (!buffer_) return std::nullopt;
    return buffer_->pop(timeout_s);
  }

  /// Ended or failed, and every buffered item taken: nothing more will come.
  bool finished() const {
    const SourceState s = thread_.state();
    return (s == SourceState::kEnded || s == SourceState::kFailed) &&
           (!buffer_ || buffer_->size() == 0);
  }
  /// The current state (kEnded or kFailed may still have buffered items).
  SourceState state() const { return thread_.state(); }
  /// Why the source ended or failed (empty while it runs).
  std::string message() const { return thread_.message(); }
  /// Trouble a running source is riding out (e.g. "device unplugged; reopening it"); empty
  /// when all is well. Thread-safe.
  std::string condition() const { return thread_.condition(); }
  /// Each time condition() went into trouble (its first words) or out of it (empty text) since
  /// the last call, oldest first, so that trouble shorter than the consumer's polling interval
  /// is still seen. Keeps the last 32 changes. Thread-safe.
  std::vector<std::string> take_condition_changes() { return thread_.take_condition_changes(); }
  /// Items the backend produced (delivered to the buffer or dropped by it).
  std::size_t produced() const { return thread_.produced(); }
  /// Items dropped because the consumer fell behind (buffer full, live mode), or reported lost
  /// by the backend (count_lost: e.g. a simulation rendering slower than real time).
  std::size_t dropped() const { return thread_.lost() + (buffer_ ? buffer_->dropped() : 0); }
  /// The backend's losses by reason (StreamBackend::losses). Thread-safe.
  std::map<std::string, std::size_t> losses() const { return backend_->losses(); }

  /// The backend, for what only it knows (a grabber's format, a tracker's counts).
  StreamBackend<T>& backend() { return *backend_; }
  const StreamBackend<T>& backend() const { return *backend_; }

 private:
  bool is_playback() const override { return backend_->is_playback(); }
  void make_buffer(std::size_t capacity) override {
    buffer_ = std::make_unique<BoundedQueue<Received<T>>>(capacity);
  }
  void close_buffer() override {
    if (buffer_) buffer_->close();
  }
  Status open() override { return backend_->open(); }
  Result<Polled> poll() override {
    pending_ = T{};
    return backend_->poll(pending_);
  }
  double pending_timestamp_s() const override { return backend_->timestamp_s(pending_); }
  bool deliver(double received_s, bool wait_when_full) override {
    Received<T> received{std::move(pending_), received_s};
    return wait_when_full ? buffer_->push_wait(std::move(received))
                          : buffer_->push_drop_oldest(std::move(received));
  }
  void close() override { backend_->close(); }

  std::unique_ptr<StreamBackend<T>> backend_;
  std::unique_ptr<BoundedQueue<Received<T>>> buffer_;
  T pending_{};                 // the item between poll() and deliver(), on the thread only
  StreamThread thread_{*this};  // declared last: joined before the members above go
};

/// The stream of a backend of type `Backend`, built in place, with the backend's own members
/// (a grabber's counters, a tracker's status) reachable through backend().
template <class Backend>
class SourceOf final : public StreamSource<typename Backend::Item> {
 public:
  using Item = typename Backend::Item;

  /// Constructs the backend from `args`.
  template <typename... Args>
  explicit SourceOf(Args&&... args)
      : StreamSource<Item>(std::make_unique<Backend>(std::forward<Args>(args)...)) {}

  Backend& backend() { return static_cast<Backend&>(StreamSource<Item>::backend()); }
  const Backend& backend() const {
    return static_cast<const Backend&>(StreamSource<Item>::backend());
  }
};

}  // namespace sonoshape::acquisition
