#pragma once
// What FrameSource and PoseSource deliver and the synchroniser pairs up (design.md, data path).
// Transform names follow PLUS: T_a_b maps b coordinates into a (PLUS's "BToA"), so
// T_reference_probe is PLUS's ProbeToReference.
#include <Eigen/Geometry>
#include <cstdint>

#include "sonoshape/core/image.hpp"

namespace sonoshape {

/// Whether a tracker measurement can be used (PLUS "OK"), or not ("INVALID", "MISSING", ...:
/// sensor out of the field, occluded marker, no sample near the frame's time).
enum class TrackingStatus { kValid, kInvalid };

/// One image from a FrameSource.
struct Frame {
  GreyImage image;
  double timestamp_s = 0.0;  ///< acquisition time on the frame source's clock
  std::int64_t index = 0;    ///< position in the stream, from 0
};

/// One tracker measurement from a PoseSource.
struct Pose {
  /// Probe (sensor) coordinates (mm) to reference coordinates (mm); rigid.
  Eigen::Isometry3d T_reference_probe = Eigen::Isometry3d::Identity();
  double timestamp_s = 0.0;  ///< time of the measurement on the pose source's clock
  TrackingStatus status = TrackingStatus::kValid;
};

/// A frame with the probe pose at its timestamp (interpolated from the tracker's samples).
/// Image pixels map into the reference frame by T_reference_probe * T_probe_image (the
/// calibration, PLUS's ImageToProbe, which includes the pixel spacing).
struct TrackedFrame {
  Frame frame;
  Eigen::Isometry3d T_reference_probe = Eigen::Isometry3d::Identity();
  TrackingStatus status = TrackingStatus::kValid;
};

}  // namespace sonoshape
