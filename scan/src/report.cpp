#include "sonoshape/scan/report.hpp"

#include <algorithm>
#include <cmath>

namespace sonoshape::scan {

const char* to_string(StopReason reason) {
  switch (reason) {
    case StopReason::kSourceEnded:
      return "source ended";
    case StopReason::kSourceFailed:
      return "source failed";
    case StopReason::kStopRequested:
      return "stop requested";
    case StopReason::kDuration:
      return "duration reached";
    case StopReason::kMaxSlices:
      return "max slices reached";
  }
  return "unknown";
}

void RepairReport::add(std::size_t frame, const Repair& repair) {
  ++counts[repair.kind];
  if (first.size() < kMaxListed) first.push_back({frame, repair});
}

std::size_t RepairReport::total() const {
  std::size_t n = 0;
  for (const auto& [kind, count] : counts) n += count;
  return n;
}

LatencyStats latency_stats(std::vector<double> samples_s) {
  LatencyStats stats;
  stats.count = samples_s.size();
  if (samples_s.empty()) return stats;
  std::sort(samples_s.begin(), samples_s.end());
  // Nearest rank: the smallest sample with at least p of the samples at or below it.
  auto rank = [&](double p) {
    const auto n = static_cast<double>(samples_s.size());
    const auto k = static_cast<std::size_t>(std::max(1.0, std::ceil(p * n)));
    return samples_s[std::min(k, samples_s.size()) - 1];
  };
  stats.p50_s = rank(0.50);
  stats.p95_s = rank(0.95);
  stats.max_s = samples_s.back();
  return stats;
}

}  // namespace sonoshape::scan
