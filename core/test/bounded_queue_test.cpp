// BoundedQueue: bounded, drop-oldest or wait when full, close semantics.
#include "sonoshape/core/bounded_queue.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

namespace sonoshape::bounded_queue_test {
namespace {

TEST(BoundedQueue, DropOldestKeepsTheNewestAndReportsWhatItDropped) {
  BoundedQueue<int> queue(3);
  for (int k = 0; k < 3; ++k) EXPECT_TRUE(queue.push_drop_oldest(k));
  std::optional<int> evicted;
  EXPECT_TRUE(queue.push_drop_oldest(3, &evicted));
  ASSERT_TRUE(evicted);
  EXPECT_EQ(*evicted, 0);
  EXPECT_TRUE(queue.push_drop_oldest(4));
  EXPECT_EQ(queue.size(), 3u);  // never more than the capacity
  EXPECT_EQ(queue.dropped(), 2u);
  EXPECT_EQ(queue.pop_all(), (std::vector<int>{2, 3, 4}));
  EXPECT_FALSE(queue.try_pop());
}

TEST(BoundedQueue, PushWaitBlocksUntilThereIsRoom) {
  BoundedQueue<int> queue(2);
  ASSERT_TRUE(queue.push_wait(1));
  ASSERT_TRUE(queue.push_wait(2));
  std::atomic<bool> pushed{false};
  std::thread producer([&] {
    queue.push_wait(3);
    pushed = true;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_FALSE(pushed.load());  // full: the producer waits, nothing is dropped
  EXPECT_EQ(queue.pop(1.0), 1);
  producer.join();
  EXPECT_TRUE(pushed.load());
  EXPECT_EQ(queue.dropped(), 0u);
  EXPECT_EQ(queue.pop(1.0), 2);
  EXPECT_EQ(queue.pop(1.0), 3);
}

TEST(BoundedQueue, PopTimesOutAndCloseWakesEveryone) {
  BoundedQueue<int> queue(1);
  EXPECT_FALSE(queue.pop(0.01));
  ASSERT_TRUE(queue.push_wait(7));
  std::thread blocked([&] { EXPECT_FALSE(queue.push_wait(8)); });  // full, then closed
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  queue.close();
  blocked.join();
  EXPECT_FALSE(queue.push_drop_oldest(9));
  EXPECT_FALSE(queue.drained());
  EXPECT_EQ(queue.pop(10.0), 7);  // queued items still come out after close
  EXPECT_TRUE(queue.drained());
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE(queue.pop(10.0));  // at once, not after the timeout
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(1));
  EXPECT_THROW(BoundedQueue<int>(0), std::invalid_argument);
}

}  // namespace
}  // namespace sonoshape::bounded_queue_test
