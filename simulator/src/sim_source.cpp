#include "sonoshape/simulator/sim_source.hpp"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace sonoshape::simulator {

std::uint64_t frame_seed(std::uint64_t seed, std::size_t k) {
  // Decorrelated per-frame seeds, independent of the order frames are rendered in.
  return seed * 0x9E3779B97F4A7C15ull + k * 0xBF58476D1CE4E5B9ull;
}

void FrameTruthStore::put(std::int64_t index, LabelImage truth) {
  std::lock_guard lock(mutex_);
  frames_.emplace_back(index, std::move(truth));
  while (frames_.size() > capacity_) frames_.pop_front();
}

std::optional<LabelImage> FrameTruthStore::take(std::int64_t index) {
  std::lock_guard lock(mutex_);
  for (auto it = frames_.begin(); it != frames_.end(); ++it)
    if (it->first == index) {
      LabelImage truth = std::move(it->second);
      frames_.erase(it);
      return truth;
    }
  return std::nullopt;
}

SimFrames::SimFrames(std::shared_ptr<const BModeSimulator> simulator, Trajectory trajectory,
                     const SimFrameOptions& options, std::string name)
    : simulator_(std::move(simulator)),
      trajectory_(std::move(trajectory)),
      options_(options),
      name_(std::move(name)) {
  if (!simulator_) throw std::invalid_argument("SimFrameSource: no simulator");
  if (!(options.frame_rate_hz > 0.0) || options.frame_count < 1 || options.first_frame < 0)
    throw std::invalid_argument(
        "SimFrameSource: need a positive frame rate, frames and a first frame >= 0");
}

Status SimFrames::open() {
  next_ = options_.first_frame;
  delivered_ = 0;
  return Status::ok();
}

Result<acquisition::Polled> SimFrames::poll(Frame& frame) {
  if (options_.fail_after_frames >= 0 && delivered_ >= options_.fail_after_frames)
    return Status::error(name_ + ": probe vanished after " + std::to_string(delivered_) +
                         " frames (simulated fault; check the probe's cable)");
  // In real time, the probe has moved on while we rendered: take the frame due now.
  if (const auto now_s = playback_now_s()) {
    const long due = static_cast<long>(std::floor(*now_s * options_.frame_rate_hz));
    if (due > next_) {
      const long last = options_.frame_count - 1;
      const long skip_to = std::min(due, last);
      if (skip_to > next_) {
        count_lost(static_cast<std::size_t>(skip_to - next_));
        next_ = skip_to;
      }
    }
  }
  if (next_ >= options_.frame_count) return acquisition::Polled::kEnd;
  const long k = next_++;
  const double t_s = static_cast<double>(k) / options_.frame_rate_hz;
  SimulatedFrame rendered = simulator_->render(
      trajectory_.T_reference_probe(t_s), frame_seed(options_.seed, static_cast<std::size_t>(k)));
  if (options_.truth) options_.truth->put(k, std::move(rendered.truth));
  frame.image = std::move(rendered.bmode);
  frame.timestamp_s = t_s;
  frame.index = k;
  ++delivered_;
  return acquisition::Polled::kItem;
}

}  // namespace sonoshape::simulator
