#pragma once
// Wall time of segment_frame's stages, for the speed benchmark (bench/segmentation_speed.cpp).
// Internal: nothing outside the benchmark sets the sink, and then a stage costs one
// thread-local read.
#include <array>
#include <chrono>
#include <cstddef>

namespace sonoshape::segmentation::detail {

/// The stages of segment_frame, in order (docs/segmentation.md, "Method").
enum class Stage : std::size_t {
  kFilter,      ///< median and masked Gaussian
  kConfidence,  ///< dark fraction, shadows, max depth, margin
  kClassify,    ///< depth-trend fit and nearest-mean classification
  kCleaning,    ///< opening, small components, diagonal repair and the output maps
  kCount
};

/// Milliseconds per stage, summed over the frames segmented while this was the sink.
struct StageTimes {
  std::array<double, static_cast<std::size_t>(Stage::kCount)> ms{};
};

/// Where this thread's segment_frame adds its stage times; null (the default): nowhere.
inline thread_local StageTimes* stage_times_sink = nullptr;

/// Adds the time since the previous lap (or construction) to a stage of the sink, if any.
class StageClock {
 public:
  StageClock() : sink_(stage_times_sink) {
    if (sink_) last_ = Clock::now();
  }
  void lap(Stage stage) {
    if (!sink_) return;
    const Clock::time_point now = Clock::now();
    sink_->ms[static_cast<std::size_t>(stage)] +=
        std::chrono::duration<double, std::milli>(now - last_).count();
    last_ = now;
  }

 private:
  using Clock = std::chrono::steady_clock;
  StageTimes* sink_;
  Clock::time_point last_{};
};

}  // namespace sonoshape::segmentation::detail
