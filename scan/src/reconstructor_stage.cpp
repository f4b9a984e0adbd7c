// recon::Reconstructor as the pipeline's reconstruction stage (its own file: tests of the
// pipeline with a fake stage do not link the engine).
#include <utility>

#include "sonoshape/scan/stages.hpp"

namespace sonoshape::scan {
namespace {

class ReconstructorStage final : public ReconstructionStage {
 public:
  explicit ReconstructorStage(const recon::ReconstructorOptions& options)
      : options_(options), reconstructor_(live_options(options)) {}
  int add_slice(LabeledSlice slice) override { return reconstructor_.add_slice(std::move(slice)); }
  recon::UpdateStats update() override { return reconstructor_.update(); }
  const MeshSet& meshes() const override { return reconstructor_.mesh(); }
  SliceSet slice_set() const override { return reconstructor_.slice_set(); }
  std::size_t slice_count() const override { return reconstructor_.slice_count(); }

  // The live updates' meshes are previews: the thin-plate meshes' refinement onto the field's
  // zero set (as much again as the mesher) and small organs' grids of their own (rebuilt as an
  // organ grows in the sweep: spikes of a few hundred milliseconds) wait for the settled meshes.
  static recon::ReconstructorOptions live_options(recon::ReconstructorOptions options) {
    options.refine_meshes = false;
    options.engine.own_grids = false;
    return options;
  }

  // The mean-value field's online updates equal its one-shot reconstruction (to the bit);
  // the thin-plate field's agree with it to its online tolerance (docs/engine.md, section 8),
  // so its final meshes are solved again from all the slices at once.
  std::optional<recon::UpdateStats> settle() override {
    if (options_.engine.field != recon::FieldKind::thin_plate || slice_count() == 0)
      return std::nullopt;
    recon::Reconstructor one_shot(options_);
    for (LabeledSlice& slice : reconstructor_.slice_set().slices)
      one_shot.add_slice(std::move(slice));
    recon::UpdateStats stats = one_shot.update();
    reconstructor_ = std::move(one_shot);
    return stats;
  }

 private:
  recon::ReconstructorOptions options_;
  recon::Reconstructor reconstructor_;
};

}  // namespace

std::unique_ptr<ReconstructionStage> make_reconstructor_stage(
    const recon::ReconstructorOptions& options) {
  return std::make_unique<ReconstructorStage>(options);
}

}  // namespace sonoshape::scan
