#pragma once
// What a scan knows before its first frame: the calibration, how to segment the frames, the
// materials, and the scan volume.
#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/segmentation/config.hpp"
#include "sonoshape/segmentation/segmenter.hpp"

namespace sonoshape::scan {

/// The setup of one scan.
struct ScanSetup {
  /// Calibration: image pixels -> probe mm (PLUS ImageToProbe, includes the pixel spacing).
  Eigen::Matrix4d T_probe_image = Eigen::Matrix4d::Identity();
  segmentation::SegmentationConfig segmentation;  ///< label models, filters
  segmentation::ImageGeometry geometry;           ///< image size, sector (the slices' fov), depths
  std::vector<LabelInfo> labels;  ///< materials, for the reconstruction and the meshes
  /// The scan volume (mm, reference frame) for the reconstruction; none: grown from the slices.
  std::optional<Box3> bounds;
  std::string calibration_from;  ///< where T_probe_image came from (for the log)
  std::string models_from;       ///< where the label models came from
  std::string sector_from;       ///< where the sector came from
};

/// The image corners keyframe selection compares: the corners of the sector's bounding box
/// (the whole image when the setup has no sector outline), in pixels.
std::array<Vec2, 4> keyframe_corners(const ScanSetup& setup);

}  // namespace sonoshape::scan
