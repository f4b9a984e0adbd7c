#pragma once
// Ultrasound probe geometry: linear and curvilinear (convex) arrays, the image they produce and
// its calibration T_probe_image (pixels -> mm, PLUS's ImageToProbe), and the sequence-header
// fields that carry it (the simulator writes them, segmentation rebuilds the sector from them).
//
// Probe frame (mm): origin at the centre of the transducer face, x along the array (towards
// increasing image columns), y along the central beam into the body (towards increasing image
// rows), z = x cross y (elevation, the normal of the image plane). The image plane is z = 0.
#include <Eigen/Geometry>
#include <optional>
#include <string>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition {

enum class ProbeType { kLinear, kConvex };

/// Parses "linear" | "convex"; throws std::invalid_argument otherwise.
ProbeType parse_probe_type(const std::string& name);
std::string to_string(ProbeType type);

/// What defines a probe and its image. Pixels are square; the spacing follows from the image
/// size so that the sector's bounding box fits the image (centred horizontally, touching the
/// top).
struct ProbeGeometry {
  ProbeType type = ProbeType::kConvex;
  double depth_mm = 120.0;      ///< imaging depth along each beam, from the face
  double width_mm = 40.0;       ///< linear: aperture width (the image's lateral extent)
  double fan_angle_deg = 60.0;  ///< convex: total angle of the fan
  double radius_mm = 40.0;      ///< convex: radius of curvature of the face
  int width_px = 512;           ///< image columns (also the number of beams)
  int height_px = 512;          ///< image rows (also the number of samples per beam)
  double frequency_mhz = 3.5;   ///< centre frequency: attenuation grows with it
};

/// A typical abdominal curvilinear probe: 60 degrees, R 40 mm, 120 mm deep, 3.5 MHz.
ProbeGeometry convex_probe_geometry(int width_px = 512, int height_px = 512);
/// A typical linear probe: 40 mm wide, 50 mm deep, 7.5 MHz.
ProbeGeometry linear_probe_geometry(int width_px = 512, int height_px = 512);

/// Derived geometry of a probe: pixel <-> mm, the sector, and beam coordinates (beam index b
/// across the array, sample index s along the beam; both continuous, sample centres at
/// integers, b in [0, width_px), s in [0, height_px)).
class Probe {
 public:
  /// Throws GeometryError for non-positive sizes, a fan outside (0, 180) degrees or a
  /// non-positive radius.
  explicit Probe(const ProbeGeometry& geometry);

  const ProbeGeometry& geometry() const { return geometry_; }
  ProbeType type() const { return geometry_.type; }
  int width_px() const { return geometry_.width_px; }
  int height_px() const { return geometry_.height_px; }
  /// Pixel spacing (mm per pixel, both directions).
  double spacing_mm() const { return spacing_mm_; }

  /// Pixel (i = column, j = row, 0) -> probe mm; z scales by the spacing too, as PLUS writes
  /// ImageToProbe for a 2D image.
  Eigen::Affine3d T_probe_image() const;
  /// Pixel centre (i, j) (continuous) -> probe (x, y) mm, and back.
  Vec2 pixel_to_mm(double i, double j) const;
  Vec2 mm_to_pixel(const Vec2& xy_mm) const;

  /// Whether the probe point (x, y) mm is in the imaged sector (boundary included).
  bool in_sector(const Vec2& xy_mm) const;
  /// 255 for pixels whose centre is in the sector, 0 elsewhere.
  ImageU8 sector_mask() const;
  /// The sector's outline in probe (x, y) mm, counter-clockwise in (x, y); arcs of a convex
  /// probe with `arc_points` points each.
  Ring2 sector_ring_mm(int arc_points = 64) const;

  /// Probe (x, y) mm of beam coordinates (b, s).
  Vec2 beam_to_mm(double b, double s) const;
  /// Beam coordinates of a probe point (meaningful inside the sector).
  Vec2 mm_to_beam(const Vec2& xy_mm) const;
  /// Spacing of samples along a beam (mm).
  double axial_step_mm() const { return geometry_.depth_mm / geometry_.height_px; }
  /// Distance between neighbouring beams at sample s (mm): constant for linear probes,
  /// growing with depth for convex ones.
  double lateral_step_mm(double s) const;
  /// Depth below the face of sample s, along its beam (mm).
  double sample_depth_mm(double s) const { return (s + 0.5) * axial_step_mm(); }

 private:
  ProbeGeometry geometry_;
  double spacing_mm_ = 1.0;
  double top_mm_ = 0.0;  // probe y of image row 0
  double half_angle_rad_ = 0.0;
};

/// The probe's header fields: SonoshapeProbeType = linear | convex, SonoshapeProbeDepthMm,
/// SonoshapeProbeWidthMm, SonoshapeProbeFanAngleDeg, SonoshapeProbeRadiusMm,
/// SonoshapeProbeFrequencyMhz, SonoshapeImageSizePx = "W H", SonoshapePixelSpacingMm.
FieldList probe_fields(const Probe& probe);
/// Rebuilds the probe from a header holding probe_fields (a sweep written by `sonoshape
/// simulate`); fails naming the missing or invalid field.
Result<Probe> probe_from_fields(const FieldList& fields);

}  // namespace sonoshape::acquisition
