#pragma once
// The command-line options of a simulated scan, shared by `sonoshape simulate` and the `sim:`
// source of `sonoshape scan` (same names, same meaning).
#include <CLI/CLI.hpp>

#include "option_checks.hpp"
#include "sonoshape/apps/sim_scenario.hpp"

namespace sonoshape::apps {

/// Where the simulator's options are registered: `simulate` (with --phantom) or the `sim:`
/// source of `scan` (the phantom comes from sim:PHANTOM_SPEC; --seed and --speed say where
/// that command's other seeds and speeds went).
enum class SimOptionsFor { simulate, scan };

namespace detail {

/// The phantom: its meshes (`simulate` only), size and tissues.
inline void add_phantom_options(CLI::App& app, SimScenarioOptions& options, bool with_phantom) {
  if (with_phantom)
    app.add_option("--phantom", options.phantoms,
                   "Closed organ mesh, LABEL:PATH[:NAME] (.obj, .ply, .off, .stl); repeat for more "
                   "(organs may nest). Default: spot and cheburashka from data/models with a rib");
  app.add_option("--phantom-size-mm", options.size_mm,
                 "Scale the phantom (one common scale) so its box diagonal is this many mm")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--tissue", options.tissues,
                 "Tissue of a label, LABEL:PRESET (hypoechoic, hyperechoic, isoechoic, cyst, "
                 "bone; label 0 = background); default: odd labels dark, even bright");
}

/// The probe, the hand's motion and the images. `scan` once read --seed as an organ point and
/// --speed as the playback factor: a value of that shape gets the new name instead of a bare
/// conversion error.
inline void add_probe_and_hand_options(CLI::App& app, SimScenarioOptions& options,
                                       SimOptionsFor command) {
  const CLI::Validator not_an_organ_seed(
      [command](std::string& value) -> std::string {
        if (command == SimOptionsFor::scan && value.find(':') != std::string::npos)
          return "--seed is the simulator's random seed; a point inside an organ is "
                 "--organ-seed LABEL:X,Y,Z";
        return {};
      },
      "");
  const CLI::Validator not_a_playback_factor(
      [command](std::string& value) -> std::string {
        if (command == SimOptionsFor::scan && !value.empty() &&
            value.find_first_not_of("0123456789.eE+-") == std::string::npos)
          return "--speed is the simulated hand's speed profile (constant, smooth, irregular); "
                 "the real-time factor of playback is --playback-speed";
        return {};
      },
      "");
  app.add_option("--probe", options.probe, "Probe geometry")
      ->check(CLI::IsMember({"linear", "convex"}))
      ->capture_default_str();
  app.add_option("--trajectory", options.trajectory,
                 "Freehand motion: sweep (slide), fan (tilt across), rock (tilt in plane), "
                 "rotate (about the beam)")
      ->check(CLI::IsMember({"sweep", "fan", "rock", "rotate"}))
      ->capture_default_str();
  app.add_option("--speed", options.speed, "Speed profile of the hand")
      ->check(not_a_playback_factor)
      ->check(CLI::IsMember({"constant", "smooth", "irregular"}))
      ->capture_default_str();
  app.add_option("--frame-rate", options.frame_rate_hz, "Frames per second")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--width-px", options.width_px, "Image width")
      ->check(number_in(16, 4096))
      ->capture_default_str();
  app.add_option("--height-px", options.height_px, "Image height")
      ->check(number_in(16, 4096))
      ->capture_default_str();
  app.add_option("--seed", options.seed, "Seed of the hand, tracker and speckle")
      ->check(not_an_organ_seed)
      ->capture_default_str();
  app.add_option("--sweep-length-mm", options.sweep_length_mm,
                 "Travel of a sweep (default: the phantom's length + 20 mm)")
      ->check(kPositiveNumber);
  app.add_option("--sweep-angle-deg", options.sweep_angle_deg,
                 "Total angle of fan / rock / rotate (default 60 / 30 / 180)")
      ->check(kPositiveNumber);
  app.add_option("--passes", options.passes,
                 "Go over the anatomy this many times, back and forth, within the sweep's "
                 "duration (a long examination revisiting the same planes)")
      ->check(kPositiveNumber)
      ->capture_default_str();
}

/// The simulated tracker: rate, latency, noise, losses.
inline void add_tracker_options(CLI::App& app, SimScenarioOptions& options) {
  app.add_option("--tracker-rate", options.tracker_rate_hz, "Tracker samples per second")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--latency-ms", options.latency_ms,
                 "Simulated tracker latency relative to the frames (ms)")
      ->check(kFiniteNumber)
      ->capture_default_str();
  app.add_option("--position-noise-mm", options.position_noise_mm,
                 "Tracker position noise, sigma per axis")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
  app.add_option("--angle-noise-deg", options.angle_noise_deg,
                 "Tracker angle noise, sigma per axis")
      ->check(kNonNegativeNumber)
      ->capture_default_str();
  app.add_option("--drop", options.drop_probability, "Share of tracker samples lost")
      ->check(number_in(0.0, 0.9))
      ->capture_default_str();
  app.add_option("--invalid", options.invalid_probability,
                 "Chance per tracker sample that an INVALID burst starts")
      ->check(number_in(0.0, 1.0))
      ->capture_default_str();
}

}  // namespace detail

/// Registers the options of `options` on `app` (an app or an option group).
inline void add_sim_scenario_options(CLI::App& app, SimScenarioOptions& options,
                                     SimOptionsFor command) {
  detail::add_phantom_options(app, options, command == SimOptionsFor::simulate);
  detail::add_probe_and_hand_options(app, options, command);
  detail::add_tracker_options(app, options);
}

}  // namespace sonoshape::apps
