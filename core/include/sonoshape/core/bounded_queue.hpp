#pragma once
// A thread-safe FIFO of fixed capacity: the buffers of sources and the queues between pipeline
// stages. Nothing is ever queued without bound: a full queue either drops its oldest item (live
// streams prefer fresh data) or makes the producer wait (recorded data played as fast as the
// consumer goes, where nothing may be lost).
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <utility>
#include <vector>

namespace sonoshape {

/// Bounded multi-producer multi-consumer FIFO. All members are thread-safe.
template <typename T>
class BoundedQueue {
 public:
  /// A queue holding at most `capacity` items; throws std::invalid_argument for 0.
  explicit BoundedQueue(std::size_t capacity) : capacity_(capacity) {
    if (capacity == 0) throw std::invalid_argument("BoundedQueue: capacity must be at least 1");
  }
  BoundedQueue(const BoundedQueue&) = delete;
  BoundedQueue& operator=(const BoundedQueue&) = delete;

  /// Appends `item`; when the queue is full, the oldest item is removed first and moved into
  /// `*evicted` (when given) so that the caller can account for it. Returns false, and drops
  /// `item`, when the queue is closed.
  bool push_drop_oldest(T item, std::optional<T>* evicted = nullptr) {
    {
      std::lock_guard lock(mutex_);
      if (closed_) return false;
      if (items_.size() >= capacity_) {
        if (evicted) *evicted = std::move(items_.front());
        items_.pop_front();
        ++dropped_;
      }
      items_.push_back(std::move(item));
    }
    not_empty_.notify_one();
    return true;
  }

  /// Appends `item`, waiting while the queue is full. Returns false, and drops `item`, when the
  /// queue is (or gets) closed.
  bool push_wait(T item) {
    {
      std::unique_lock lock(mutex_);
      not_full_.wait(lock, [&] { return closed_ || items_.size() < capacity_; });
      if (closed_) return false;
      items_.push_back(std::move(item));
    }
    not_empty_.notify_one();
    return true;
  }

  /// Removes the oldest item, waiting up to `timeout_s` seconds for one. None on timeout, or
  /// at once when the queue is closed and empty.
  std::optional<T> pop(double timeout_s) {
    std::unique_lock lock(mutex_);
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                              std::chrono::duration<double>(std::max(0.0, timeout_s)));
    if (!not_empty_.wait_until(lock, deadline, [&] { return closed_ || !items_.empty(); }))
      return std::nullopt;
    return take(lock);
  }

  /// Removes the oldest item if there is one, without waiting.
  std::optional<T> try_pop() {
    std::unique_lock lock(mutex_);
    return take(lock);
  }

  /// Removes and returns every queued item, oldest first.
  std::vector<T> pop_all() {
    std::vector<T> out;
    {
      std::lock_guard lock(mutex_);
      out.reserve(items_.size());
      for (T& item : items_) out.push_back(std::move(item));
      items_.clear();
    }
    not_full_.notify_all();
    return out;
  }

  /// Refuses further pushes and wakes every waiting producer and consumer; queued items can
  /// still be popped.
  void close() {
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
    }
    not_empty_.notify_all();
    not_full_.notify_all();
  }

  /// Whether close() was called.
  bool closed() const {
    std::lock_guard lock(mutex_);
    return closed_;
  }
  /// Closed and empty: nothing will ever come out again.
  bool drained() const {
    std::lock_guard lock(mutex_);
    return closed_ && items_.empty();
  }
  /// Items queued now.
  std::size_t size() const {
    std::lock_guard lock(mutex_);
    return items_.size();
  }
  /// The most items the queue holds.
  std::size_t capacity() const { return capacity_; }
  /// Items removed by push_drop_oldest because the queue was full, since construction.
  std::size_t dropped() const {
    std::lock_guard lock(mutex_);
    return dropped_;
  }

 private:
  std::optional<T> take(std::unique_lock<std::mutex>& lock) {
    if (items_.empty()) return std::nullopt;
    std::optional<T> item(std::move(items_.front()));
    items_.pop_front();
    lock.unlock();
    not_full_.notify_one();
    return item;
  }

  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable not_empty_;
  std::condition_variable not_full_;
  std::deque<T> items_;
  bool closed_ = false;
  std::size_t dropped_ = 0;
};

}  // namespace sonoshape
