#include "sonoshape/acquisition/stream_source.hpp"

#include <algorithm>
#include <chrono>
#include <exception>
#include <string>
#include <thread>
#include <utility>

namespace sonoshape::acquisition {

Status StreamThread::start(const SourceOptions& options) {
  if (state_.load() != SourceState::kIdle || thread_.joinable())
    return Status::error(steps_.describe() + ": already started");
  if (options.buffer_capacity == 0 || !(options.playback.speed > 0.0))
    return Status::error(steps_.describe() +
                         ": invalid source options (buffer capacity must be >= 1 and the "
                         "playback speed positive)");
  options_ = options;
  if (options_.playback.monotonic_origin_s == 0.0)
    options_.playback.monotonic_origin_s = monotonic_s();
  steps_.make_buffer(options.buffer_capacity);
  state_.store(SourceState::kRunning);
  thread_ = std::thread([this] { run(); });
  return Status::ok();
}

void StreamThread::stop() {
  stop_requested_.store(true);
  steps_.close_buffer();  // wakes a thread waiting for room
  if (thread_.joinable()) thread_.join();
}

std::string StreamThread::message() const {
  std::lock_guard lock(message_mutex_);
  return message_;
}

std::string StreamThread::condition() const {
  std::lock_guard lock(message_mutex_);
  return condition_;
}

std::vector<std::string> StreamThread::take_condition_changes() {
  std::lock_guard lock(message_mutex_);
  std::vector<std::string> changes(condition_changes_.begin(), condition_changes_.end());
  condition_changes_.clear();
  return changes;
}

void StreamThread::set_condition(std::string text) {
  constexpr std::size_t kKeptChanges = 32;  // a consumer that never takes them keeps no more
  std::lock_guard lock(message_mutex_);
  // Only going into trouble and coming out of it are changes; new words for the same trouble
  // (a reopen's latest failure) only update condition().
  const bool changes = text.empty() != condition_.empty();
  condition_ = std::move(text);
  if (!changes) return;
  condition_changes_.push_back(condition_);
  if (condition_changes_.size() > kKeptChanges) condition_changes_.pop_front();
}

std::optional<double> StreamThread::playback_now_s() const {
  if (!steps_.is_playback() || !options_.playback.real_time) return std::nullopt;
  return options_.playback.device_origin_s +
         (monotonic_s() - options_.playback.monotonic_origin_s) * options_.playback.speed;
}

void StreamThread::finish(SourceState state, std::string message) {
  {
    std::lock_guard lock(message_mutex_);
    message_ = std::move(message);
  }
  state_.store(state);  // before closing: a consumer that sees the end sees the state too
  steps_.close_buffer();
}

// Waits until the item's playback time (real-time playback only). False when stopped.
bool StreamThread::pace(double timestamp_s) {
  if (!steps_.is_playback() || !options_.playback.real_time) return true;
  const Playback& p = options_.playback;
  const double due_s = p.monotonic_origin_s + (timestamp_s - p.device_origin_s) / p.speed;
  while (!stop_requested()) {
    const double wait_s = due_s - monotonic_s();
    if (wait_s <= 0.0) return true;
    // Short naps so that stop() is honoured quickly.
    std::this_thread::sleep_for(std::chrono::duration<double>(std::min(wait_s, 0.02)));
  }
  return false;
}

void StreamThread::run() {
  if (!open_backend()) return;
  SourceState end_state = SourceState::kEnded;
  std::string end_message = "stopped";
  poll_until_done(end_state, end_message);
  close_backend(end_state, end_message);
  finish(end_state, std::move(end_message));
}

// Opens the backend; on failure finishes the stream (kFailed) and returns false.
bool StreamThread::open_backend() {
  try {
    if (Status opened = steps_.open(); !opened) {
      finish(SourceState::kFailed, opened.message());
      return false;
    }
  } catch (const std::exception& e) {
    finish(SourceState::kFailed, steps_.describe() + ": open failed: " + e.what());
    return false;
  }
  return true;
}

// Polls and delivers until the stream ends, fails or is stopped; says how it ended.
void StreamThread::poll_until_done(SourceState& end_state, std::string& end_message) {
  try {
    while (!stop_requested()) {
      const Result<Polled> polled = steps_.poll();
      if (!polled) {
        end_state = SourceState::kFailed;
        end_message = polled.message();
        return;
      }
      if (*polled == Polled::kEnd) {
        end_message = "end of stream after " + std::to_string(produced_.load()) + " items";
        return;
      }
      if (*polled == Polled::kNothing) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        continue;
      }
      if (!pace(steps_.pending_timestamp_s())) return;
      produced_.fetch_add(1);
      if (!steps_.deliver(monotonic_s(), options_.wait_when_full)) return;  // closed by stop()
    }
  } catch (const std::exception& e) {
    end_state = SourceState::kFailed;
    end_message = steps_.describe() + ": " + e.what();
  }
}

// Closes the backend after its last poll(); a failing close fails a stream that had not failed.
void StreamThread::close_backend(SourceState& end_state, std::string& end_message) {
  try {
    steps_.close();
  } catch (const std::exception& e) {
    if (end_state != SourceState::kFailed) {
      end_state = SourceState::kFailed;
      end_message = steps_.describe() + ": close failed: " + e.what();
    }
  }
}

}  // namespace sonoshape::acquisition
