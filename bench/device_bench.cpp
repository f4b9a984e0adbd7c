// The field devices on one slice set, with no more than the engine linked (core, recon,
// kernels): what bench/gpu_run.sh runs on a machine without our Debian libraries (the carry of
// bench/make_carry.sh stays small without OpenCV's and ZeroMQ's dependencies).
//
//   sonoshape_device_bench SET.slices.json [--device D] [--online] [--threads N] [--repeat R]
//   sonoshape_device_bench SET.slices.json --compare-whole [--threads N]
//   sonoshape_device_bench --list-devices   (one line per OpenCL device: spec, fp64, name)
//
// Offline: reconstructs R times (one update of a fresh engine, as `sonoshape reconstruct`).
// Online: feeds the slices one per update (file order, as `reconstruct --online`), R times.
// Prints one JSON object: the device, per run the stats (online: per step), and a hash of the
// meshes (vertices and triangles, bit for bit) that tells whether two devices agree.
// --compare-whole: the invariant of cells on demand on this set: one update with cells on
// demand and one on the whole arrangement; prints the largest field difference over the
// sampled vertices, whether the sampled vertices and the meshes' triangles are the same, the
// largest vertex distance, and both runs' stats.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/kernels/opencl.hpp"
#include "sonoshape/recon/reconstruct.hpp"
#include "sonoshape/recon/reconstructor.hpp"

namespace {

using namespace sonoshape;

// FNV-1a over the bytes of every mesh's label, vertices and triangles.
std::string mesh_hash(const MeshSet& meshes) {
  std::uint64_t h = 1469598103934665603ull;
  auto add = [&](const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t k = 0; k < bytes; ++k) h = (h ^ p[k]) * 1099511628211ull;
  };
  for (const auto& m : meshes.meshes) {
    add(&m.label, sizeof(m.label));
    for (const Vec3& v : m.mesh.vertices) add(v.data(), 3 * sizeof(double));
    for (const auto& t : m.mesh.triangles) add(&t, sizeof(t));
  }
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(h));
  return text;
}

nlohmann::json stats_json(const recon::ReconstructionStats& s) {
  return {{"total_s", s.total_s},
          {"arrangement_s", s.arrangement_s},
          {"arrangement_serial_s", s.arrangement_serial_s},
          {"face_images_s", s.face_images_s},
          {"field_s", s.field_s},
          {"smoothing_s", s.smoothing_s},
          {"mesh_s", s.mesh_s},
          {"evaluation_s", s.evaluation_s},
          {"completion_s", s.completion_s},
          {"cells", s.cells},
          {"slices", s.slices},
          {"field_evaluations", s.field_evaluations},
          {"unknown_triangles", s.unknown_triangles},
          {"completed_slices", s.completed_slices}};
}

// One update of every slice of `set`, with cells on demand or on the whole arrangement.
std::unique_ptr<recon::Reconstructor> reconstruct_with(const SliceSet& set,
                                                       recon::ReconstructorOptions setup,
                                                       bool on_demand,
                                                       recon::ReconstructionStats& stats) {
  setup.engine.cells_on_demand = on_demand;
  auto engine = std::make_unique<recon::Reconstructor>(setup);
  for (const LabeledSlice& slice : set.slices) engine->add_slice(slice);
  stats = engine->update().step;
  return engine;
}

nlohmann::json compare_whole(const SliceSet& set, const recon::ReconstructorOptions& setup) {
  recon::ReconstructionStats lazy_stats, whole_stats;
  const auto lazy = reconstruct_with(set, setup, true, lazy_stats);
  const auto whole = reconstruct_with(set, setup, false, whole_stats);
  const auto a = whole->sampled_field();
  const auto b = lazy->sampled_field();
  bool same_vertices = a.size() == b.size();
  double worst_field = 0.0;
  for (std::size_t n = 0; same_vertices && n < a.size(); ++n) {
    same_vertices = a[n].first == b[n].first;
    for (std::size_t l = 0; same_vertices && l < a[n].second.size(); ++l)
      worst_field = std::max(worst_field, std::abs(a[n].second[l] - b[n].second[l]));
  }
  bool same_triangles = whole->mesh().meshes.size() == lazy->mesh().meshes.size();
  double worst_vertex = 0.0;
  for (std::size_t m = 0; same_triangles && m < whole->mesh().meshes.size(); ++m) {
    const TriangleMesh& x = whole->mesh().meshes[m].mesh;
    const TriangleMesh& y = lazy->mesh().meshes[m].mesh;
    same_triangles = x.triangles == y.triangles && x.vertices.size() == y.vertices.size();
    for (std::size_t v = 0; same_triangles && v < x.vertices.size(); ++v)
      worst_vertex = std::max(worst_vertex, (x.vertices[v] - y.vertices[v]).norm());
  }
  return {{"sampled_vertices_equal", same_vertices},
          {"max_field_difference", same_vertices ? nlohmann::json(worst_field) : nlohmann::json()},
          {"triangles_equal", same_triangles},
          {"max_vertex_distance", same_triangles ? nlohmann::json(worst_vertex) : nlohmann::json()},
          {"mesh_hash_on_demand", mesh_hash(lazy->mesh())},
          {"mesh_hash_whole", mesh_hash(whole->mesh())},
          {"on_demand", stats_json(lazy_stats)},
          {"whole", stats_json(whole_stats)}};
}

int run(int argc, char** argv) {
  std::string path, device = "cpu";
  bool online = false, compare = false;
  int threads = 0, repeat = 1;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    auto value = [&]() -> std::string {
      if (k + 1 >= argc) throw Error(a + " needs a value");
      return argv[++k];
    };
    if (a == "--list-devices") {
      std::string error;
      for (const kernels::DeviceInfo& d : kernels::list_devices(&error))
        std::cout << "opencl:" << d.platform << ":" << d.device << "\t"
                  << (d.fp64 ? "fp64" : "no-fp64") << "\t" << (d.gpu ? "GPU" : "CPU") << "\t"
                  << d.device_name << " (" << d.platform_name << ")\n";
      if (!error.empty()) std::cerr << error << "\n";
      return 0;
    }
    if (a == "--device")
      device = value();
    else if (a == "--online")
      online = true;
    else if (a == "--compare-whole")
      compare = true;
    else if (a == "--threads")
      threads = std::stoi(value());
    else if (a == "--repeat")
      repeat = std::stoi(value());
    else if (!a.empty() && a[0] != '-' && path.empty())
      path = a;
    else
      throw Error("unknown argument " + a +
                  "; usage: SET.slices.json [--device D] [--online] [--threads N] [--repeat R] "
                  "[--compare-whole]");
  }
  if (path.empty())
    throw Error("usage: SET.slices.json [--device D] [--online] [--threads N] [--repeat R]");
  const Result<SliceSet> set = read_slice_set(path);
  if (!set) throw Error(set.message());
  recon::ReconstructorOptions setup;
  setup.engine.threads = threads;
  setup.engine.device = device;
  setup.bounds = set->effective_bounds();
  for (const int id : set->material_ids()) setup.labels.push_back({id, set->label_name(id)});
  if (compare) {
    std::cout << nlohmann::json{{"set", path}, {"compare_whole", compare_whole(*set, setup)}}.dump()
              << "\n";
    return 0;
  }
  nlohmann::json out = {{"set", path}, {"device", device}, {"online", online}};
  if (device != "cpu") {
    const auto opened = kernels::open_device(kernels::parse_device_spec(device));
    if (opened)
      out["device_name"] = opened->info().device_name + " (" + opened->info().platform_name + ")";
  }
  nlohmann::json runs = nlohmann::json::array();
  std::string hash;
  for (int r = 0; r < repeat; ++r) {
    if (!online) {
      recon::ReconstructionStats stats;
      hash = mesh_hash(recon::reconstruct(*set, setup.engine, &stats));
      runs.push_back(stats_json(stats));
      continue;
    }
    recon::Reconstructor engine(setup);
    nlohmann::json steps = nlohmann::json::array();
    for (const LabeledSlice& slice : set->slices) {
      engine.add_slice(slice);
      steps.push_back(stats_json(engine.update().step));
    }
    hash = mesh_hash(engine.mesh());
    runs.push_back({{"steps", steps}});
  }
  out["runs"] = runs;
  out["mesh_hash"] = hash;
  std::cout << out.dump() << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
}
