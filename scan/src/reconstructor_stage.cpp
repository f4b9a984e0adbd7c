// recon::Reconstructor as the pipeline's reconstruction stage (its own file: tests of the
// pipeline with a fake stage do not link the engine).
#include <stdexcept>
#include <utility>

#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/scan/stages.hpp"

namespace sonoshape::scan {
namespace {

class ReconstructorStage final : public ReconstructionStage {
 public:
  explicit ReconstructorStage(const recon::ReconstructorOptions& options)
      : options_(options), reconstructor_(options) {}
  // A slice wholly outside the scan volume adds nothing, and the scan's slices.json (whose
  // bounds are that volume) must hold no slice that the slice-set reader refuses.
  int add_slice(LabeledSlice slice) override {
    if (options_.bounds && !slice_meets_box(slice, *options_.bounds))
      throw std::invalid_argument("it lies wholly outside the scan volume, where it adds nothing");
    return reconstructor_.add_slice(std::move(slice));
  }
  recon::UpdateStats update() override { return reconstructor_.update(); }
  const MeshSet& meshes() const override { return reconstructor_.mesh(); }
  SliceSet slice_set() const override { return reconstructor_.slice_set(); }
  std::size_t slice_count() const override { return reconstructor_.slice_count(); }

  // The mean-value field's online updates equal its one-shot reconstruction (to the bit);
  // the thin-plate field's agree with it to the solver's tolerance (docs/engine.md, section 8),
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
