// sonoshape_keyframe_bench: how many slices keyframe selection keeps from a long freehand sweep,
// and what the reconstruction loses for it. The defaults of tracking::KeyframeOptions come from
// this table (docs/benchmarks.md, "Keyframes").
//
//   sonoshape_keyframe_bench [--trajectory sweep|fan] [--duration-s 60] [--fps 30] [--depth 6]
//                            [--passes 1] [--slice-budget N] [--every K ...]
//                            [ANGLE_DEG:DISTANCE_MM ...]
//
// --passes N: the hand goes back and forth N times in the duration, as in a long examination;
// a second table then gives the slices kept by the end of each minute (does the count level off
// once the anatomy is covered?). --slice-budget N selects with KeyframeOptions::slice_budget
// (scan --slice-budget): past N slices, only planes beyond twice the thresholds are new.
//
// The built-in demo phantom is swept by the default 512x512 convex probe (the `scan` defaults:
// smooth speed, hand tremor and drift, a 40 Hz tracker with noise, drops and INVALID bursts).
// Frames choose keyframes from their *tracked* plane, as the pipeline does; every keyframe's
// slice is the exact cut of the phantom at the frame's true pose with the sector as field of
// view, so the table isolates the effect of the selection from segmentation and tracking
// errors. Each row reconstructs its slices offline (recon::reconstruct) and scores the meshes
// against the phantom (IoU on a 100^3 grid over the phantom's box).
#include <algorithm>
#include <charconv>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "sonoshape/acquisition/probe.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/mesh_slicer.hpp"
#include "sonoshape/recon/reconstruct.hpp"
#include "sonoshape/simulator/evaluation.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/trajectory.hpp"
#include "sonoshape/tracking/keyframes.hpp"

namespace {

using namespace sonoshape;

struct Row {
  std::string rule;
  std::vector<std::size_t> frames;  // indices of the frames kept
};

double to_double(const std::string& text) {
  double value = 0.0;
  std::from_chars(text.data(), text.data() + text.size(), value);
  return value;
}

}  // namespace

int main(int argc, char** argv) {
  std::string trajectory = "sweep";
  double duration_s = 60.0, fps = 30.0;
  int depth = 6, passes = 1;
  std::size_t slice_budget = 0;
  std::vector<int> every;
  std::vector<std::pair<double, double>> thresholds;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&] { return std::string(i + 1 < argc ? argv[++i] : ""); };
    if (arg == "--trajectory")
      trajectory = next();
    else if (arg == "--duration-s")
      duration_s = to_double(next());
    else if (arg == "--fps")
      fps = to_double(next());
    else if (arg == "--depth")
      depth = static_cast<int>(to_double(next()));
    else if (arg == "--passes")
      passes = std::max(1, static_cast<int>(to_double(next())));
    else if (arg == "--slice-budget")
      slice_budget = static_cast<std::size_t>(to_double(next()));
    else if (arg == "--every")
      every.push_back(static_cast<int>(to_double(next())));
    else if (const auto colon = arg.find(':'); colon != std::string::npos)
      thresholds.emplace_back(to_double(arg.substr(0, colon)), to_double(arg.substr(colon + 1)));
    else {
      std::cerr << "usage: sonoshape_keyframe_bench [--trajectory sweep|fan] [--duration-s S] "
                   "[--fps F] [--depth D] [--passes N] [--slice-budget N] [--every K ...] "
                   "[ANGLE_DEG:DISTANCE_MM ...]\n";
      return 2;
    }
  }
  if (thresholds.empty())
    thresholds = {{1, 0.5}, {2, 1}, {3, 1.5}, {3, 2}, {4, 2.5}, {5, 3}, {8, 5}};
  set_log_level(LogLevel::kWarning);

  auto phantom = simulator::make_default_phantom(std::string(SONOSHAPE_DATA_DIR) + "/models");
  if (!phantom) {
    std::cerr << phantom.message() << '\n';
    return 1;
  }
  const acquisition::Probe probe(acquisition::convex_probe_geometry());
  const Box3 box = phantom->bounds();
  simulator::TrajectoryOptions motion;
  motion.motion = simulator::parse_sweep_motion(trajectory);
  motion.duration_s = duration_s;
  motion.passes = passes;
  motion.T_reference_probe_centre.translation() = Vec3(
      0.5 * (box.min.x() + box.max.x()), box.min.y() - 10.0, 0.5 * (box.min.z() + box.max.z()));
  motion.sweep_length_mm = box.size().z() + 20.0;
  motion.sweep_angle_deg = motion.motion == simulator::SweepMotion::kFan ? 60.0 : 0.0;
  const int frame_count = static_cast<int>(duration_s * fps) + 1;
  const simulator::SimulatedAcquisition acquisition = simulator::acquire(
      simulator::Trajectory(motion), simulator::TrackerOptions{}, frame_count, fps);

  const Eigen::Matrix4d T_probe_image = probe.T_probe_image().matrix();
  std::vector<Vec2> sector_px;
  for (const Vec2& p : probe.sector_ring_mm(64)) sector_px.push_back(probe.mm_to_pixel(p));
  const auto corners = tracking::bounding_corners(sector_px);

  std::vector<Row> rows;
  for (const auto& [angle, distance] : thresholds) {
    tracking::KeyframeOptions keyframes{angle, distance};
    keyframes.slice_budget = slice_budget;
    tracking::KeyframeSelector selector(keyframes);
    Row row{std::to_string(angle).substr(0, 4) + " deg / " + std::to_string(distance).substr(0, 4) +
                " mm" + (slice_budget > 0 ? ", budget " + std::to_string(slice_budget) : ""),
            {}};
    for (int k = 0; k < frame_count; ++k) {
      const Pose& tracked = acquisition.tracked_poses[static_cast<std::size_t>(k)];
      if (tracked.status != TrackingStatus::kValid) continue;
      if (selector.offer(
              tracking::frame_plane(tracked.T_reference_probe.matrix() * T_probe_image, corners)))
        row.frames.push_back(static_cast<std::size_t>(k));
    }
    rows.push_back(std::move(row));
  }
  for (const int k : every) {
    Row row{"every " + std::to_string(k) + "th frame", {}};
    for (int f = 0; f < frame_count; f += k)
      if (acquisition.tracked_poses[static_cast<std::size_t>(f)].status == TrackingStatus::kValid)
        row.frames.push_back(static_cast<std::size_t>(f));
    rows.push_back(std::move(row));
  }

  if (passes > 1) {
    // Slices kept by the end of each minute, per rule.
    std::printf("| rule |");
    for (int minute = 1; minute * 60.0 <= duration_s + 1e-9; ++minute)
      std::printf(" %d min |", minute);
    std::printf("\n");
    for (const Row& row : rows) {
      std::printf("| %s |", row.rule.c_str());
      for (int minute = 1; minute * 60.0 <= duration_s + 1e-9; ++minute) {
        const auto last = static_cast<std::size_t>(minute * 60.0 * fps);
        std::printf(" %zu |", static_cast<std::size_t>(
                                  std::count_if(row.frames.begin(), row.frames.end(),
                                                [&](std::size_t k) { return k <= last; })));
      }
      std::printf("\n");
    }
    std::printf("\n");
  }

  const MeshSet truth = phantom->mesh_set();
  std::printf("%s, %.0f s at %.0f fps (%d frames), depth %d\n\n", trajectory.c_str(), duration_s,
              fps, frame_count, depth);
  std::printf("| rule | slices | cells | reconstruct s | IoU 1 spot | IoU 2 cheburashka |\n");
  std::printf("|---|---|---|---|---|---|\n");
  for (const Row& row : rows) {
    SliceSet set;
    for (const auto& m : phantom->meshes) set.labels.push_back({m.label, m.name});
    set.bounds = box.padded(0.1 * box.diagonal());
    for (const std::size_t k : row.frames) {
      const Eigen::Isometry3d& T = acquisition.true_poses[k];
      SlicePlane plane{T.translation(), T.linear().col(0), T.linear().col(1)};
      LabeledSlice slice = slice_meshes(phantom->meshes, plane);
      slice.fov = probe.sector_ring_mm();
      set.slices.push_back(std::move(slice));
    }
    recon::ReconstructionOptions options;
    options.max_depth = depth;
    recon::ReconstructionStats stats;
    Stopwatch clock;
    MeshSet meshes;
    try {
      meshes = recon::reconstruct(set, options, &stats);
    } catch (const std::exception& e) {
      std::printf("| %s | %zu | failed: %s |\n", row.rule.c_str(), set.slices.size(), e.what());
      continue;
    }
    const double seconds = clock.seconds();
    simulator::EvaluationOptions evaluation;
    evaluation.grid_resolution = 100;
    const auto scores =
        simulator::evaluate(meshes, truth, nullptr, box.padded(0.05 * box.diagonal()), evaluation);
    double iou[3] = {0, 0, 0};
    for (const auto& s : scores)
      if (s.label >= 1 && s.label <= 2) iou[s.label] = s.iou;
    std::printf("| %s | %zu | %zu | %.1f | %.3f | %.3f |\n", row.rule.c_str(), set.slices.size(),
                stats.cells, seconds, iou[1], iou[2]);
    std::fflush(stdout);
  }
  return 0;
}
