#pragma once
// The reconstruction as the segmentation's prior: the surfaces built from the slices so far, cut
// by a new frame's plane and drawn into its pixels, predict that frame's label map.
#include <optional>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/recon/reconstructor.hpp"
#include "sonoshape/segmentation/labeller.hpp"

namespace sonoshape::scan {

/// The label map that `meshes` (closed, one per material) predict for a frame in `plane`: each
/// pixel inside the sector gets the label of the innermost mesh around it (nested organs), else
/// 0; kLabelPixelUnknown outside the sector. Empty meshes predict background.
LabelImage predict_label_map(const MeshSet& meshes, const segmentation::ImagePlane& plane,
                             const segmentation::ImageGeometry& geometry);

/// A LabelPredictor backed by its own online Reconstructor (for `segment`, which has none).
class ReconstructionPrior final : public segmentation::LabelPredictor {
 public:
  /// `options` set up the reconstruction (give the scan's box as bounds: a box that grows forces
  /// full rebuilds). Throws like recon::Reconstructor.
  explicit ReconstructionPrior(recon::ReconstructorOptions options);
  /// Updates the reconstruction with the slices added since the last call, then predicts;
  /// none before any material has a mesh. A failed update keeps the previous meshes.
  std::optional<LabelImage> predict(const segmentation::ImagePlane& plane,
                                    const segmentation::ImageGeometry& geometry) override;
  void add(const LabeledSlice& slice) override;

 private:
  recon::Reconstructor reconstructor_;
  bool pending_ = false;
};

}  // namespace sonoshape::scan
