#pragma once
// Freehand probe motion and the tracker's view of it. The trajectory is a continuous function
// of time (the truth); the tracker samples it at its own rate with latency, noise, dropped
// samples and INVALID bursts; frames get their pose by interpolating the tracker's samples, as
// PLUS does.
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "sonoshape/core/frame.hpp"
#include "sonoshape/core/geometry.hpp"

namespace sonoshape::simulator {

/// The sonographer's manoeuvre (probe frame: x along the array, y along the beam, z normal to
/// the image, see probe.hpp).
enum class SweepMotion {
  kTranslate,  ///< slide along z: parallel planes ("sweep")
  kFan,        ///< tilt about the array axis x at the face: planes fan out through the body
  kRock,       ///< tilt about z at the face: the image rotates within its own plane
  kRotate,     ///< turn about the beam axis y: planes share the central beam line
};

/// Parses "sweep" | "translate" | "fan" | "rock" | "rotate"; throws std::invalid_argument.
SweepMotion parse_sweep_motion(const std::string& name);

/// How the sweep's progress advances in time.
enum class SpeedProfile {
  kConstant,   ///< uniform speed
  kSmooth,     ///< starts and stops gently (raised cosine)
  kIrregular,  ///< a hand's uneven speed: random smooth variations, never stopping
};

struct TrajectoryOptions {
  SweepMotion motion = SweepMotion::kTranslate;
  /// Probe pose halfway through the sweep (probe -> reference).
  Eigen::Isometry3d T_reference_probe_centre = Eigen::Isometry3d::Identity();
  double duration_s = 10.0;
  /// The hand goes over the anatomy this many times, back and forth, each pass taking
  /// duration_s / passes (a long examination revisits the same planes); 1: one sweep.
  int passes = 1;
  double sweep_length_mm = 80.0;  ///< kTranslate: total travel along z
  double sweep_angle_deg = 60.0;  ///< kFan, kRock, kRotate: total angle
  SpeedProfile speed = SpeedProfile::kSmooth;
  /// Physiological hand tremor (8-12 Hz), RMS per axis; 0 turns it off.
  double tremor_mm = 0.15;
  double tremor_deg = 0.15;
  /// Slow wandering of the hand (0.1-0.5 Hz), amplitude per axis.
  double drift_mm = 1.5;
  double drift_deg = 1.5;
  std::uint64_t seed = 1;
};

/// The true probe pose as a function of time, deterministic for the options' seed.
class Trajectory {
 public:
  /// Throws std::invalid_argument for a non-positive duration or fewer than one pass.
  explicit Trajectory(const TrajectoryOptions& options);

  const TrajectoryOptions& options() const { return options_; }
  double duration_s() const { return options_.duration_s; }
  /// Sweep progress in [0, 1] at time t (clamped outside [0, duration]); with several passes
  /// it runs 0 -> 1 on even passes and 1 -> 0 on odd ones.
  double progress(double t_s) const;
  /// The probe's true pose at time t (s); before 0 and after the duration the sweep holds
  /// still but the hand keeps trembling.
  Eigen::Isometry3d T_reference_probe(double t_s) const;

 private:
  /// Progress through one pass at x in [0, 1] of it, shaped by the speed profile.
  double pass_progress(double x) const;
  struct Wave {
    double amplitude = 0.0, frequency_hz = 0.0, phase = 0.0;
  };
  TrajectoryOptions options_;
  std::vector<Wave> speed_waves_;
  std::vector<Wave> hand_waves_[6];  // x, y, z (mm) then rotation about x, y, z (deg)
};

/// The tracker: its clock, latency and errors.
struct TrackerOptions {
  double rate_hz = 40.0;  ///< sampling rate (independent of the frame rate)
  /// A measurement of the pose at true time t is stamped t + latency_s (relative to the
  /// frames' clock): interpolating at a frame's time then gives the pose latency_s earlier.
  double latency_s = 0.0;
  double position_noise_mm = 0.1;  ///< Gaussian, standard deviation per axis
  double angle_noise_deg = 0.05;   ///< Gaussian rotation vector, standard deviation per axis
  double drop_probability = 0.01;  ///< chance that a sample never arrives
  /// Chance per sample that an INVALID burst (sensor out of range) starts.
  double invalid_probability = 0.005;
  double invalid_burst_s = 0.25;  ///< length of an INVALID burst
  std::uint64_t seed = 2;
};

/// The tracker's samples over [start_s, end_s] (true time), in time order: dropped samples are
/// missing, INVALID ones carry status kInvalid (and a pose no one should use). Deterministic for
/// the options' seed.
std::vector<Pose> track(const Trajectory& trajectory, const TrackerOptions& options, double start_s,
                        double end_s);

/// The pose at time t interpolated between the tracker samples around it (linear position,
/// spherical rotation). kInvalid when t is outside the samples, a neighbour is INVALID, or the
/// neighbours are more than max_gap_s apart (dropped samples).
Pose interpolate_pose(const std::vector<Pose>& samples, double t_s, double max_gap_s);

/// A whole acquisition: frame times at frame_rate_hz from 0, the true pose of each frame, and
/// the tracked pose the frame gets from the tracker.
struct SimulatedAcquisition {
  TrajectoryOptions trajectory;
  TrackerOptions tracker;
  double frame_rate_hz = 20.0;
  std::vector<double> frame_times_s;
  std::vector<Eigen::Isometry3d> true_poses;  ///< T_reference_probe at each frame's time
  std::vector<Pose> tracked_poses;            ///< what the tracker says at each frame's time
  std::vector<Pose> tracker_samples;          ///< the raw tracker stream
};

/// Runs `trajectory` for `frame_count` frames at `frame_rate_hz` and tracks it. max_gap: 2.5
/// tracker periods.
SimulatedAcquisition acquire(const Trajectory& trajectory, const TrackerOptions& tracker,
                             int frame_count, double frame_rate_hz);

}  // namespace sonoshape::simulator
