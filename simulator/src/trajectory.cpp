#include "sonoshape/simulator/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>

namespace sonoshape::simulator {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
// Physiological tremor band (Hz) and the hand's slow drift band (Hz).
constexpr double kTremorLowHz = 8.0, kTremorHighHz = 12.0;
constexpr double kDriftLowHz = 0.1, kDriftHighHz = 0.5;
constexpr int kTremorWaves = 3, kDriftWaves = 2, kSpeedWaves = 3;

// Our own uniform and normal draws from mt19937_64 (whose output the standard fixes), so the
// sequences are the same with every standard library.
class Random {
 public:
  explicit Random(std::uint64_t seed) : engine_(seed) {}
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1]
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::mt19937_64 engine_;
};

Eigen::Matrix3d rotation_from_vector(const Vec3& rotation_vector_rad) {
  const double angle = rotation_vector_rad.norm();
  if (angle == 0.0) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, rotation_vector_rad / angle).toRotationMatrix();
}

}  // namespace

SweepMotion parse_sweep_motion(const std::string& name) {
  if (name == "sweep" || name == "translate") return SweepMotion::kTranslate;
  if (name == "fan") return SweepMotion::kFan;
  if (name == "rock") return SweepMotion::kRock;
  if (name == "rotate") return SweepMotion::kRotate;
  throw std::invalid_argument("unknown trajectory '" + name + "' (use sweep, fan, rock, rotate)");
}

Trajectory::Trajectory(const TrajectoryOptions& options) : options_(options) {
  if (!(options.duration_s > 0.0))
    throw std::invalid_argument("trajectory: duration_s must be positive");
  if (options.passes < 1) throw std::invalid_argument("trajectory: passes must be at least 1");
  Random random(options.seed);
  // Integer harmonics of the duration keep progress(0) = 0 and progress(duration) = 1; the
  // amplitudes sum below 1 so the speed never reverses.
  for (int k = 1; k <= kSpeedWaves; ++k)
    speed_waves_.push_back({random.uniform(-0.25, 0.25), k / options.duration_s, 0.0});
  for (int axis = 0; axis < 6; ++axis) {
    const bool angular = axis >= 3;
    const double tremor = angular ? options.tremor_deg : options.tremor_mm;
    const double drift = angular ? options.drift_deg : options.drift_mm;
    // RMS of a sum of n unit sines with random phases is sqrt(n / 2).
    const double tremor_amplitude = tremor / std::sqrt(0.5 * kTremorWaves);
    for (int w = 0; w < kTremorWaves; ++w)
      hand_waves_[axis].push_back({tremor_amplitude, random.uniform(kTremorLowHz, kTremorHighHz),
                                   random.uniform(0.0, 2.0 * std::numbers::pi)});
    for (int w = 0; w < kDriftWaves; ++w)
      hand_waves_[axis].push_back({drift / kDriftWaves, random.uniform(kDriftLowHz, kDriftHighHz),
                                   random.uniform(0.0, 2.0 * std::numbers::pi)});
  }
}

double Trajectory::progress(double t_s) const {
  // Which pass, and how far through it; the speed profile shapes every pass alike.
  const double total = std::clamp(t_s / options_.duration_s, 0.0, 1.0) * options_.passes;
  const int pass = std::min(static_cast<int>(total), options_.passes - 1);
  const double p = pass_progress(total - pass);
  return pass % 2 == 0 ? p : 1.0 - p;
}

double Trajectory::pass_progress(double x) const {
  switch (options_.speed) {
    case SpeedProfile::kConstant:
      return x;
    case SpeedProfile::kSmooth:
      return 0.5 * (1.0 - std::cos(std::numbers::pi * x));
    case SpeedProfile::kIrregular: {
      double p = x;
      for (std::size_t k = 0; k < speed_waves_.size(); ++k) {
        const double omega = 2.0 * std::numbers::pi * static_cast<double>(k + 1);
        p += speed_waves_[k].amplitude * std::sin(omega * x) / omega;
      }
      return std::clamp(p, 0.0, 1.0);
    }
  }
  return x;
}

Eigen::Isometry3d Trajectory::T_reference_probe(double t_s) const {
  const double q = progress(t_s) - 0.5;
  Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
  const double angle = q * options_.sweep_angle_deg * kDegToRad;
  switch (options_.motion) {
    case SweepMotion::kTranslate:
      motion.translation() = Vec3(0.0, 0.0, q * options_.sweep_length_mm);
      break;
    case SweepMotion::kFan:
      motion.linear() = Eigen::AngleAxisd(angle, Vec3::UnitX()).toRotationMatrix();
      break;
    case SweepMotion::kRock:
      motion.linear() = Eigen::AngleAxisd(angle, Vec3::UnitZ()).toRotationMatrix();
      break;
    case SweepMotion::kRotate:
      motion.linear() = Eigen::AngleAxisd(angle, Vec3::UnitY()).toRotationMatrix();
      break;
  }
  double hand[6];
  for (int axis = 0; axis < 6; ++axis) {
    hand[axis] = 0.0;
    for (const Wave& w : hand_waves_[axis])
      hand[axis] += w.amplitude * std::sin(2.0 * std::numbers::pi * w.frequency_hz * t_s + w.phase);
  }
  Eigen::Isometry3d tremor = Eigen::Isometry3d::Identity();
  tremor.translation() = Vec3(hand[0], hand[1], hand[2]);
  tremor.linear() = rotation_from_vector(kDegToRad * Vec3(hand[3], hand[4], hand[5]));
  return options_.T_reference_probe_centre * motion * tremor;
}

std::vector<Pose> track(const Trajectory& trajectory, const TrackerOptions& options, double start_s,
                        double end_s) {
  if (!(options.rate_hz > 0.0)) throw std::invalid_argument("tracker: rate_hz must be positive");
  Random random(options.seed);
  std::vector<Pose> samples;
  double invalid_until = -std::numeric_limits<double>::infinity();
  const auto count = static_cast<long long>(std::floor((end_s - start_s) * options.rate_hz)) + 1;
  for (long long i = 0; i < count; ++i) {
    const double t = start_s + static_cast<double>(i) / options.rate_hz;
    // Draw everything for every sample so one sample's fate does not shift the others' noise.
    const bool dropped = random.uniform() < options.drop_probability;
    const bool burst = random.uniform() < options.invalid_probability;
    const Vec3 position_noise(random.normal(), random.normal(), random.normal());
    const Vec3 angle_noise(random.normal(), random.normal(), random.normal());
    if (burst && t >= invalid_until) invalid_until = t + options.invalid_burst_s;
    if (dropped) continue;
    Pose pose;
    pose.T_reference_probe = trajectory.T_reference_probe(t);
    pose.T_reference_probe.translation() += options.position_noise_mm * position_noise;
    pose.T_reference_probe.linear() =
        rotation_from_vector(options.angle_noise_deg * kDegToRad * angle_noise) *
        pose.T_reference_probe.linear();
    pose.timestamp_s = t + options.latency_s;
    pose.status = t < invalid_until ? TrackingStatus::kInvalid : TrackingStatus::kValid;
    samples.push_back(pose);
  }
  return samples;
}

Pose interpolate_pose(const std::vector<Pose>& samples, double t_s, double max_gap_s) {
  Pose out;
  out.timestamp_s = t_s;
  out.status = TrackingStatus::kInvalid;
  if (samples.empty()) return out;
  const auto after = std::lower_bound(samples.begin(), samples.end(), t_s,
                                      [](const Pose& p, double t) { return p.timestamp_s < t; });
  if (after == samples.end() || (after == samples.begin() && after->timestamp_s > t_s)) {
    out.T_reference_probe =
        (after == samples.end() ? samples.back() : samples.front()).T_reference_probe;
    return out;
  }
  if (after->timestamp_s == t_s) {
    out.T_reference_probe = after->T_reference_probe;
    out.status = after->status;
    return out;
  }
  const Pose& a = *(after - 1);
  const Pose& b = *after;
  const double alpha = (t_s - a.timestamp_s) / (b.timestamp_s - a.timestamp_s);
  const Eigen::Quaterniond qa(a.T_reference_probe.linear()), qb(b.T_reference_probe.linear());
  out.T_reference_probe.linear() = qa.slerp(alpha, qb).toRotationMatrix();
  out.T_reference_probe.translation() =
      (1.0 - alpha) * a.T_reference_probe.translation() + alpha * b.T_reference_probe.translation();
  const bool valid = a.status == TrackingStatus::kValid && b.status == TrackingStatus::kValid &&
                     b.timestamp_s - a.timestamp_s <= max_gap_s;
  out.status = valid ? TrackingStatus::kValid : TrackingStatus::kInvalid;
  return out;
}

SimulatedAcquisition acquire(const Trajectory& trajectory, const TrackerOptions& tracker,
                             int frame_count, double frame_rate_hz) {
  if (frame_count < 1 || !(frame_rate_hz > 0.0))
    throw std::invalid_argument("acquire: need at least one frame and a positive frame rate");
  SimulatedAcquisition out;
  out.trajectory = trajectory.options();
  out.tracker = tracker;
  out.frame_rate_hz = frame_rate_hz;
  const double last_s = (frame_count - 1) / frame_rate_hz;
  // Tracker samples cover the frames' times shifted by the latency, with a margin.
  const double margin_s = 1.0 + std::abs(tracker.latency_s);
  out.tracker_samples = track(trajectory, tracker, -margin_s, last_s + margin_s);
  const double max_gap_s = 2.5 / tracker.rate_hz;
  for (int k = 0; k < frame_count; ++k) {
    const double t = k / frame_rate_hz;
    out.frame_times_s.push_back(t);
    out.true_poses.push_back(trajectory.T_reference_probe(t));
    out.tracked_poses.push_back(interpolate_pose(out.tracker_samples, t, max_gap_s));
  }
  return out;
}

}  // namespace sonoshape::simulator
