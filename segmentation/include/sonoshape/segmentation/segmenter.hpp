#pragma once
// Frame -> label map: speckle-reducing filtering, depth compensation, per-pixel classification
// by the label models, shadow / low-confidence detection (unknown), and morphological cleaning.
#include <vector>

#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/segmentation/config.hpp"

namespace sonoshape::segmentation {

/// What the segmenter knows about the image geometry (the same for every frame of a sweep).
struct ImageGeometry {
  int width_px = 0;
  int height_px = 0;
  ImageU8 sector;   ///< 255 where the probe sees, 0 elsewhere (width_px x height_px)
  Ring2 sector_px;  ///< the sector's outline in pixel coordinates (column, row); the slice fov
  /// Depth below the transducer face along the beam (mm), per pixel, row-major; empty: the
  /// row's distance below the sector's top row.
  std::vector<float> depth_mm;
  double spacing_mm = 1.0;  ///< mm per pixel (geometric mean of the two directions)

  /// Throws std::invalid_argument when sizes disagree or the spacing is not positive.
  void check() const;
};

/// The whole image as the sector (a rectangle), depth = row * spacing.
ImageGeometry full_image_geometry(int width_px, int height_px, double spacing_mm);
/// A sector given as a polygon in pixel coordinates (rasterised for the mask); depth = rows
/// below the polygon's top. Throws std::invalid_argument for fewer than 3 points.
ImageGeometry polygon_geometry(int width_px, int height_px, double spacing_mm,
                               const Ring2& sector_px);
/// The sector found from the frames: the convex hull of the pixels whose median-filtered grey
/// exceeds `signal_grey` in at least one frame (specks removed by an opening); a hull is a
/// simple polygon by construction and fits a linear probe's rectangle and a convex probe's fan.
/// Falls back to the full image when the hull covers less than 1% of it.
ImageGeometry auto_geometry(const std::vector<const GreyImage*>& frames, double spacing_mm,
                            double signal_grey);

/// The label map of one frame and the intermediate maps (for pictures and diagnostics).
struct Segmentation {
  LabelImage labels;       ///< 0 background, material ids, kLabelPixelUnknown (outside, shadow)
  GreyImage smoothed;      ///< speckle-reduced, depth-compensated grey (0 outside the sector)
  ImageU8 low_confidence;  ///< 255 where the confidence rule made the pixel unknown
  double depth_slope_grey_per_mm = 0.0;  ///< the depth trend removed
  std::size_t unknown_in_sector_px = 0;  ///< sector pixels left unknown
};

/// Segments one frame. `image` must match the geometry's size (throws std::invalid_argument
/// otherwise, and for a configuration that fails validate()). Pixels outside the sector, in
/// shadows and beyond max_depth_mm are kLabelPixelUnknown; no material component is smaller
/// than min_region_mm2 and no label touches another one only diagonally (so every label's
/// contours are simple polygons).
Segmentation segment_frame(const GreyImage& image, const ImageGeometry& geometry,
                           const SegmentationConfig& config);

}  // namespace sonoshape::segmentation
