// `sonoshape slice`: cuts closed meshes with a family of planes into a slice set, the ground
// truth input of reconstruction tests and benchmarks.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>

#include "commands.hpp"
#include "mesh_spec.hpp"
#include "option_checks.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/mesh_slicer.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/simulator/plane_generator.hpp"
#include "sonoshape/simulator/unknowns.hpp"

namespace sonoshape::apps {
namespace {

// Gap between meshes laid out in a row, as a fraction of the largest mesh diagonal.
constexpr double kRowGapFraction = 0.15;
// Slice-set bounds: the union box of the meshes padded by this fraction of its diagonal.
constexpr double kBoundsPadding = 0.1;

struct SliceOptions {
  std::vector<std::string> meshes;
  std::string family = "parallel";
  int count = 20;
  std::uint64_t seed = 1;
  std::filesystem::path output;
  double size_mm = 0.0;  // 0: keep the meshes' own units
  std::string layout;    // "", "asis" or "row"
  std::filesystem::path truth_dir;
  bool skip_invalid = false;
  double unknown_fraction = 0.0;
  double unknown_radius = 0.03;
  std::string fov = "none";
  std::string fov_aim = "centre";
};

Box3 empty_box() {
  return Box3{Vec3::Constant(std::numeric_limits<double>::infinity()),
              Vec3::Constant(-std::numeric_limits<double>::infinity())};
}

Box3 united(const Box3& a, const Box3& b) {
  return Box3{a.min.cwiseMin(b.min), a.max.cwiseMax(b.max)};
}

void transform(TriangleMesh& mesh, double scale, const Vec3& before, const Vec3& after) {
  for (Vec3& p : mesh.vertices) p = (p - before) * scale + after;
}

Vec3 centre_of(const Box3& box) { return 0.5 * (box.min + box.max); }

// Scales and places the meshes as --size-mm and --layout ask.
void place(std::vector<LabeledMesh>& meshes, double size_mm, bool row) {
  if (size_mm > 0.0 && !row) {
    // One common scale keeps nested meshes nested.
    Box3 all = empty_box();
    for (const auto& m : meshes) all = united(all, m.mesh.bounds());
    const double scale = size_mm / all.diagonal();
    for (auto& m : meshes) transform(m.mesh, scale, centre_of(all), Vec3::Zero());
    return;
  }
  if (!row) return;
  double largest = 0.0;
  for (auto& m : meshes) {
    const Box3 box = m.mesh.bounds();
    const double scale = size_mm > 0.0 ? size_mm / box.diagonal() : 1.0;
    transform(m.mesh, scale, centre_of(box), Vec3::Zero());
    largest = std::max(largest, m.mesh.bounds().diagonal());
  }
  double cursor = 0.0;
  for (auto& m : meshes) {
    const Box3 box = m.mesh.bounds();
    transform(m.mesh, 1.0, Vec3::Zero(), Vec3(cursor - box.min.x(), 0.0, 0.0));
    cursor += box.size().x() + kRowGapFraction * largest;
  }
  const double row_length = cursor - kRowGapFraction * largest;
  for (auto& m : meshes) transform(m.mesh, 1.0, Vec3::Zero(), Vec3(-0.5 * row_length, 0.0, 0.0));
}

std::string join_specs(const std::vector<std::string>& specs) {
  std::string out;
  for (const std::string& spec : specs) out += (out.empty() ? "" : ", ") + spec;
  return out;
}

std::string vec_text(const Vec3& v) {
  std::ostringstream out;
  out << '(' << v.x() << ", " << v.y() << ", " << v.z() << ')';
  return out.str();
}

// Reads the --mesh files and places them as --size-mm and --layout ask.
Result<std::vector<LabeledMesh>> load_placed_meshes(const SliceOptions& options) {
  std::vector<LabeledMesh> meshes;
  for (const std::string& text : options.meshes) {
    auto mesh = load_mesh_spec(text, "--mesh");
    if (!mesh) return mesh.status();
    meshes.push_back(std::move(*mesh));
  }
  const bool row = options.layout.empty() ? (meshes.size() > 1 && options.size_mm > 0.0)
                                          : options.layout == "row";
  place(meshes, options.size_mm, row);
  return meshes;
}

// What the cut produced, for the summary line.
struct CutCounts {
  std::size_t regions = 0, holes = 0, empty = 0, skipped = 0;
};

// Cuts the meshes with every plane into `set`, each slice checked before it is kept. Meshes
// that self-intersect (cow.obj does) or intersect each other cut into crossing or overlapping
// polygons, which no reader accepts: an error, or (--skip-invalid) a slice dropped.
Status cut_slices(const std::vector<LabeledMesh>& meshes, const std::vector<SlicePlane>& planes,
                  bool skip_invalid, SliceSet& set, CutCounts& counts) {
  for (std::size_t i = 0; i < planes.size(); ++i) {
    LabeledSlice slice = slice_meshes(meshes, planes[i]);
    SliceSet single{set.units, set.labels, set.bounds, {slice}, {}};
    if (const Status valid = validate_slice_set(single, "plane " + std::to_string(i)); !valid) {
      if (!skip_invalid)
        return Status::error(valid.message() +
                             "\nThe input meshes self-intersect or intersect each other there. "
                             "Repair them, or pass --skip-invalid to drop such slices.");
      ++counts.skipped;
      continue;
    }
    counts.regions += slice.regions.size();
    for (const Region& r : slice.regions) counts.holes += r.holes.size();
    if (slice.regions.empty()) ++counts.empty;
    set.slices.push_back(std::move(slice));
  }
  return Status::ok();
}

// The slice set of the meshes cut by --count planes of the --planes family, in mm, bounded by
// the meshes' box padded.
Result<SliceSet> slice_set_of(const std::vector<LabeledMesh>& meshes, const Box3& objects,
                              const SliceOptions& options, CutCounts& counts) {
  const auto planes = simulator::generate_planes(simulator::parse_plane_family(options.family),
                                                 options.count, objects, options.seed);
  SliceSet set;
  set.units = "mm";
  std::map<int, std::string> names;
  for (const auto& m : meshes) names.try_emplace(m.label, m.name);
  for (const auto& [id, name] : names) set.labels.push_back({id, name});
  set.bounds = objects.padded(kBoundsPadding * objects.diagonal());
  if (Status cut = cut_slices(meshes, planes, options.skip_invalid, set, counts); !cut) return cut;
  // No region on any plane: the set would say "nothing there" about meshes that are there.
  if (counts.regions == 0 && !set.slices.empty())
    return Status::error("none of the " + std::to_string(set.slices.size()) +
                         " planes cuts a region out of " + join_specs(options.meshes) +
                         " (their box: min " + vec_text(objects.min) + ", max " +
                         vec_text(objects.max) +
                         " mm): a mesh whose triangles all have zero area, or one vertex far from "
                         "the others, leaves nothing to slice; check the mesh files");
  return set;
}

// --unknown and --fov: unknown blobs over contours and a field of view on the slices.
Status add_unknown_regions(const SliceOptions& options, SliceSet& set) {
  if (options.unknown_fraction <= 0.0 && options.fov == "none") return Status::ok();
  simulator::UnknownOptions unknowns;
  unknowns.fraction = options.unknown_fraction;
  unknowns.blob_radius = options.unknown_radius;
  unknowns.fov = simulator::parse_fov_shape(options.fov);
  unknowns.fov_covers_material = options.fov_aim == "cover";
  unknowns.seed = options.seed + 1;
  simulator::add_unknowns(set, unknowns);
  if (const Status valid = validate_slice_set(set, options.output.string()); !valid)
    return Status::error("the unknown regions made an invalid slice set: " + valid.message());
  return Status::ok();
}

// --truth: the placed meshes, one file per label (meshes sharing a label are one material).
Status write_truth_meshes(const std::vector<LabeledMesh>& meshes,
                          const std::filesystem::path& truth_dir) {
  std::error_code ec;
  std::filesystem::create_directories(truth_dir, ec);
  if (ec)
    return Status::error("cannot create the --truth directory " + truth_dir.string() + ": " +
                         ec.message());
  std::map<int, TriangleMesh> by_label;
  for (const auto& m : meshes) {
    TriangleMesh& out = by_label[m.label];
    const auto offset = static_cast<std::uint32_t>(out.vertices.size());
    out.vertices.insert(out.vertices.end(), m.mesh.vertices.begin(), m.mesh.vertices.end());
    for (const auto& t : m.mesh.triangles)
      out.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  }
  for (const auto& [label, mesh] : by_label)
    if (Status written = write_mesh(mesh, truth_dir / ("label_" + std::to_string(label) + ".ply"));
        !written)
      return written;
  return Status::ok();
}

std::string summary_line(const SliceOptions& options, std::size_t mesh_count, const SliceSet& set,
                         const CutCounts& counts, const Box3& objects) {
  std::ostringstream summary;
  summary << "slice: " << mesh_count << (mesh_count == 1 ? " mesh, " : " meshes, ")
          << set.slices.size() << ' ' << options.family << " planes, " << counts.regions
          << " regions (" << counts.holes << " holes, " << counts.empty
          << " empty slices), box diagonal " << objects.diagonal() << " -> "
          << options.output.string();
  if (!options.truth_dir.empty()) summary << ", truth in " << options.truth_dir.string();
  if (counts.skipped > 0)
    summary << "; skipped " << counts.skipped << " invalid slices (self-intersecting input meshes)";
  return summary.str();
}

int run_slice(const SliceOptions& options) {
  const auto fail = [](const std::string& message) {
    std::cerr << "error: " << message << '\n';
    return 1;
  };
  auto meshes = load_placed_meshes(options);
  if (!meshes) return fail(meshes.message());
  Box3 objects = empty_box();
  for (const auto& m : *meshes) objects = united(objects, m.mesh.bounds());
  CutCounts counts;
  auto set = slice_set_of(*meshes, objects, options, counts);
  if (!set) return fail(set.message());
  if (Status added = add_unknown_regions(options, *set); !added) return fail(added.message());
  if (Status written = write_slice_set(*set, options.output); !written)
    return fail(written.message());
  if (!options.truth_dir.empty())
    if (Status written = write_truth_meshes(*meshes, options.truth_dir); !written)
      return fail(written.message());
  std::cerr << summary_line(options, meshes->size(), *set, counts, objects) << '\n';
  return 0;
}

}  // namespace

CommandRunner add_slice_command(CLI::App& app) {
  auto options = std::make_shared<SliceOptions>();
  app.add_option("--mesh", options->meshes,
                 "Closed mesh to cut, LABEL:PATH[:NAME] (.obj, .ply, .off, .stl); repeat for more")
      ->required();
  app.add_option("--planes", options->family, "Plane family")
      ->check(CLI::IsMember({"parallel", "orthogonal", "random", "sweep"}))
      ->capture_default_str();
  app.add_option("--count", options->count, "Number of planes")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--seed", options->seed, "Seed of the plane generator")->capture_default_str();
  app.add_option("-o,--output", options->output, "Slice set to write (.slices.json or .csl)")
      ->required();
  app.add_option("--size-mm", options->size_mm,
                 "Scale meshes so their bounding-box diagonal is this many mm, centred at 0")
      ->check(kFiniteNumber)
      ->check(kPositiveNumber);
  app.add_option("--layout", options->layout,
                 "asis: keep relative positions (nested organs); row: side by side along x "
                 "(default with several meshes and --size-mm)")
      ->check(CLI::IsMember({"asis", "row"}));
  app.add_option("--truth", options->truth_dir,
                 "Directory to write the placed meshes to, as label_<id>.ply");
  app.add_flag("--skip-invalid", options->skip_invalid,
               "Drop slices whose polygons are invalid (self-intersecting input meshes) instead "
               "of failing");
  app.add_option("--unknown", options->unknown_fraction,
                 "Share of slices that get a random unknown blob over a contour (0-1)")
      ->check(kFiniteNumber)
      ->check(number_in(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--unknown-radius", options->unknown_radius,
                 "Mean radius of the unknown blobs, as a fraction of the box diagonal")
      ->check(number_in(0.001, 0.5))
      ->capture_default_str();
  app.add_option("--fov", options->fov,
                 "Field of view of every slice: sector (60 deg fan, 80 mm deep) or rect "
                 "(60 x 80 mm); outside it is unknown")
      ->check(CLI::IsMember({"none", "sector", "rect"}))
      ->capture_default_str();
  app.add_option("--fov-aim", options->fov_aim,
                 "centre: the fov (fixed size) looks at the slice's material from a random side, "
                 "its centre at half depth; cover: the fov is sized to contain the material's "
                 "bounding circle, as a sonographer aims the probe and sets the depth")
      ->check(CLI::IsMember({"centre", "cover"}))
      ->capture_default_str();
  return [options] { return run_slice(*options); };
}

}  // namespace sonoshape::apps
