#include "sonoshape/recon/reconstruct.hpp"

#include <algorithm>
#include <set>
#include <stdexcept>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/recon/reconstructor.hpp"

namespace sonoshape::recon {

const char* field_name(FieldKind field) {
  return field == FieldKind::thin_plate ? "thin-plate" : "mean-value";
}

std::optional<FieldKind> parse_field_name(const std::string& name) {
  if (name == "mean-value") return FieldKind::mean_value;
  if (name == "thin-plate") return FieldKind::thin_plate;
  return std::nullopt;
}

// The one-shot reconstruction is the online engine given every slice in one update, so that
// the two agree by construction (design.md); the invariant tests check that the field of a
// sequence of updates equals this one's.
MeshSet reconstruct(const SliceSet& set, const ReconstructionOptions& options,
                    ReconstructionStats* stats_out) {
  ReconstructorOptions setup;
  setup.engine = options;
  setup.bounds = set.effective_bounds();
  // A declared material that no region uses has an empty surface: it gets its (empty) entry
  // without a field of its own, so 1000 declared labels with one used cost one field, not 1000.
  std::set<int> used;
  for (const LabeledSlice& slice : set.slices)
    for (const Region& region : slice.regions)
      if (region.label >= 1) used.insert(region.label);
  std::vector<MeshSet::Entry> unused;
  for (const int id : set.material_ids()) {
    if (used.count(id))
      setup.labels.push_back(set.label_info(id));
    else
      unused.push_back({id, set.label_name(id), {}});
  }
  Reconstructor reconstructor(setup);
  try {
    for (const LabeledSlice& slice : set.slices) reconstructor.add_slice(slice);
  } catch (const std::invalid_argument& e) {
    throw GeometryError(e.what());
  }
  const UpdateStats update = reconstructor.update();
  if (stats_out) *stats_out = update.step;
  MeshSet meshes = reconstructor.mesh();
  for (MeshSet::Entry& entry : unused) meshes.meshes.push_back(std::move(entry));
  std::sort(meshes.meshes.begin(), meshes.meshes.end(),
            [](const MeshSet::Entry& a, const MeshSet::Entry& b) { return a.label < b.label; });
  return meshes;
}

}  // namespace sonoshape::recon
