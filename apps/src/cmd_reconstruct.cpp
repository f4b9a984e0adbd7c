// `sonoshape reconstruct INPUT -o OUT [--online]`: reconstruction of a slice set, at once or
// slice by slice through the online engine (recon::Reconstructor).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "commands.hpp"
#include "engine_options.hpp"
#include "option_checks.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/recon/reconstruct.hpp"
#include "sonoshape/recon/reconstructor.hpp"

namespace sonoshape::apps {
namespace {

nlohmann::json stats_json(const recon::ReconstructionStats& stats) {
  nlohmann::json j;
  j["arrangement_s"] = stats.arrangement_s;
  j["face_images_s"] = stats.face_images_s;
  j["field_s"] = stats.field_s;
  j["smoothing_s"] = stats.smoothing_s;
  j["mesh_s"] = stats.mesh_s;
  j["total_s"] = stats.total_s;
  j["slices"] = stats.slices;
  j["cells"] = stats.cells;
  j["faces"] = stats.faces;
  j["field_evaluations"] = stats.field_evaluations;
  j["depth"] = stats.depth;
  j["snapped_vertices"] = stats.snapped_vertices;
  j["completion_s"] = stats.completion_s;
  j["arrangement_serial_s"] = stats.arrangement_serial_s;
  j["evaluation_s"] = stats.evaluation_s;
  j["unknown_triangles"] = stats.unknown_triangles;
  j["cell_groups"] = stats.cell_groups;
  j["completed_slices"] = stats.completed_slices;
  j["data_s"] = stats.data_s;
  j["solve_s"] = stats.solve_s;
  j["solve_iterations"] = stats.solve_iterations;
  j["solve_nodes"] = stats.solve_nodes;
  nlohmann::json triangles = nlohmann::json::object();
  for (const auto& [label, count] : stats.triangles) triangles[std::to_string(label)] = count;
  j["triangles"] = triangles;
  return j;
}

nlohmann::json repairs_json(const std::vector<Repair>& repairs) {
  nlohmann::json list = nlohmann::json::array();
  for (const Repair& r : repairs)
    list.push_back({{"kind", r.kind},
                    {"where", r.where},
                    {"detail", r.detail},
                    {"area_changed", r.area_changed_mm2}});
  return list;
}

// What was written, per material: size, enclosed volume and whether the surface is closed,
// manifold and oriented (users of real data need to see it without a ground truth).
nlohmann::json meshes_json(const MeshSet& meshes) {
  nlohmann::json list = nlohmann::json::array();
  for (const MeshSet::Entry& entry : meshes.meshes) {
    const MeshHealth health = check_mesh_health(entry.mesh);
    list.push_back(
        {{"label", entry.label},
         {"name", entry.name},
         {"vertices", entry.mesh.vertices.size()},
         {"triangles", entry.mesh.triangles.size()},
         {"volume", signed_volume(entry.mesh)},
         {"closed_manifold_oriented", !entry.mesh.empty() && health.closed_manifold_oriented()}});
  }
  return list;
}

int write_json(const nlohmann::json& j, const std::string& path) {
  std::ofstream out(path);
  out << j.dump(2) << '\n';
  // Flushed here, not in the destructor: a full disk (/dev/full) fails the flush, and a stats
  // file that was not written must not end in exit 0.
  out.flush();
  if (!out) {
    const int error = errno;
    std::cerr << "error: cannot write stats to " << path << ": " << std::strerror(error)
              << "; check the directory exists and is writable, and free disk space\n";
    return 2;
  }
  return 0;
}

// Feeds the slices one by one (file order, or by timestamp) to the online engine; writes the
// meshes every `emit_every` slices (OUT/step_NNNN/) and at the end (OUT).
int run_online(const SliceSet& set, const std::string& output, const std::string& stats_path,
               const recon::ReconstructionOptions& engine, int emit_every, bool by_timestamp) {
  std::vector<std::size_t> order(set.slices.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  if (by_timestamp) {
    for (std::size_t k = 0; k < set.slices.size(); ++k)
      if (!set.slices[k].timestamp_s) {
        std::cerr << "error: --order timestamp: slice " << k
                  << " has no timestamp; give every slice a \"timestamp\" or use --order file\n";
        return 2;
      }
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return *set.slices[a].timestamp_s < *set.slices[b].timestamp_s;
    });
  }
  recon::ReconstructorOptions setup;
  setup.engine = engine;
  // The whole file's box from the start: no rebuild when a later slice reaches further.
  setup.bounds = set.effective_bounds();
  for (const int id : set.material_ids()) setup.labels.push_back(set.label_info(id));
  recon::Reconstructor reconstructor(setup);
  nlohmann::json steps = nlohmann::json::array();
  Progress progress("online reconstruction", order.size());
  for (std::size_t step = 0; step < order.size(); ++step) {
    reconstructor.add_slice(set.slices[order[step]]);
    const recon::UpdateStats update = reconstructor.update();
    nlohmann::json j = stats_json(update.step);
    j["step"] = step + 1;
    j["slice"] = order[step];
    j["cells_changed"] = update.cells_changed;
    j["full_rebuild"] = update.full_rebuild;
    j["peak_rss_mb"] = peak_rss_mb();
    steps.push_back(std::move(j));
    progress.update(step + 1);
    if (emit_every > 0 && (step + 1) % static_cast<std::size_t>(emit_every) == 0) {
      std::ostringstream name;
      name << "step_" << std::setw(4) << std::setfill('0') << step + 1;
      const auto written =
          write_mesh_set(reconstructor.mesh(), std::filesystem::path(output) / name.str());
      if (!written) {
        std::cerr << "error: " << written.message() << '\n';
        return 2;
      }
    }
  }
  const auto written = write_mesh_set(reconstructor.mesh(), output);
  if (!written) {
    std::cerr << "error: " << written.message() << '\n';
    return 2;
  }
  for (const auto& path : *written) log_info("wrote " + path.string());
  const recon::ReconstructionStats& totals = reconstructor.totals();
  log_info("reconstructed " + std::to_string(totals.slices) + " slices online, " +
           std::to_string(totals.cells) + " cells, " + std::to_string(totals.field_evaluations) +
           " field evaluations in " + std::to_string(totals.total_s) + " s");
  if (stats_path.empty()) return 0;
  nlohmann::json j = stats_json(totals);
  j["peak_rss_mb"] = peak_rss_mb();
  j["repairs"] = repairs_json(set.repairs);
  j["meshes"] = meshes_json(reconstructor.mesh());
  j["steps"] = std::move(steps);
  return write_json(j, stats_path);
}

struct ReconstructCommandOptions {
  std::string input, output, stats_path;
  recon::ReconstructionOptions engine;
  bool online = false;
  bool strict = false;
  std::string device;  // empty: SONOSHAPE_DEVICE, else cpu
  std::string field = kDefaultField;
  int emit_every = 0;
  std::string order = "file";
};

// The slice set of INPUT, refused when it holds nothing to reconstruct (an error, not exit 0
// with no mesh written).
Result<SliceSet> read_slices_to_reconstruct(const ReconstructCommandOptions& opt) {
  Result<SliceSet> slices = read_slice_set(opt.input, ReadOptions{opt.strict});
  if (!slices) return slices;
  if (slices->slices.empty())
    return Status::error(opt.input +
                         ": slices: the set holds no slice, so there is nothing to reconstruct; "
                         "give at least one slice with a labelled region");
  if (slices->material_ids().empty())
    return Status::error(opt.input +
                         ": no slice has a region of a material (every region is \"unknown\" or "
                         "there are none), so there is no surface to reconstruct; label the "
                         "organ's regions with a material id");
  return slices;
}

// Warns of the labels whose surface came out empty: unused ones, and ones whose regions are
// too small for the octree.
void warn_of_empty_meshes(const SliceSet& slices, const MeshSet& meshes) {
  std::set<int> used;
  for (const LabeledSlice& slice : slices.slices)
    for (const Region& region : slice.regions) used.insert(region.label);
  std::string unused;
  for (const auto& entry : meshes.meshes) {
    if (!entry.mesh.empty()) continue;
    if (!used.count(entry.label))
      unused += (unused.empty() ? "" : ", ") + std::to_string(entry.label);
    else
      log_warning("label " + std::to_string(entry.label) + " (" + entry.name +
                  ") produced an empty surface: its regions may be smaller than the octree cells"
                  " (try a larger --depth)");
  }
  if (!unused.empty())
    log_warning("label(s) " + unused +
                " declared but no region uses them: their meshes "
                "are empty");
}

// The one-shot reconstruction of the whole set (recon::reconstruct), its meshes and stats.
int run_at_once(const SliceSet& slices, const ReconstructCommandOptions& opt) {
  recon::ReconstructionStats stats;
  const MeshSet meshes = recon::reconstruct(slices, opt.engine, &stats);
  const auto written = write_mesh_set(meshes, opt.output);
  if (!written) {
    std::cerr << "error: " << written.message() << '\n';
    return 2;
  }
  for (const auto& path : *written) log_info("wrote " + path.string());
  warn_of_empty_meshes(slices, meshes);
  log_info("reconstructed " + std::to_string(stats.slices) + " slices, " +
           std::to_string(stats.cells) + " cells, " + std::to_string(stats.field_evaluations) +
           " field evaluations in " + std::to_string(stats.total_s) + " s");
  if (opt.stats_path.empty()) return 0;
  nlohmann::json j = stats_json(stats);
  j["peak_rss_mb"] = peak_rss_mb();
  j["repairs"] = repairs_json(slices.repairs);
  j["meshes"] = meshes_json(meshes);
  return write_json(j, opt.stats_path);
}

int run_reconstruct(ReconstructCommandOptions& opt) {
  opt.engine.field = *recon::parse_field_name(opt.field);
  opt.engine.device = resolve_device(opt.device, opt.field);
  const Result<SliceSet> slices = read_slices_to_reconstruct(opt);
  if (!slices) {
    std::cerr << "error: " << slices.message() << '\n';
    return 2;
  }
  if (opt.emit_every > 0 && !opt.online) {
    std::cerr << "error: --emit-every needs --online\n";
    return 2;
  }
  if (opt.online)
    return run_online(*slices, opt.output, opt.stats_path, opt.engine, opt.emit_every,
                      opt.order == "timestamp");
  return run_at_once(*slices, opt);
}

// The slice set read, the meshes and the stats written, and how the input is read.
void add_file_options(CLI::App& app, ReconstructCommandOptions& opt) {
  app.add_option("input", opt.input, "Slice set: .slices.json (see docs/formats/slices.md) or .csl")
      ->required();
  app.add_option("-o,--output", opt.output,
                 "Output: a .ply/.obj/.off file (one label) or a directory of label_<id>.ply")
      ->required();
}

// The engine: the shared group (engine_options.hpp), its threads and its arrangement.
void add_reconstruct_engine_options(CLI::App& app, ReconstructCommandOptions& opt) {
  add_engine_options(
      app, {opt.engine.max_depth, opt.engine.smoothing_iterations, opt.field, opt.device});
  app.add_option("--threads", opt.engine.threads,
                 "Threads for every stage of the reconstruction (0: all cores)")
      ->check(number_in(0, 1024))
      ->capture_default_str();
}

// What is reported and how strictly the input is taken.
void add_report_options(CLI::App& app, ReconstructCommandOptions& opt) {
  app.add_option("--stats", opt.stats_path,
                 "Write per-stage seconds and counts as JSON (with "
                 "--online: totals and one entry per step)");
  app.add_flag("--strict", opt.strict,
               "Refuse input that needs repairs (pinched contours, a flipped plane equation, "
               "rounding overlaps, ...) instead of repairing it with a warning");
  app.add_flag(
      "--whole-arrangement", [&opt](std::int64_t) { opt.engine.cells_on_demand = false; },
      "Build every cell of the slices' arrangement instead of those the surface needs (the "
      "same field, at a cost that grows with the cube of the slice count; for comparisons)");
  app.add_flag(
      "--one-grid", [&opt](std::int64_t) { opt.engine.own_grids = false; },
      "Thin-plate field: solve every organ on the one grid over the box, without the grids of "
      "their own that small organs get (for comparisons)");
}

// --online: the slices one by one through the online engine.
void add_online_options(CLI::App& app, ReconstructCommandOptions& opt) {
  app.add_flag("--online", opt.online,
               "Feed the slices one by one to the online engine (an update per slice)");
  app.add_option("--emit-every", opt.emit_every,
                 "With --online: also write the meshes after every K slices to OUT/step_NNNN/")
      ->check(number_in(1, 1000000));
  app.add_option("--order", opt.order, "With --online: feed in file order or by timestamp")
      ->check(CLI::IsMember({"file", "timestamp"}))
      ->capture_default_str();
}

}  // namespace

CommandRunner add_reconstruct_command(CLI::App& app) {
  auto opt = std::make_shared<ReconstructCommandOptions>();
  add_file_options(app, *opt);
  add_reconstruct_engine_options(app, *opt);
  add_report_options(app, *opt);
  add_online_options(app, *opt);
  return [opt] { return run_reconstruct(*opt); };
}

}  // namespace sonoshape::apps
