// `sonoshape reconstruct INPUT -o OUT`: offline reconstruction of a slice set.
#include <CLI/CLI.hpp>

#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/publish/mesh_writer.hpp"
#include "sonoshape/recon/reconstruct.hpp"

namespace sonoshape::apps {

CommandRunner add_reconstruct_command(CLI::App& app) {
  struct Options {
    std::string input, output, stats_path;
    recon::ReconstructionOptions engine;
  };
  auto opt = std::make_shared<Options>();
  app.add_option("input", opt->input, "Slice set: .slices.json (see docs/formats/slices.md) or .csl")
      ->required();
  app.add_option("-o,--output", opt->output,
                 "Output: a .ply/.obj/.off file (one label) or a directory of label_<id>.ply")
      ->required();
  app.add_option("--depth", opt->engine.max_depth,
                 "Octree depth (finest cells = largest box side / 2^depth); default: about 1/128 "
                 "of the box diagonal")
      ->check(CLI::Range(1, 11));
  app.add_option("--smooth", opt->engine.smoothing_iterations,
                 "Bi-Laplacian smoothing iterations (0 turns smoothing off)")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  app.add_option("--threads", opt->engine.threads, "Evaluation threads (0: all cores)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  app.add_option("--stats", opt->stats_path, "Write per-stage seconds and counts as JSON");

  return [opt]() -> int {
    const Result<SliceSet> slices = read_slice_set(opt->input);
    if (!slices) {
      std::cerr << "error: " << slices.message() << '\n';
      return 2;
    }
    recon::ReconstructionStats stats;
    const MeshSet meshes = recon::reconstruct(*slices, opt->engine, &stats);
    const auto written = publish::write_mesh_set(meshes, opt->output);
    if (!written) {
      std::cerr << "error: " << written.message() << '\n';
      return 2;
    }
    for (const auto& path : *written) log_info("wrote " + path.string());
    for (const auto& entry : meshes.meshes)
      if (entry.mesh.empty())
        log_warning("label " + std::to_string(entry.label) + " (" + entry.name +
                    ") produced an empty surface: its regions may be smaller than the octree cells"
                    " (try a larger --depth)");
    log_info("reconstructed " + std::to_string(stats.slices) + " slices, " +
             std::to_string(stats.cells) + " cells, " + std::to_string(stats.field_evaluations) +
             " field evaluations in " + std::to_string(stats.total_s) + " s");
    if (!opt->stats_path.empty()) {
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
      j["unknown_triangles"] = stats.unknown_triangles;
      j["cell_groups"] = stats.cell_groups;
      nlohmann::json triangles = nlohmann::json::object();
      for (const auto& [label, count] : stats.triangles) triangles[std::to_string(label)] = count;
      j["triangles"] = triangles;
      j["peak_rss_mb"] = peak_rss_mb();
      std::ofstream out(opt->stats_path);
      out << j.dump(2) << '\n';
      if (!out) {
        std::cerr << "error: cannot write stats to " << opt->stats_path
                  << ": check the directory exists and is writable\n";
        return 2;
      }
    }
    return 0;
  };
}

}  // namespace sonoshape::apps
