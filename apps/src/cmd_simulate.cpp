// `sonoshape simulate`: a virtual patient scanned freehand with a tracked probe, written as a
// PLUS sequence file (B-mode frames, tracked poses, calibration and sector in the header), a
// sidecar PLUS configuration, and optionally the ground truth (placed meshes, label frames).
#include <CLI/CLI.hpp>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>

#include "commands.hpp"
#include "mesh_spec.hpp"
#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/publish/mesh_writer.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/mesh_reader.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace sonoshape::apps {
namespace {

// Gap between the skin (top of the phantom's box) and the centre of the probe face.
constexpr double kConvexStandoffMm = 10.0;
constexpr double kLinearStandoffMm = 4.0;
// A translating sweep runs past the phantom's ends by this much on each side.
constexpr double kSweepMarginMm = 10.0;

struct SimulateOptions {
  std::vector<std::string> phantoms;
  std::vector<std::string> tissues;
  double size_mm = 120.0;
  std::string probe = "convex";
  std::string trajectory = "sweep";
  std::string speed = "smooth";
  int frames = 200;
  double frame_rate_hz = 20.0;
  int width_px = 512;
  int height_px = 512;
  std::uint64_t seed = 1;
  double sweep_length_mm = 0.0;  // 0: the phantom's length plus margins
  double sweep_angle_deg = 0.0;  // 0: per trajectory (fan 60, rock 30, rotate 180)
  double tracker_rate_hz = 40.0;
  double latency_ms = 0.0;
  double position_noise_mm = 0.1;
  double angle_noise_deg = 0.05;
  double drop_probability = 0.01;
  double invalid_probability = 0.005;
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

Result<sim::Phantom> build_phantom(const SimulateOptions& options) {
  if (options.phantoms.empty())
    return sim::make_default_phantom(std::filesystem::path(SONOSHAPE_DATA_DIR) / "models",
                                     options.size_mm);
  std::vector<MeshSpec> specs;
  std::vector<TriangleMesh> meshes;
  for (const std::string& text : options.phantoms) {
    auto spec = parse_mesh_spec(text, "--phantom");
    if (!spec) return spec.status();
    if (spec->label > kMaxPixelLabel)
      return Status::error("--phantom '" + text + "': labels go up to " +
                           std::to_string(kMaxPixelLabel) + " (label images are 8-bit)");
    auto mesh = sim::read_mesh(spec->path);
    if (!mesh) return mesh.status();
    sim::orient_outward(*mesh);
    specs.push_back(*spec);
    meshes.push_back(std::move(*mesh));
  }
  // One common scale keeps nested organs nested.
  const Eigen::Affine3d fit = sim::fit_to_size(meshes, options.size_mm);
  sim::Phantom phantom;
  for (std::size_t i = 0; i < specs.size(); ++i)
    phantom.add(specs[i].label, specs[i].name, meshes[i], fit);
  return phantom;
}

Status apply_tissues(const SimulateOptions& options, sim::Phantom& phantom) {
  for (const std::string& text : options.tissues) {
    const std::size_t colon = text.find(':');
    int label = 0;
    try {
      label = std::stoi(text.substr(0, colon));
      if (colon == std::string::npos) throw std::invalid_argument("no preset");
      phantom.tissues[label] = sim::tissue_preset(text.substr(colon + 1));
    } catch (const std::exception& e) {
      return Status::error("--tissue '" + text + "': " + e.what() +
                           " (expected LABEL:PRESET, e.g. 2:bone; presets: hypoechoic, "
                           "hyperechoic, isoechoic, cyst, bone, background)");
    }
    if (label == 0) phantom.background = phantom.tissues[0];
  }
  return Status::ok();
}

int run_simulate(const SimulateOptions& options) {
  Stopwatch clock;
  auto phantom = build_phantom(options);
  if (!phantom) {
    std::cerr << "error: " << phantom.message() << '\n';
    return 1;
  }
  if (const Status status = apply_tissues(options, *phantom); !status) {
    std::cerr << "error: " << status.message() << '\n';
    return 1;
  }
  sim::ProbeGeometry geometry =
      options.probe == "linear" ? sim::linear_probe_geometry(options.width_px, options.height_px)
                                : sim::convex_probe_geometry(options.width_px, options.height_px);
  const sim::Probe probe(geometry);
  const Box3 box = phantom->bounds();

  sim::TrajectoryOptions motion;
  motion.motion = sim::parse_sweep_motion(options.trajectory);
  motion.speed = options.speed == "constant"    ? sim::SpeedProfile::kConstant
                 : options.speed == "irregular" ? sim::SpeedProfile::kIrregular
                                                : sim::SpeedProfile::kSmooth;
  motion.duration_s = std::max(options.frames - 1, 1) / options.frame_rate_hz;
  motion.seed = options.seed;
  const double standoff =
      probe.type() == sim::ProbeType::kConvex ? kConvexStandoffMm : kLinearStandoffMm;
  motion.T_reference_probe_centre.translation() = Vec3(
      0.5 * (box.min.x() + box.max.x()), box.min.y() - standoff, 0.5 * (box.min.z() + box.max.z()));
  motion.sweep_length_mm = options.sweep_length_mm > 0.0 ? options.sweep_length_mm
                                                         : box.size().z() + 2.0 * kSweepMarginMm;
  const std::map<sim::SweepMotion, double> default_angle{{sim::SweepMotion::kTranslate, 0.0},
                                                         {sim::SweepMotion::kFan, 60.0},
                                                         {sim::SweepMotion::kRock, 30.0},
                                                         {sim::SweepMotion::kRotate, 180.0}};
  motion.sweep_angle_deg =
      options.sweep_angle_deg > 0.0 ? options.sweep_angle_deg : default_angle.at(motion.motion);

  sim::TrackerOptions tracker;
  tracker.rate_hz = options.tracker_rate_hz;
  tracker.latency_s = 1e-3 * options.latency_ms;
  tracker.position_noise_mm = options.position_noise_mm;
  tracker.angle_noise_deg = options.angle_noise_deg;
  tracker.drop_probability = options.drop_probability;
  tracker.invalid_probability = options.invalid_probability;
  tracker.seed = options.seed + 1;

  const sim::SimulatedAcquisition acquisition =
      sim::acquire(sim::Trajectory(motion), tracker, options.frames, options.frame_rate_hz);
  const sim::BModeSimulator simulator(*phantom, probe);
  sim::SimulatedSweep sweep;
  {
    Progress progress("simulate", static_cast<std::size_t>(options.frames));
    sweep = sim::simulate_sweep(simulator, acquisition, options.seed,
                                [&](std::size_t done) { progress.update(done); });
  }
  const double render_s = clock.seconds();

  std::error_code ec;
  if (!options.output.parent_path().empty())
    std::filesystem::create_directories(options.output.parent_path(), ec);
  const acq::SequenceWriteOptions write_options{!options.raw, 1};
  if (const Status written = acq::write_sequence_file(sweep.bmode, options.output, write_options);
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  acq::PlusConfig config;
  config.transforms.push_back(
      {"Image", "Probe", probe.T_probe_image().matrix(), std::nullopt, "simulated"});
  const auto sidecar = sidecar_path(options.output);
  if (const Status written = acq::write_plus_config(
          config, sidecar,
          "sonoshape simulate: calibration of " + options.output.filename().string());
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  if (!options.truth_dir.empty()) {
    std::filesystem::create_directories(options.truth_dir, ec);
    if (ec) {
      std::cerr << "error: cannot create the --truth directory " << options.truth_dir.string()
                << ": " << ec.message() << '\n';
      return 1;
    }
    for (const auto& entry : phantom->mesh_set().meshes) {
      const auto path = options.truth_dir / ("label_" + std::to_string(entry.label) + ".ply");
      if (const Status written = publish::write_mesh(entry.mesh, path); !written) {
        std::cerr << "error: " << written.message() << '\n';
        return 1;
      }
    }
    if (const Status written =
            acq::write_sequence_file(sweep.truth, options.truth_dir / "labels.mha", write_options);
        !written) {
      std::cerr << "error: " << written.message() << '\n';
      return 1;
    }
  }

  std::size_t invalid = 0;
  for (const Pose& pose : acquisition.tracked_poses)
    invalid += pose.status == TrackingStatus::kInvalid ? 1 : 0;
  std::ostringstream summary;
  summary << "simulate: " << phantom->labels().size() << " labels, " << sim::to_string(probe.type())
          << " probe, " << options.trajectory << ", " << options.frames << " frames of "
          << options.width_px << "x" << options.height_px << " (" << invalid
          << " with INVALID pose, " << static_cast<int>(100.0 * sweep.mean_shadow_fraction + 0.5)
          << "% of the sector shadowed) in " << clock.seconds() << " s (render " << render_s
          << " s) -> " << options.output.string() << ", " << sidecar.string();
  if (!options.truth_dir.empty()) summary << ", truth in " << options.truth_dir.string();
  log_info(summary.str());
  return 0;
}

}  // namespace

CommandRunner add_simulate_command(CLI::App& app) {
  auto options = std::make_shared<SimulateOptions>();
  app.add_option("--phantom", options->phantoms,
                 "Closed organ mesh, LABEL:PATH[:NAME] (.obj, .ply, .off); repeat for more "
                 "(organs may nest). Default: spot and cheburashka from data/models with a rib");
  app.add_option("--phantom-size-mm", options->size_mm,
                 "Scale the phantom (one common scale) so its box diagonal is this many mm")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--tissue", options->tissues,
                 "Tissue of a label, LABEL:PRESET (hypoechoic, hyperechoic, isoechoic, cyst, "
                 "bone; label 0 = background); default: odd labels dark, even bright");
  app.add_option("--probe", options->probe, "Probe geometry")
      ->check(CLI::IsMember({"linear", "convex"}))
      ->capture_default_str();
  app.add_option("--trajectory", options->trajectory,
                 "Freehand motion: sweep (slide), fan (tilt across), rock (tilt in plane), "
                 "rotate (about the beam)")
      ->check(CLI::IsMember({"sweep", "fan", "rock", "rotate"}))
      ->capture_default_str();
  app.add_option("--speed", options->speed, "Speed profile of the hand")
      ->check(CLI::IsMember({"constant", "smooth", "irregular"}))
      ->capture_default_str();
  app.add_option("--frames", options->frames, "Number of frames")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--frame-rate", options->frame_rate_hz, "Frames per second")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--width-px", options->width_px, "Image width")
      ->check(CLI::Range(16, 4096))
      ->capture_default_str();
  app.add_option("--height-px", options->height_px, "Image height")
      ->check(CLI::Range(16, 4096))
      ->capture_default_str();
  app.add_option("--seed", options->seed, "Seed of the hand, tracker and speckle")
      ->capture_default_str();
  app.add_option("--sweep-length-mm", options->sweep_length_mm,
                 "Travel of a sweep (default: the phantom's length + 20 mm)")
      ->check(CLI::PositiveNumber);
  app.add_option("--sweep-angle-deg", options->sweep_angle_deg,
                 "Total angle of fan / rock / rotate (default 60 / 30 / 180)")
      ->check(CLI::PositiveNumber);
  app.add_option("--tracker-rate", options->tracker_rate_hz, "Tracker samples per second")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--latency-ms", options->latency_ms, "Tracker latency relative to the frames (ms)")
      ->capture_default_str();
  app.add_option("--position-noise-mm", options->position_noise_mm,
                 "Tracker position noise, sigma per axis")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--angle-noise-deg", options->angle_noise_deg,
                 "Tracker angle noise, sigma per axis")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--drop", options->drop_probability, "Share of tracker samples lost")
      ->check(CLI::Range(0.0, 0.9))
      ->capture_default_str();
  app.add_option("--invalid", options->invalid_probability,
                 "Chance per tracker sample that an INVALID burst starts")
      ->check(CLI::Range(0.0, 1.0))
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
