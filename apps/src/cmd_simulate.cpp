// `sonoshape simulate`: a virtual patient scanned freehand with a tracked probe, written as a
// PLUS sequence file (B-mode frames, tracked poses, calibration and sector in the header), a
// sidecar PLUS configuration, and optionally the ground truth (placed meshes, label frames).
#include <CLI/CLI.hpp>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>

#include "commands.hpp"
#include "option_checks.hpp"
#include "sim_options.hpp"
#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/apps/sim_scenario.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace sonoshape::apps {
namespace {

struct SimulateOptions {
  SimScenarioOptions scenario;
  int frames = 200;
  std::filesystem::path output = "sweep.igs.mha";
  std::filesystem::path truth_dir;
  bool raw = false;
};

// "sweep.igs.mha" -> "sweep.plus.xml" next to it.
std::filesystem::path sidecar_path(const std::filesystem::path& output) {
  std::string name = output.filename().string();
  for (const std::string ext : {".igs.mha", ".seq.mha", ".mha"})
    if (name.size() > ext.size() && name.ends_with(ext)) {
      name.resize(name.size() - ext.size());
      break;
    }
  return output.parent_path() / (name + ".plus.xml");
}

// The truth of a simulated sweep in `directory`: the phantom's meshes (label_<id>.ply) and the
// label frames (labels.mha).
Status write_truth(const std::filesystem::path& directory, const simulator::Phantom& phantom,
                   const simulator::SimulatedSweep& sweep,
                   const acquisition::SequenceWriteOptions& options) {
  std::error_code ec;
  std::filesystem::create_directories(directory, ec);
  if (ec)
    return Status::error("cannot create the --truth directory " + directory.string() + ": " +
                         ec.message());
  for (const auto& entry : phantom.mesh_set().meshes) {
    const auto path = directory / ("label_" + std::to_string(entry.label) + ".ply");
    if (const Status written = write_mesh(entry.mesh, path); !written) return written;
  }
  return acquisition::write_sequence_file(sweep.truth, directory / "labels.mha", options);
}

int run_simulate(const SimulateOptions& options) {
  Stopwatch clock;
  const SimScenarioOptions& scenario_options = options.scenario;
  const double duration_s = std::max(options.frames - 1, 1) / scenario_options.frame_rate_hz;
  auto scenario = make_sim_scenario(scenario_options, duration_s,
                                    std::filesystem::path(SONOSHAPE_DATA_DIR) / "models");
  if (!scenario) {
    std::cerr << "error: " << scenario.message() << '\n';
    return 1;
  }
  const simulator::Phantom* phantom = &scenario->phantom;
  const acquisition::Probe probe(scenario->probe);
  const simulator::TrackerOptions& tracker = scenario->tracker;

  const simulator::SimulatedAcquisition acquisition =
      simulator::acquire(simulator::Trajectory(scenario->motion), tracker, options.frames,
                         scenario_options.frame_rate_hz);
  const simulator::BModeSimulator simulator(*phantom, probe);
  simulator::SimulatedSweep sweep;
  {
    Progress progress("simulate", static_cast<std::size_t>(options.frames));
    sweep = simulator::simulate_sweep(simulator, acquisition, scenario_options.seed,
                                      [&](std::size_t done) { progress.update(done); });
  }
  const double render_s = clock.seconds();

  std::error_code ec;
  if (!options.output.parent_path().empty())
    std::filesystem::create_directories(options.output.parent_path(), ec);
  const acquisition::SequenceWriteOptions write_options{!options.raw, 1};
  if (const Status written =
          acquisition::write_sequence_file(sweep.bmode, options.output, write_options);
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  acquisition::PlusConfig config;
  config.transforms.push_back(
      {"Image", "Probe", probe.T_probe_image().matrix(), std::nullopt, "simulated"});
  const auto sidecar = sidecar_path(options.output);
  if (const Status written = acquisition::write_plus_config(
          config, sidecar,
          "sonoshape simulate: calibration of " + options.output.filename().string());
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  if (!options.truth_dir.empty())
    if (const Status written = write_truth(options.truth_dir, *phantom, sweep, write_options);
        !written) {
      std::cerr << "error: " << written.message() << '\n';
      return 1;
    }

  std::size_t invalid = 0;
  for (const Pose& pose : acquisition.tracked_poses)
    invalid += pose.status == TrackingStatus::kInvalid ? 1 : 0;
  std::ostringstream summary;
  summary << "simulate: " << phantom->labels().size() << " labels, "
          << acquisition::to_string(probe.type()) << " probe, " << scenario_options.trajectory
          << ", " << options.frames << " frames of " << scenario_options.width_px << "x"
          << scenario_options.height_px << " (" << invalid << " with INVALID pose, "
          << static_cast<int>(100.0 * sweep.mean_shadow_fraction + 0.5)
          << "% of the sector shadowed) in " << clock.seconds() << " s (render " << render_s
          << " s) -> " << options.output.string() << ", " << sidecar.string();
  if (!options.truth_dir.empty()) summary << ", truth in " << options.truth_dir.string();
  log_info(summary.str());
  return 0;
}

}  // namespace

CommandRunner add_simulate_command(CLI::App& app) {
  auto options = std::make_shared<SimulateOptions>();
  add_sim_scenario_options(app, options->scenario, SimOptionsFor::simulate);
  app.add_option("--frames", options->frames, "Number of frames")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("-o,--output", options->output,
                 "Sequence file to write (.igs.mha); the calibration goes next to it as "
                 "<name>.plus.xml")
      ->capture_default_str();
  app.add_option("--truth", options->truth_dir,
                 "Directory for the ground truth: label_<id>.ply (placed meshes, mm) and "
                 "labels.mha (label frames, 255 unknown)");
  app.add_flag("--raw", options->raw, "Write uncompressed pixels (faster, larger)");
  return [options] { return run_simulate(*options); };
}

}  // namespace sonoshape::apps
