#pragma once
// Taking samples from a running pose source in tests, and checking its counts against them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <vector>

#include "sonoshape/tracking/pose_source.hpp"

namespace sonoshape::tracking::test {

/// Up to `count` samples, waiting at most 10 s for each.
inline std::vector<Pose> take(PoseSource& source, std::size_t count) {
  std::vector<Pose> poses;
  while (poses.size() < count)
    if (auto p = source.next(10.0))
      poses.push_back(p->item);
    else
      break;
  return poses;
}

/// Takes `count` samples, stops the source, and adds what it produced meanwhile: then the
/// source's counts describe the samples returned, but for the one sample a stop() may catch
/// between its decoding (counted) and the closed buffer (see within_one).
inline std::vector<Pose> take_then_stop(PoseSource& source, std::size_t count) {
  std::vector<Pose> poses = take(source, count);
  source.stop();
  while (auto p = source.next(0.0)) poses.push_back(p->item);
  return poses;
}

/// A count of the source against the samples delivered: equal, or one more (take_then_stop).
inline void within_one(std::size_t counted, std::size_t delivered) {
  EXPECT_GE(counted, delivered);
  EXPECT_LE(counted, delivered + 1);
}

inline std::size_t count_valid(const std::vector<Pose>& poses) {
  return static_cast<std::size_t>(std::count_if(poses.begin(), poses.end(), [](const Pose& p) {
    return p.status == TrackingStatus::kValid;
  }));
}

}  // namespace sonoshape::tracking::test
