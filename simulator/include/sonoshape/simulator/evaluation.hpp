#pragma once
// Accuracy of a reconstruction against ground truth meshes, beside the closest-point baseline.
#include <map>
#include <optional>
#include <vector>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::simulator {

/// Per-label scores. Distances are in % of the evaluation box diagonal. A score that cannot be
/// computed (no slices given, label missing from the reconstruction, no contour of the label)
/// is NaN.
struct LabelScore {
  int label = 1;
  bool reconstructed = true;           ///< false: the reconstruction has no mesh for the label
  double iou = 0.0;                    ///< volumetric IoU of the reconstruction vs truth
  double baseline_iou = 0.0;           ///< same for the closest-point baseline (needs slices)
  double mean_surface_distance = 0.0;  ///< symmetric mean, % of diagonal
  double hausdorff_distance = 0.0;     ///< symmetric max, % of diagonal
  double contour_mean = 0.0;           ///< input contour points to output surface, mean, %
  double contour_max = 0.0;            ///< same, max, %
  /// 6-connected components of the inside samples of the IoU grid: reconstruction, baseline
  /// (-1 without slices) and truth (shows a method joining or splitting parts).
  int components = 0, baseline_components = -1, truth_components = 0;
  MeshHealth health;
};

struct EvaluationOptions {
  int grid_resolution = 200;             ///< IoU samples per axis of the box (fine enough that the
                                         ///< sampling error stays well below the IoU differences)
  int surface_samples = 20000;           ///< points sampled per surface for distances
  double contour_step_fraction = 0.002;  ///< contour sampling step, fraction of diagonal
};

/// Scores every label present in `truth`. `slices` (optional) enables the baseline and contour
/// fidelity; `box` is the evaluation box (usually the slice set's bounds). IoU samples the cell
/// centres of a grid_resolution^3 grid over `box` (inside = odd number of surface crossings
/// along z, so meshes need not be oriented). Throws GeometryError for an empty box or a
/// resolution below 1.
std::vector<LabelScore> evaluate(const MeshSet& reconstruction, const MeshSet& truth,
                                 const SliceSet* slices, const Box3& box,
                                 const EvaluationOptions& options = {});

}  // namespace sonoshape::simulator
