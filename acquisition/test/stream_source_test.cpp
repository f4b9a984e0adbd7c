// StreamSource (through FrameSource): threads, buffers, pacing, failures reported as states,
// the backend's life (closed after its last poll, destroyed after the thread is joined), and
// the replay of the real PLUS sweep.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "sonoshape/acquisition/frame_source.hpp"

namespace sonoshape::acquisition::stream_source_test {
namespace {

const std::filesystem::path kPlusSweep =
    std::filesystem::path(SONOSHAPE_DATA_DIR) / "plus" / "SpinePhantomFreehand.igs.mha";

// Frames 0..count-1 of 4x4 pixels at `period_s`; optionally fails (error or exception) after
// `fail_after` frames.
class FakeFrames final : public FrameBackend {
 public:
  enum class Failure { kNone, kError, kThrow };
  FakeFrames(int count, double period_s, Failure failure = Failure::kNone, int fail_after = 0)
      : count_(count), period_s_(period_s), failure_(failure), fail_after_(fail_after) {}
  std::string describe() const override { return "fake"; }

 protected:
  Status open() override { return Status::ok(); }
  Result<Polled> poll(Frame& frame) override {
    if (failure_ != Failure::kNone && next_ == fail_after_) {
      if (failure_ == Failure::kThrow) throw std::runtime_error("probe unplugged");
      return Status::error("fake: device vanished");
    }
    if (next_ == count_) return Polled::kEnd;
    frame.image = GreyImage(4, 4, static_cast<std::uint8_t>(next_));
    frame.index = next_;
    frame.timestamp_s = 10.0 + next_ * period_s_;
    ++next_;
    return Polled::kItem;
  }
  bool is_playback() const override { return true; }

 private:
  int count_;
  double period_s_;
  Failure failure_;
  int fail_after_;
  int next_ = 0;
};

std::vector<std::int64_t> drain(FrameSource& source) {
  std::vector<std::int64_t> indices;
  while (true) {
    auto frame = source.next(5.0);
    if (!frame) break;
    indices.push_back(frame->item.index);
  }
  return indices;
}

TEST(StreamSource, FastPlaybackWaitsForTheConsumerAndLosesNothing) {
  SourceOf<FakeFrames> source(50, 0.1);
  SourceOptions options;
  options.buffer_capacity = 2;
  options.wait_when_full = true;
  ASSERT_TRUE(source.start(options));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // let it fill the buffer
  const auto indices = drain(source);
  ASSERT_EQ(indices.size(), 50u);
  for (std::size_t k = 0; k < indices.size(); ++k) EXPECT_EQ(indices[k], static_cast<long>(k));
  EXPECT_TRUE(source.finished());
  EXPECT_EQ(source.state(), SourceState::kEnded);
  EXPECT_EQ(source.dropped(), 0u);
  EXPECT_EQ(source.produced(), 50u);
  EXPECT_FALSE(source.start(options));  // once only
}

TEST(StreamSource, LiveBufferDropsTheOldestWhenTheConsumerIsLate) {
  SourceOf<FakeFrames> source(20, 0.1);
  SourceOptions options;
  options.buffer_capacity = 4;
  options.wait_when_full = false;
  ASSERT_TRUE(source.start(options));
  while (source.state() == SourceState::kRunning)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const auto indices = drain(source);
  EXPECT_EQ(indices, (std::vector<std::int64_t>{16, 17, 18, 19}));  // the freshest
  EXPECT_EQ(source.dropped(), 16u);
}

TEST(StreamSource, RealTimePlaybackFollowsTheTimestamps) {
  SourceOf<FakeFrames> source(4, 0.05);
  SourceOptions options;
  options.playback.real_time = true;
  options.playback.device_origin_s = 10.0;
  options.playback.monotonic_origin_s = monotonic_s();
  ASSERT_TRUE(source.start(options));
  std::vector<double> delays;
  while (auto frame = source.next(5.0))
    delays.push_back(frame->received_s - options.playback.monotonic_origin_s);
  ASSERT_EQ(delays.size(), 4u);
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_GE(delays[k], 0.05 * k - 1e-3);
    EXPECT_LT(delays[k], 0.05 * k + 0.15);  // generous: loaded CI machines
  }
}

TEST(StreamSource, ErrorsAndExceptionsBecomeAFailedStateAfterTheFramesSoFar) {
  for (const auto failure : {FakeFrames::Failure::kError, FakeFrames::Failure::kThrow}) {
    SourceOf<FakeFrames> source(10, 0.1, failure, 3);
    SourceOptions options;
    options.wait_when_full = true;
    ASSERT_TRUE(source.start(options));
    EXPECT_EQ(drain(source).size(), 3u);
    EXPECT_TRUE(source.finished());
    EXPECT_EQ(source.state(), SourceState::kFailed);
    EXPECT_NE(source.message().find(failure == FakeFrames::Failure::kThrow ? "probe unplugged"
                                                                           : "device vanished"),
              std::string::npos)
        << source.message();
  }
}

TEST(StreamSource, StopEndsABlockedSource) {
  SourceOf<FakeFrames> source(1000000, 0.1);
  SourceOptions options;
  options.buffer_capacity = 1;
  options.wait_when_full = true;
  ASSERT_TRUE(source.start(options));
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  source.stop();  // must not hang on the full buffer
  EXPECT_EQ(source.state(), SourceState::kEnded);
  EXPECT_EQ(source.message(), "stopped");
}

// What a backend saw of its own life, kept outside it so that it can be read once it is gone.
struct BackendLife {
  std::atomic<int> polls_running{0};
  std::atomic<int> polls{0};
  std::atomic<int> closes{0};
  std::atomic<bool> destroyed{false};
  // Violations of the backend contract (StreamBackend): each must stay 0.
  std::atomic<int> polls_after_close{0};
  std::atomic<int> closes_during_poll{0};
  std::atomic<int> destroyed_during_poll{0};
  std::atomic<int> calls_after_destruction{0};
};

// A live device whose every read blocks for a while (a grabber waiting for its next frame),
// and which logs each call into `life`.
class BlockingFrames final : public FrameBackend {
 public:
  explicit BlockingFrames(std::shared_ptr<BackendLife> life) : life_(std::move(life)) {}
  ~BlockingFrames() override {
    if (life_->polls_running.load() > 0) ++life_->destroyed_during_poll;
    life_->destroyed.store(true);
  }
  std::string describe() const override { return "blocking"; }

 protected:
  Status open() override { return Status::ok(); }
  Result<Polled> poll(Frame& frame) override {
    if (life_->destroyed.load()) ++life_->calls_after_destruction;
    if (life_->closes.load() > 0) ++life_->polls_after_close;
    ++life_->polls_running;
    std::this_thread::sleep_for(std::chrono::milliseconds(15));
    --life_->polls_running;
    frame.image = GreyImage(2, 2, 0);
    frame.index = life_->polls++;
    return Polled::kItem;
  }
  void close() override {
    if (life_->destroyed.load()) ++life_->calls_after_destruction;
    if (life_->polls_running.load() > 0) ++life_->closes_during_poll;
    ++life_->closes;
  }

 private:
  std::shared_ptr<BackendLife> life_;
};

TEST(StreamSource, DestroyedWhilePollingClosesTheBackendAfterItsLastPollThenDestroysIt) {
  for (int round = 0; round < 5; ++round) {
    auto life = std::make_shared<BackendLife>();
    auto source = std::make_unique<SourceOf<BlockingFrames>>(life);
    ASSERT_TRUE(source->start());
    // Destroy the stream while its thread is inside poll(), after a few rounds of it.
    while (life->polls.load() < round || life->polls_running.load() == 0)
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    source.reset();
    EXPECT_TRUE(life->destroyed.load());
    EXPECT_EQ(life->closes.load(), 1);
    EXPECT_EQ(life->closes_during_poll.load(), 0);
    EXPECT_EQ(life->polls_after_close.load(), 0);
    EXPECT_EQ(life->destroyed_during_poll.load(), 0);
    EXPECT_EQ(life->calls_after_destruction.load(), 0);
    EXPECT_EQ(life->polls_running.load(), 0);
  }
}

TEST(StreamSource, ABackendNeverStartedIsDestroyedWithoutBeingOpened) {
  auto life = std::make_shared<BackendLife>();
  { SourceOf<BlockingFrames> source(life); }
  EXPECT_TRUE(life->destroyed.load());
  EXPECT_EQ(life->polls.load(), 0);
  EXPECT_EQ(life->closes.load(), 0);
}

// A live device that loses its connection and gets it back between two frames, then ends.
class FlickeringFrames final : public FrameBackend {
 public:
  std::string describe() const override { return "flickering"; }

 protected:
  Status open() override { return Status::ok(); }
  Result<Polled> poll(Frame& frame) override {
    if (next_ == 3) return Polled::kEnd;
    if (next_ == 1) {
      set_condition("cable pulled; reconnecting");
      set_condition("cable pulled; reconnect failed");  // new words for the same trouble
      set_condition("");
    }
    frame.image = GreyImage(2, 2, 0);
    frame.index = next_++;
    return Polled::kItem;
  }

 private:
  int next_ = 0;
};

TEST(StreamSource, TroubleShorterThanAPollIsStillSeenOnceEachWay) {
  SourceOf<FlickeringFrames> source;
  ASSERT_TRUE(source.start());
  EXPECT_EQ(drain(source).size(), 3u);
  EXPECT_EQ(source.condition(), "");  // all well by now: only the changes tell
  EXPECT_EQ(source.take_condition_changes(),
            (std::vector<std::string>{"cable pulled; reconnecting", ""}));
  EXPECT_TRUE(source.take_condition_changes().empty());  // each change is taken once
}

TEST(StreamSource, RefusesANullBackend) {
  EXPECT_THROW(FrameSource(std::unique_ptr<FrameBackend>()), std::invalid_argument);
}

TEST(ReplayFrameSource, ReplaysTheRealPlusSweep) {
  auto file = read_sequence_file(kPlusSweep);
  ASSERT_TRUE(file) << file.message();
  auto shared = std::make_shared<const SequenceFile>(std::move(*file));
  ReplayFrameSource source(shared, kPlusSweep.filename().string());
  SourceOptions options;
  options.wait_when_full = true;
  ASSERT_TRUE(source.start(options));
  std::size_t count = 0;
  while (auto frame = source.next(5.0)) {
    EXPECT_EQ(frame->item.index, static_cast<std::int64_t>(count));
    EXPECT_EQ(frame->item.image.width, 820);
    EXPECT_EQ(frame->item.image.height, 616);
    EXPECT_DOUBLE_EQ(frame->item.timestamp_s, *shared->timestamp_s(count));
    ++count;
  }
  EXPECT_EQ(count, 21u);
  EXPECT_EQ(source.state(), SourceState::kEnded);
  EXPECT_DOUBLE_EQ(first_timestamp_s(*shared), 215.102186);
}

}  // namespace
}  // namespace sonoshape::acquisition::stream_source_test
