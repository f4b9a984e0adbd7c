// StreamSource (through FrameSource): threads, buffers, pacing, failures reported as states,
// and the replay of the real PLUS sweep.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <stdexcept>
#include <thread>

#include "sonoshape/acquisition/frame_source.hpp"

namespace sonoshape::acq {
namespace {

const std::filesystem::path kPlusSweep =
    std::filesystem::path(SONOSHAPE_DATA_DIR) / "plus" / "SpinePhantomFreehand.igs.mha";

// Frames 0..count-1 of 4x4 pixels at `period_s`; optionally fails (error or exception) after
// `fail_after` frames.
class FakeFrames final : public FrameSource {
 public:
  enum class Failure { kNone, kError, kThrow };
  FakeFrames(int count, double period_s, Failure failure = Failure::kNone, int fail_after = 0)
      : count_(count), period_s_(period_s), failure_(failure), fail_after_(fail_after) {}
  ~FakeFrames() override { stop(); }
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
  FakeFrames source(50, 0.1);
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
  FakeFrames source(20, 0.1);
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
  FakeFrames source(4, 0.05);
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
    FakeFrames source(10, 0.1, failure, 3);
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
  FakeFrames source(1000000, 0.1);
  SourceOptions options;
  options.buffer_capacity = 1;
  options.wait_when_full = true;
  ASSERT_TRUE(source.start(options));
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  source.stop();  // must not hang on the full buffer
  EXPECT_EQ(source.state(), SourceState::kEnded);
  EXPECT_EQ(source.message(), "stopped");
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
}  // namespace sonoshape::acq
