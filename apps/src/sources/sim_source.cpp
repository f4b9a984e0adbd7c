// `sim:PHANTOM_SPEC`: a simulated probe and tracker sweeping a phantom.
#include "sonoshape/simulator/sim_source.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>

#include "sonoshape/apps/scan_sources.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/tracking/pose_source.hpp"

namespace sonoshape::apps {
namespace {

// Frames rendered (with their ground truth) to learn the simulated probe's grey-level models:
// spread over the sweep so that every organ is seen, and with enough of each organ's inside (6
// frames showed cheburashka's only as slivers at 512 x 512, no pixel of them inside it).
constexpr int kModelFrames = 12;
// The models are learnt from the pixels at least this many point-spread sigmas from another
// label: a small organ's boundary pixels are blurred towards its surroundings, and its mean
// with them lowered the boundary with the background.
constexpr double kInteriorPsfSigmas = 2.0;

// Label models of the simulated probe, learnt from a few frames and their ground truth (what a
// preset of a real probe holds). Names come from the phantom.
segmentation::SegmentationConfig learn_sim_models(const simulator::BModeSimulator& simulator,
                                                  const simulator::Trajectory& trajectory,
                                                  const segmentation::SegmentationConfig& base,
                                                  std::uint64_t seed) {
  const acquisition::Probe& probe = simulator.probe();
  const int w = probe.width_px(), h = probe.height_px();
  GreyImage grey(w, h * kModelFrames);
  LabelImage visible(w, h * kModelFrames);
  std::vector<std::array<int, 256>> caster_runs_px;
  for (int k = 0; k < kModelFrames; ++k) {
    const double t_s = trajectory.duration_s() * (k + 0.5) / kModelFrames;
    // Seeds apart from the scan's frames: the models must not have seen the frames they read.
    const simulator::SimulatedFrame frame =
        simulator.render(trajectory.T_reference_probe(t_s),
                         simulator::frame_seed(seed ^ 0x5EEDull, static_cast<std::size_t>(k)));
    std::copy(frame.bmode.pixels.begin(), frame.bmode.pixels.end(),
              grey.pixels.begin() + static_cast<std::ptrdiff_t>(k) * w * h);
    // Grey models from what the probe sees: not a bone's shadowed inside.
    const LabelImage shown = frame.visible_truth();
    std::copy(shown.pixels.begin(), shown.pixels.end(),
              visible.pixels.begin() + static_cast<std::ptrdiff_t>(k) * w * h);
    caster_runs_px.push_back(simulator::shadow_caster_runs_px(frame));
  }
  // Within two sigmas of the point-spread function of a boundary the grey mixes both sides'.
  const double interior_px = kInteriorPsfSigmas * simulator.psf_sigma_mm() / probe.spacing_mm();
  segmentation::SegmentationConfig config =
      segmentation::learn_label_models(grey, visible, base, interior_px);
  if (config.psf_sigma_mm < 0.0) {
    config.psf_sigma_mm = simulator.psf_sigma_mm();
    config.dynamic_range_db = simulator.options().dynamic_range_db;
  }
  const auto thickness = simulator::shadow_caster_thickness_mm(caster_runs_px, probe.spacing_mm());
  for (segmentation::LabelModel& m : config.materials)
    if (const auto t = thickness.find(m.label); t != thickness.end()) m.thickness_mm = t->second;
  return config;
}

// The segmentation of the simulated sweep: the given configuration or preset, with label models
// learnt from simulated frames where it has none; `models_from` says which.
Result<segmentation::SegmentationConfig> sim_segmentation(
    const scan::SourceRequest& request, const SimScenario& scenario,
    const simulator::BModeSimulator& simulator, const simulator::Trajectory& trajectory,
    std::uint64_t seed, std::string& models_from) {
  segmentation::SegmentationConfig base;
  models_from = "learnt from " + std::to_string(kModelFrames) + " simulated frames";
  if (request.segmentation || !request.preset.empty()) {
    auto read = segmentation::load_segmentation_config(request.segmentation, request.preset);
    if (!read) return read.status();
    base = std::move(*read);
    models_from =
        request.segmentation ? request.segmentation->string() : "preset " + request.preset;
  }
  if (base.materials.empty()) {
    for (const auto& m : scenario.phantom.meshes)
      if (std::none_of(base.materials.begin(), base.materials.end(),
                       [&](const segmentation::LabelModel& b) { return b.label == m.label; }))
        base.materials.push_back({m.label, m.name, 128.0, 25.0});
    base = learn_sim_models(simulator, trajectory, base, seed);
    if (request.segmentation) models_from += " (models learnt from simulated frames)";
  }
  if (const Status valid = base.validate(); !valid) return valid;
  return base;
}

// The simulated frames: `frame_count` of them, from the frame after `resume_after_frame`, the
// probe vanishing after `fail_after_s` (< 0: never), each frame's truth kept for scoring.
simulator::SimFrameOptions sim_frame_options(const SimScenarioOptions& options, int frame_count,
                                             std::optional<std::int64_t> resume_after_frame,
                                             double fail_after_s) {
  simulator::SimFrameOptions frame_options;
  frame_options.frame_rate_hz = options.frame_rate_hz;
  frame_options.frame_count = frame_count;
  frame_options.seed = options.seed;
  if (resume_after_frame)
    frame_options.first_frame =
        static_cast<long>(std::max<std::int64_t>(*resume_after_frame + 1, 0));
  if (fail_after_s >= 0.0)
    frame_options.fail_after_frames =
        static_cast<long>(std::floor(fail_after_s * options.frame_rate_hz));
  frame_options.truth = std::make_shared<simulator::FrameTruthStore>();
  return frame_options;
}

}  // namespace

Result<scan::ScanSource> open_sim_source(const scan::SourceRequest& request,
                                         const SimSourceOptions& sim,
                                         const std::string& phantom_spec) {
  SimScenarioOptions options = sim.scenario;
  options.phantoms = parse_phantom_spec(phantom_spec);
  if (!(sim.duration_s > 0.0) || !(options.frame_rate_hz > 0.0))
    return Status::error("sim: the sweep duration and the frame rate must be positive");
  const int frame_count = static_cast<int>(std::floor(sim.duration_s * options.frame_rate_hz)) + 1;
  const double duration_s = std::max(frame_count - 1, 1) / options.frame_rate_hz;
  auto scenario = make_sim_scenario(options, duration_s, sim.models_dir);
  if (!scenario) return scenario.status();

  scan::ScanSource source;
  scan::ScanSetup& setup = source.setup;
  std::shared_ptr<const simulator::BModeSimulator> simulator;
  try {
    simulator = std::make_shared<const simulator::BModeSimulator>(
        scenario->phantom, acquisition::Probe(scenario->probe));
  } catch (const GeometryError& e) {
    return Status::error(std::string("sim: ") + e.what());
  }
  const acquisition::Probe& probe = simulator->probe();
  const simulator::Trajectory trajectory(scenario->motion);

  // Calibration: the simulated probe's own, unless the user gives one (to study a bad one).
  setup.T_probe_image = probe.T_probe_image().matrix();
  setup.calibration_from = "the simulated probe";
  if (request.calibration) {
    auto read = segmentation::read_calibration(*request.calibration);
    if (!read) return read.status();
    setup.T_probe_image = *read;
    setup.calibration_from = request.calibration->string();
  }
  auto geometry = segmentation::geometry_from_header(acquisition::probe_fields(probe));
  if (!geometry) return geometry.status();
  setup.geometry = std::move(*geometry);
  setup.sector_from = "the simulated probe (" + acquisition::to_string(probe.type()) + ")";

  auto config =
      sim_segmentation(request, *scenario, *simulator, trajectory, options.seed, setup.models_from);
  if (!config) return config.status();
  setup.segmentation = std::move(*config);
  for (const int label : scenario->phantom.labels()) {
    std::string name;
    for (const auto& m : scenario->phantom.meshes)
      if (m.label == label) name = m.name;
    setup.labels.push_back({label, name, simulator->casts_shadow(label)});
  }
  const Box3 box = scenario->phantom.bounds();
  setup.bounds = request.bounds ? *request.bounds : box.padded(0.1 * box.diagonal());

  const simulator::SimFrameOptions frame_options =
      sim_frame_options(options, frame_count, request.resume_after_frame, sim.fail_after_s);
  source.device_origin_s = static_cast<double>(frame_options.first_frame) / options.frame_rate_hz;
  source.truth_of_frame = [truth = frame_options.truth](std::int64_t index) {
    return truth->take(index);
  };
  const std::string name = "sim:" + (phantom_spec.empty() ? std::string("default") : phantom_spec);
  source.frames =
      std::make_unique<simulator::SimFrameSource>(simulator, trajectory, frame_options, name);
  // The tracker samples the whole sweep (and a margin for its latency), as simulator::acquire does.
  const double margin_s = 1.0 + std::abs(scenario->tracker.latency_s);
  source.poses = std::make_unique<tracking::RecordedPoseSource>(
      simulator::track(trajectory, scenario->tracker, -margin_s, duration_s + margin_s),
      name + " (tracker)");
  source.tracker_latency_s = scenario->tracker.latency_s;
  std::ostringstream text;
  text << "simulated " << acquisition::to_string(probe.type()) << " probe " << probe.width_px()
       << "x" << probe.height_px() << " at " << options.frame_rate_hz << " fps, "
       << options.trajectory << " of " << duration_s << " s (" << frame_count << " frames), "
       << scenario->phantom.labels().size() << " labels, tracker " << scenario->tracker.rate_hz
       << " Hz; models " << setup.models_from;
  source.description = text.str();
  return source;
}

}  // namespace sonoshape::apps
