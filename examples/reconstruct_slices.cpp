// Example: sonoshape's engine from a program of your own. Reads a slice set, feeds its slices
// one by one to the online reconstructor (as a live scan does), and writes one mesh per label.
//
//   reconstruct_slices SLICES.slices.json OUT_DIR [mean-value|thin-plate]
//
// Links sonoshape::recon (the engine), sonoshape::core (slice sets) and sonoshape::publish
// (mesh writers); see examples/CMakeLists.txt.
#include <cstdio>
#include <filesystem>
#include <string>

#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/recon/reconstructor.hpp"

namespace fs = std::filesystem;
using namespace sonoshape;

int main(int argc, char** argv) {
  if (argc < 3 || argc > 4) {
    std::fprintf(stderr, "usage: %s SLICES.slices.json OUT_DIR [mean-value|thin-plate]\n", argv[0]);
    return 2;
  }
  // Slice sets are user input: every failure comes back as a Status naming the file and field.
  Result<SliceSet> slices = read_slice_set(argv[1]);
  if (!slices) {
    std::fprintf(stderr, "%s\n", slices.message().c_str());
    return 1;
  }
  recon::ReconstructorOptions options;
  if (argc == 4) {
    const auto field = recon::parse_field_name(argv[3]);
    if (!field) {
      std::fprintf(stderr, "unknown field '%s': use mean-value or thin-plate\n", argv[3]);
      return 2;
    }
    options.engine.field = *field;
  }
  // A live scan gives the scan volume up front, so that no slice outside the box seen so far
  // forces a rebuild; the set's own box does the same here.
  options.bounds = slices->effective_bounds();
  options.labels = slices->labels;

  recon::Reconstructor engine(options);
  for (const LabeledSlice& slice : slices->slices) {
    engine.add_slice(slice);
    const recon::UpdateStats update = engine.update();
    std::size_t triangles = 0;
    for (const MeshSet::Entry& entry : engine.mesh().meshes)
      triangles += entry.mesh.triangles.size();
    std::printf("slice %zu: %zu triangles in %.1f ms\n", engine.slice_count(), triangles,
                1000.0 * update.step.total_s);
  }

  fs::create_directories(argv[2]);
  for (const MeshSet::Entry& entry : engine.mesh().meshes) {
    const fs::path path = fs::path(argv[2]) / ("label_" + std::to_string(entry.label) + ".ply");
    if (const Status written = write_mesh(entry.mesh, path); !written.is_ok()) {
      std::fprintf(stderr, "%s\n", written.message().c_str());
      return 1;
    }
    std::printf("%s: %s, %zu triangles\n", path.c_str(), entry.name.c_str(),
                entry.mesh.triangles.size());
  }
  return 0;
}
