#pragma once
// A simulated patient, probe, hand and tracker, as `sonoshape simulate` and the `sim:` source of
// `sonoshape scan` build them from their options.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "sonoshape/acquisition/probe.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace sonoshape::apps {

/// The options of a simulated scan (the names of `sonoshape simulate`'s options).
struct SimScenarioOptions {
  std::vector<std::string> phantoms;  ///< LABEL:PATH[:NAME] meshes; empty: the built-in demo
  std::vector<std::string> tissues;   ///< LABEL:PRESET
  double size_mm = 120.0;             ///< phantom box diagonal
  std::string probe = "convex";       ///< linear | convex
  std::string trajectory = "sweep";   ///< sweep | fan | rock | rotate
  std::string speed = "smooth";       ///< constant | smooth | irregular
  double frame_rate_hz = 20.0;
  int width_px = 512;
  int height_px = 512;
  std::uint64_t seed = 1;
  double sweep_length_mm = 0.0;  ///< 0: the phantom's length plus margins
  double sweep_angle_deg = 0.0;  ///< 0: per trajectory (fan 60, rock 30, rotate 180)
  int passes = 1;                ///< back-and-forth passes over the sweep's duration
  double tracker_rate_hz = 40.0;
  double latency_ms = 0.0;  ///< the simulated tracker's latency
  double position_noise_mm = 0.1;
  double angle_noise_deg = 0.05;
  double drop_probability = 0.01;
  double invalid_probability = 0.005;
};

/// Everything a simulation needs.
struct SimScenario {
  simulator::Phantom phantom;
  acquisition::ProbeGeometry probe;
  simulator::TrajectoryOptions motion;
  simulator::TrackerOptions tracker;
};

/// Builds the scenario of a sweep lasting `duration_s`: the phantom (the options' meshes, one
/// common scale, or the built-in demo from `models_dir`), tissues, probe, the trajectory placed
/// above the phantom, and the tracker (seeded by seed + 1). Fails, saying which option is
/// wrong, for unreadable meshes and bad tissue specs.
Result<SimScenario> make_sim_scenario(const SimScenarioOptions& options, double duration_s,
                                      const std::filesystem::path& models_dir);

/// Splits the PHANTOM_SPEC of `sim:PHANTOM_SPEC`: empty or "default" is the built-in demo (no
/// meshes); otherwise comma-separated LABEL:PATH[:NAME] meshes.
std::vector<std::string> parse_phantom_spec(const std::string& spec);

}  // namespace sonoshape::apps
