#pragma once
// Unknown regions and fields of view added to ground-truth slice sets, as the segmentation of real
// ultrasound frames reports them: blobs of shadow or noise over contours, and each frame seeing
// only its own sector of the plane.
#include <cstdint>
#include <string>

#include "sonoshape/core/slice.hpp"

namespace sonoshape::simulator {

enum class FovShape { kNone, kSector, kRect };

/// Parses "none" | "sector" | "rect"; throws std::invalid_argument otherwise.
FovShape parse_fov_shape(const std::string& name);

struct UnknownOptions {
  double fraction = 0.0;      ///< share of slices that get an unknown blob over a contour
  double blob_radius = 0.03;  ///< mean blob radius, fraction of the bounds' diagonal
  FovShape fov = FovShape::kNone;
  double fov_depth_mm = 80.0;   ///< sector radius / rectangle depth
  double fan_angle_deg = 60.0;  ///< sector opening
  double rect_width_mm = 60.0;  ///< rectangle width
  /// false: the fov's axis passes through the centre of the slice's material, at half depth
  /// (fixed size; parts of large cross-sections fall outside). true: as a sonographer aims the
  /// probe at the organ and sets the depth to see it whole: the fov's size follows the material's
  /// bounding circle, which it contains (the fan angle is kept).
  bool fov_covers_material = false;
  std::uint64_t seed = 1;
};

/// Adds a field of view to every slice (material regions are clipped to it; the probe looks at
/// the slice's material from a random side; see fov_covers_material) and replaces, on `fraction` of
/// the slices, a random blob over a contour by an unknown region (materials lose the blob). Regions
/// stay a valid partition: the blob and the materials share their common boundary vertex for
/// vertex.
void add_unknowns(SliceSet& set, const UnknownOptions& options);

}  // namespace sonoshape::simulator
