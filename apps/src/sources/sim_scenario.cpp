#include "sonoshape/apps/sim_scenario.hpp"

#include <map>
#include <sstream>

#include "../mesh_spec.hpp"
#include "sonoshape/core/mesh_io.hpp"

namespace sonoshape::apps {
namespace {

// Gap between the skin (top of the phantom's box) and the centre of the probe face.
constexpr double kConvexStandoffMm = 10.0;
constexpr double kLinearStandoffMm = 4.0;
// A translating sweep runs past the phantom's ends by this much on each side.
constexpr double kSweepMarginMm = 10.0;

Result<simulator::Phantom> build_phantom(const SimScenarioOptions& options,
                                         const std::filesystem::path& models_dir) {
  if (options.phantoms.empty()) return simulator::make_default_phantom(models_dir, options.size_mm);
  std::vector<apps::MeshSpec> specs;
  std::vector<TriangleMesh> meshes;
  for (const std::string& text : options.phantoms) {
    auto spec = apps::parse_mesh_spec(text, "--phantom");
    if (!spec) return spec.status();
    if (spec->label > kMaxPixelLabel)
      return Status::error("--phantom '" + text + "': labels go up to " +
                           std::to_string(kMaxPixelLabel) + " (label images are 8-bit)");
    auto mesh = read_mesh(spec->path);
    if (!mesh) return mesh.status();
    orient_outward(*mesh);
    specs.push_back(*spec);
    meshes.push_back(std::move(*mesh));
  }
  // One common scale keeps nested organs nested.
  const Eigen::Affine3d fit = simulator::fit_to_size(meshes, options.size_mm);
  simulator::Phantom phantom;
  for (std::size_t i = 0; i < specs.size(); ++i)
    phantom.add(specs[i].label, specs[i].name, meshes[i], fit);
  return phantom;
}

Status apply_tissues(const SimScenarioOptions& options, simulator::Phantom& phantom) {
  for (const std::string& text : options.tissues) {
    const std::size_t colon = text.find(':');
    int label = 0;
    try {
      label = std::stoi(text.substr(0, colon));
      if (colon == std::string::npos) throw std::invalid_argument("no preset");
      phantom.tissues[label] = simulator::tissue_preset(text.substr(colon + 1));
    } catch (const std::exception& e) {
      return Status::error("--tissue '" + text + "': " + e.what() +
                           " (expected LABEL:PRESET, e.g. 2:bone; presets: hypoechoic, "
                           "hyperechoic, isoechoic, cyst, bone, background)");
    }
    if (label == 0) phantom.background = phantom.tissues[0];
  }
  return Status::ok();
}

}  // namespace

std::vector<std::string> parse_phantom_spec(const std::string& spec) {
  std::vector<std::string> meshes;
  if (spec.empty() || spec == "default") return meshes;
  std::istringstream in(spec);
  std::string item;
  while (std::getline(in, item, ','))
    if (!item.empty()) meshes.push_back(item);
  return meshes;
}

Result<SimScenario> make_sim_scenario(const SimScenarioOptions& options, double duration_s,
                                      const std::filesystem::path& models_dir) {
  SimScenario scenario;
  auto phantom = build_phantom(options, models_dir);
  if (!phantom) return phantom.status();
  scenario.phantom = std::move(*phantom);
  if (const Status status = apply_tissues(options, scenario.phantom); !status) return status;
  scenario.probe = options.probe == "linear"
                       ? acquisition::linear_probe_geometry(options.width_px, options.height_px)
                       : acquisition::convex_probe_geometry(options.width_px, options.height_px);
  const Box3 box = scenario.phantom.bounds();

  simulator::TrajectoryOptions& motion = scenario.motion;
  try {
    motion.motion = simulator::parse_sweep_motion(options.trajectory);
  } catch (const std::invalid_argument& e) {
    return Status::error(std::string("--trajectory: ") + e.what());
  }
  motion.speed = options.speed == "constant"    ? simulator::SpeedProfile::kConstant
                 : options.speed == "irregular" ? simulator::SpeedProfile::kIrregular
                                                : simulator::SpeedProfile::kSmooth;
  motion.duration_s = duration_s;
  motion.passes = options.passes;
  motion.seed = options.seed;
  const double standoff = scenario.probe.type == acquisition::ProbeType::kConvex
                              ? kConvexStandoffMm
                              : kLinearStandoffMm;
  motion.T_reference_probe_centre.translation() = Vec3(
      0.5 * (box.min.x() + box.max.x()), box.min.y() - standoff, 0.5 * (box.min.z() + box.max.z()));
  motion.sweep_length_mm = options.sweep_length_mm > 0.0 ? options.sweep_length_mm
                                                         : box.size().z() + 2.0 * kSweepMarginMm;
  const std::map<simulator::SweepMotion, double> default_angle{
      {simulator::SweepMotion::kTranslate, 0.0},
      {simulator::SweepMotion::kFan, 60.0},
      {simulator::SweepMotion::kRock, 30.0},
      {simulator::SweepMotion::kRotate, 180.0}};
  motion.sweep_angle_deg =
      options.sweep_angle_deg > 0.0 ? options.sweep_angle_deg : default_angle.at(motion.motion);

  simulator::TrackerOptions& tracker = scenario.tracker;
  tracker.rate_hz = options.tracker_rate_hz;
  tracker.latency_s = 1e-3 * options.latency_ms;
  tracker.position_noise_mm = options.position_noise_mm;
  tracker.angle_noise_deg = options.angle_noise_deg;
  tracker.drop_probability = options.drop_probability;
  tracker.invalid_probability = options.invalid_probability;
  tracker.seed = options.seed + 1;
  return scenario;
}

}  // namespace sonoshape::apps
