#pragma once
// Label map -> polygons with holes in mm -> LabeledSlice in the reference frame.
#include <Eigen/Core>
#include <vector>

#include "sonoshape/core/image.hpp"
#include "sonoshape/core/repairs.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::segmentation {

/// The plane of an image in the reference frame and the map from pixels to its (u, v) mm.
struct ImagePlane {
  Vec3 origin_mm = Vec3::Zero();  ///< the probe origin projected onto the image plane
  Vec3 u = Vec3::UnitX();         ///< along increasing columns
  Vec3 v = Vec3::UnitY();         ///< orthogonal to u, towards increasing rows
  /// Pixel (column i, row j) -> plane (a, b) mm: [a b]^T = pixel_to_plane * [i j 1]^T.
  Eigen::Matrix<double, 2, 3> pixel_to_plane = Eigen::Matrix<double, 2, 3>::Zero();

  Vec2 to_plane(double i, double j) const { return pixel_to_plane * Eigen::Vector3d(i, j, 1.0); }
  /// mm per pixel, geometric mean of the two directions.
  double spacing_mm() const;
};

/// The image plane of T_reference_image = T_reference_probe * T_probe_image (pixels -> mm,
/// PLUS ImageToReference; may include scale and a small shear, as real calibrations do): u and
/// v are the orthonormalised images of the pixel axes. `probe_origin_mm` (the probe's origin in
/// the reference frame) is projected onto the plane to become its origin, so that a calibration
/// without shear gives plane coordinates equal to the probe's (x, y) mm. Throws GeometryError
/// when the pixel axes are degenerate.
ImagePlane image_plane(const Eigen::Matrix4d& T_reference_image, const Vec3& probe_origin_mm);

/// How label_map_regions draws an outline before simplifying it.
enum class OutlineForm {
  /// Along the pixels' edges: the rings enclose exactly the label's pixels (a staircase on a
  /// slanted boundary).
  kPixelEdges,
  /// The marching-squares outline of the label's mask (the midpoints of the staircase's unit
  /// edges), smoothed along the outline by a few Taubin steps that move no point more than
  /// 0.35 px: a slanted boundary comes out straight instead of swinging about the line its
  /// pixels sample. The corners where three values meet (or a pinch was removed) stay, so that
  /// neighbouring labels keep sharing their edges.
  kSmooth,
};

/// The regions of a label map: for every material id and for unknown pixels inside `sector`
/// (pixels outside it are left to the slice's fov), outer rings and holes mapped into the plane.
/// Valid by construction (docs/segmentation.md, "Polygons"): each label's mask loses the pixels
/// that touch only diagonally (a pinch), its outlines are traced on the pixels' edges (through
/// cv::findContours, RETR_CCOMP, at twice the resolution, so that one-pixel necks keep their
/// width), and all rings are simplified together by `tolerance_mm` with CGAL's
/// topology-preserving polyline simplification, which simplifies an edge that two labels share
/// once for both (0 with OutlineForm::kPixelEdges: the exact outlines, whose area is the
/// pixels'). Rings are simple, holes lie
/// inside their outer ring touching it nowhere, rings of one label do not touch, and regions of
/// neighbouring labels share edges but no area. A ring that still comes out degenerate is
/// dropped and recorded in `repairs` (kind "degenerate_region"; `where` names the label).
std::vector<Region> label_map_regions(const LabelImage& labels, const ImageU8& sector,
                                      const ImagePlane& plane, double tolerance_mm,
                                      std::vector<Repair>* repairs = nullptr,
                                      OutlineForm form = OutlineForm::kPixelEdges);

/// Drops every region of `slice` that is not valid on its own (validate_slice_set: a ring that
/// crosses or touches itself, a hole outside its outer ring, ...) and records each in `repairs`
/// (kind "invalid_region", the label in `where`, the check's message, the region's area in mm²).
void drop_invalid_regions(LabeledSlice& slice, std::vector<Repair>* repairs);

/// A LabeledSlice of a segmented frame: the plane, the fov (`sector_px` mapped into the plane)
/// and the regions of label_map_regions (in `form`, by default with cut corners). The slice is
/// checked with validate_slice_set; should the simplified polygons fail, the exact pixel
/// outlines are taken, and should one of those fail,
/// that region is dropped and recorded in `repairs` (kind "invalid_region", with its area).
/// Fails (with validate_slice_set's message) only when the fov itself is invalid or dropping
/// regions does not help.
Result<LabeledSlice> make_slice(const LabelImage& labels, const ImageU8& sector,
                                const Ring2& sector_px, const ImagePlane& plane,
                                double tolerance_mm, std::vector<Repair>* repairs = nullptr,
                                OutlineForm form = OutlineForm::kSmooth);

}  // namespace sonoshape::segmentation
