// recon::Reconstructor as the pipeline's reconstruction stage (its own file: tests of the
// pipeline with a fake stage do not link the engine).
#include <utility>

#include "sonoshape/scan/stages.hpp"

namespace sonoshape::scan {
namespace {

class ReconstructorStage final : public ReconstructionStage {
 public:
  explicit ReconstructorStage(const recon::ReconstructorOptions& options)
      : reconstructor_(options) {}
  int add_slice(LabeledSlice slice) override { return reconstructor_.add_slice(std::move(slice)); }
  recon::UpdateStats update() override { return reconstructor_.update(); }
  const MeshSet& meshes() const override { return reconstructor_.mesh(); }
  SliceSet slice_set() const override { return reconstructor_.slice_set(); }
  std::size_t slice_count() const override { return reconstructor_.slice_count(); }

 private:
  recon::Reconstructor reconstructor_;
};

}  // namespace

std::unique_ptr<ReconstructionStage> make_reconstructor_stage(
    const recon::ReconstructorOptions& options) {
  return std::make_unique<ReconstructorStage>(options);
}

}  // namespace sonoshape::scan
