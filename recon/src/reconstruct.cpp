#include "sonoshape/recon/reconstruct.hpp"

#include <stdexcept>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/recon/reconstructor.hpp"

namespace sonoshape::recon {

// The one-shot reconstruction is the online engine given every slice in one update, so that
// the two agree by construction (design.md); the invariant tests check that the field of a
// sequence of updates equals this one's.
MeshSet reconstruct(const SliceSet& set, const ReconstructionOptions& options,
                    ReconstructionStats* stats_out) {
  ReconstructorOptions setup;
  setup.engine = options;
  setup.bounds = set.effective_bounds();
  setup.cells_on_demand = true;  // one update: only the cells the octree reaches are built
  for (const int id : set.material_ids()) setup.labels.push_back({id, set.label_name(id)});
  Reconstructor reconstructor(setup);
  try {
    for (const LabeledSlice& slice : set.slices) reconstructor.add_slice(slice);
  } catch (const std::invalid_argument& e) {
    throw GeometryError(e.what());
  }
  const UpdateStats update = reconstructor.update();
  if (stats_out) *stats_out = update.step;
  return reconstructor.mesh();
}

}  // namespace sonoshape::recon
