// `sonoshape evaluate`: scores reconstructed meshes against ground truth (IoU, surface and
// contour distances, mesh health) beside the closest-point baseline.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>

#include "commands.hpp"
#include "mesh_spec.hpp"
#include "option_checks.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/simulator/evaluation.hpp"

namespace sonoshape::apps {
namespace {

namespace fs = std::filesystem;

// Without slices, the box is the union of all meshes padded by this fraction of its diagonal.
constexpr double kBoxPadding = 0.05;

struct EvaluateOptions {
  fs::path recon;
  std::vector<std::string> truth;
  fs::path slices;
  int grid = 200;
  int samples = 20000;
  fs::path json;
};

void add_mesh(MeshSet& set, int label, const std::string& name, TriangleMesh mesh) {
  for (auto& e : set.meshes)
    if (e.label == label) {  // several files of one label: one material
      const auto offset = static_cast<std::uint32_t>(e.mesh.vertices.size());
      e.mesh.vertices.insert(e.mesh.vertices.end(), mesh.vertices.begin(), mesh.vertices.end());
      for (const auto& t : mesh.triangles)
        e.mesh.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
      return;
    }
  set.meshes.push_back({label, name, std::move(mesh)});
  std::sort(set.meshes.begin(), set.meshes.end(),
            [](const auto& a, const auto& b) { return a.label < b.label; });
}

// A directory of label_<id>.{ply,obj,off,stl} files, or one mesh file (label 1).
Result<MeshSet> read_reconstruction(const fs::path& path) {
  MeshSet set;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    const std::regex pattern(R"(label_(\d+)\.(ply|obj|off|stl))", std::regex::icase);
    std::vector<std::pair<int, fs::path>> files;
    for (const auto& entry : fs::directory_iterator(path, ec)) {
      std::smatch match;
      const std::string name = entry.path().filename().string();
      if (entry.is_regular_file() && std::regex_match(name, match, pattern))
        files.emplace_back(std::stoi(match[1].str()), entry.path());
    }
    if (ec)
      return Status::error("cannot list --recon directory " + path.string() + ": " + ec.message());
    if (files.empty())
      return Status::error("--recon directory " + path.string() +
                           " holds no label_<id>.ply/.obj/.off/.stl mesh");
    std::sort(files.begin(), files.end());
    for (const auto& [label, file] : files) {
      auto mesh = read_mesh(file, /*allow_empty=*/true);
      if (!mesh) return mesh.status();
      // A material that vanished is written empty; it scores as not reconstructed.
      if (mesh->empty()) continue;
      add_mesh(set, label, "label_" + std::to_string(label), std::move(*mesh));
    }
    return set;
  }
  if (!fs::exists(path, ec))
    return Status::error("--recon " + path.string() +
                         " does not exist (give the output directory "
                         "or mesh file of `sonoshape reconstruct`)");
  auto mesh = read_mesh(path);
  if (!mesh) return mesh.status();
  add_mesh(set, 1, path.stem().string(), std::move(*mesh));
  return set;
}

std::string number(double value, int precision) {
  if (std::isnan(value)) return "-";
  char text[32];
  std::snprintf(text, sizeof text, "%.*f", precision, value);
  return text;
}

void print_table(const std::vector<simulator::LabelScore>& scores,
                 const std::map<int, std::string>& names, const Box3& box, int grid) {
  std::printf("evaluation box [%g %g %g] - [%g %g %g], diagonal %g, grid %d^3\n", box.min.x(),
              box.min.y(), box.min.z(), box.max.x(), box.max.y(), box.max.z(), box.diagonal(),
              grid);
  std::printf("%-6s %-16s %7s %9s %9s %9s %9s %9s\n", "label", "name", "IoU", "baseline", "mean %",
              "Hausd. %", "cont.mean", "cont.max");
  for (const auto& s : scores) {
    const auto name = names.count(s.label) ? names.at(s.label) : "";
    std::printf("%-6d %-16.16s %7s %9s %9s %9s %9s %9s%s\n", s.label, name.c_str(),
                number(s.iou, 4).c_str(), number(s.baseline_iou, 4).c_str(),
                number(s.mean_surface_distance, 3).c_str(), number(s.hausdorff_distance, 3).c_str(),
                number(s.contour_mean, 3).c_str(), number(s.contour_max, 3).c_str(),
                s.reconstructed ? "" : "  (not reconstructed)");
  }
  std::printf("\nconnected parts (6-connected inside samples of the grid)\n");
  std::printf("%-6s %9s %9s %9s\n", "label", "recon", "baseline", "truth");
  for (const auto& s : scores)
    std::printf("%-6d %9s %9s %9d\n", s.label,
                s.reconstructed ? std::to_string(s.components).c_str() : "-",
                s.baseline_components < 0 ? "-" : std::to_string(s.baseline_components).c_str(),
                s.truth_components);
  std::printf("\nmesh health of the reconstruction\n");
  std::printf("%-6s %9s %9s %11s %9s %10s  %s\n", "label", "boundary", "non-man.", "misoriented",
              "nm.verts", "degenerate", "closed manifold oriented");
  for (const auto& s : scores) {
    if (!s.reconstructed) {
      std::printf("%-6d %9s\n", s.label, "-");
      continue;
    }
    const MeshHealth& h = s.health;
    std::printf("%-6d %9zu %9zu %11zu %9zu %10zu  %s\n", s.label, h.boundary_edges,
                h.non_manifold_edges, h.misoriented_edges, h.non_manifold_vertices,
                h.degenerate_triangles, h.closed_manifold_oriented() ? "yes" : "no");
  }
}

nlohmann::json to_json(const std::vector<simulator::LabelScore>& scores,
                       const std::map<int, std::string>& names, const Box3& box, int grid) {
  // NaN (a score that could not be computed) becomes null.
  auto value = [](double x) { return std::isnan(x) ? nlohmann::json(nullptr) : nlohmann::json(x); };
  nlohmann::json labels = nlohmann::json::array();
  for (const auto& s : scores) {
    const MeshHealth& h = s.health;
    labels.push_back({
        {"label", s.label},
        {"name", names.count(s.label) ? names.at(s.label) : ""},
        {"reconstructed", s.reconstructed},
        {"iou", value(s.iou)},
        {"baseline_iou", value(s.baseline_iou)},
        {"components", s.components},
        {"baseline_components", s.baseline_components < 0 ? nlohmann::json(nullptr)
                                                          : nlohmann::json(s.baseline_components)},
        {"truth_components", s.truth_components},
        {"mean_surface_distance_percent", value(s.mean_surface_distance)},
        {"hausdorff_distance_percent", value(s.hausdorff_distance)},
        {"contour_mean_percent", value(s.contour_mean)},
        {"contour_max_percent", value(s.contour_max)},
        {"health",
         {{"boundary_edges", h.boundary_edges},
          {"non_manifold_edges", h.non_manifold_edges},
          {"misoriented_edges", h.misoriented_edges},
          {"non_manifold_vertices", h.non_manifold_vertices},
          {"degenerate_triangles", h.degenerate_triangles},
          {"closed_manifold_oriented", s.reconstructed && h.closed_manifold_oriented()}}},
    });
  }
  return {{"box",
           {{"min", {box.min.x(), box.min.y(), box.min.z()}},
            {"max", {box.max.x(), box.max.y(), box.max.z()}},
            {"diagonal", box.diagonal()}}},
          {"grid_resolution", grid},
          {"labels", labels}};
}

int run_evaluate(const EvaluateOptions& options) {
  auto reconstruction = read_reconstruction(options.recon);
  if (!reconstruction) {
    std::cerr << "error: " << reconstruction.message() << '\n';
    return 1;
  }
  MeshSet truth;
  std::map<int, std::string> names;
  for (const std::string& text : options.truth) {
    auto mesh = load_mesh_spec(text, "--truth");
    if (!mesh) {
      std::cerr << "error: " << mesh.message() << '\n';
      return 1;
    }
    names.try_emplace(mesh->label, mesh->name);
    add_mesh(truth, mesh->label, mesh->name, std::move(mesh->mesh));
  }

  std::optional<SliceSet> slices;
  Box3 box;
  if (!options.slices.empty()) {
    auto read = read_slice_set(options.slices);
    if (!read) {
      std::cerr << "error: " << read.message() << '\n';
      return 1;
    }
    slices = std::move(*read);
    for (const LabelInfo& l : slices->labels)
      if (!l.name.empty()) names[l.id] = l.name;
    box = slices->effective_bounds();
  } else {
    box = Box3{Vec3::Constant(std::numeric_limits<double>::infinity()),
               Vec3::Constant(-std::numeric_limits<double>::infinity())};
    for (const MeshSet* set : {&truth, &*reconstruction})
      for (const auto& e : set->meshes) {
        const Box3 b = e.mesh.bounds();
        box = Box3{box.min.cwiseMin(b.min), box.max.cwiseMax(b.max)};
      }
    box = box.padded(kBoxPadding * box.diagonal());
  }

  simulator::EvaluationOptions evaluation;
  evaluation.grid_resolution = options.grid;
  evaluation.surface_samples = options.samples;
  const Stopwatch clock;
  const auto scores =
      simulator::evaluate(*reconstruction, truth, slices ? &*slices : nullptr, box, evaluation);
  log_debug("evaluate: " + std::to_string(clock.seconds()) + " s");

  print_table(scores, names, box, options.grid);
  if (!options.json.empty()) {
    std::ofstream out(options.json);
    out << to_json(scores, names, box, options.grid).dump(2) << '\n';
    if (!out) {
      std::cerr << "error: cannot write --json file " << options.json.string() << '\n';
      return 1;
    }
  }
  return 0;
}

}  // namespace

CommandRunner add_evaluate_command(CLI::App& app) {
  auto options = std::make_shared<EvaluateOptions>();
  app.add_option("--recon", options->recon,
                 "Reconstruction: a directory of label_<id>.ply files or one mesh file (label 1)")
      ->required();
  app.add_option("--truth", options->truth, "Ground-truth mesh LABEL:PATH[:NAME]; repeat for more")
      ->required();
  app.add_option("--slices", options->slices,
                 "The slice set that was reconstructed: enables the baseline and contour scores "
                 "and gives the evaluation box");
  app.add_option("--grid", options->grid, "IoU samples per axis")
      ->check(number_in(1, 1024))
      ->capture_default_str();
  app.add_option("--samples", options->samples, "Surface samples per mesh for distances")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--json", options->json, "Also write the scores as JSON");
  return [options] { return run_evaluate(*options); };
}

}  // namespace sonoshape::apps
