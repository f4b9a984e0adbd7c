#pragma once
// B-mode synthesis: cut the phantom with the image plane (slice_meshes), rasterise the labels,
// and render an ultrasound-like image with a convolution model along the beams: Rayleigh
// speckle scaled by each tissue's echogenicity, specular echoes at boundaries (strength from
// the impedance jump and the angle of incidence), attenuation with depth partly compensated by
// time-gain compensation, and shadows behind strong reflectors and absorbers; then log
// compression and scan conversion. Also returns the ground truth a careful segmenter should
// produce: the labels, unknown (255) outside the sector and in shadows (but a bone, which
// shadows its own inside, keeps its whole cross-section).
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>

#include "sonoshape/acquisition/probe.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/simulator/phantom.hpp"

namespace sonoshape::simulator {

struct BModeOptions {
  double dynamic_range_db = 50.0;  ///< echo range mapped onto grey 0..255 (log compression)
  /// Gain before log compression: places the background speckle at about grey 120.
  double gain_db = -28.5;
  /// Fraction of the background tissue's attenuation that time-gain compensation undoes (the
  /// rest shows as darkening with depth).
  double tgc_fraction = 0.8;
  /// Point-spread function, Gaussian sigma along the beam in wavelengths (1.54 mm / f_MHz):
  /// finer at higher frequency, as with real probes.
  double psf_axial_wavelengths = 0.6;
  double psf_lateral_wavelengths = 1.5;  ///< ... and across beams
  /// Amplitude of a normal-incidence specular echo per unit reflection coefficient, relative
  /// to the background's mean speckle amplitude.
  double specular_gain = 300.0;
  /// Extra loss (dB, round trip) beyond what background tissue would cause at the same depth
  /// from which a pixel counts as shadowed: unknown in the ground truth.
  double shadow_threshold_db = 12.0;
};

/// One simulated frame.
struct SimulatedFrame {
  GreyImage bmode;    ///< the B-mode image, 0 outside the sector
  LabelImage labels;  ///< the cut rasterised (0 background, label ids), 255 outside the sector
  /// `labels` with shadowed pixels also 255 (unknown), except those of an organ that shadows
  /// its own inside (bone): they keep its label.
  LabelImage truth;
  ImageU8 shadow;  ///< 255 where the pixel is shadowed (whatever its label), else 0

  /// `truth` with every shadowed pixel unknown: what the image shows of each label (the pixels
  /// to learn grey models from).
  LabelImage visible_truth() const;
  /// The exact cut in the reference frame: (u, v) = the probe's (x, y) axes, so its in-plane
  /// coordinates are probe mm; fov = the sector.
  LabeledSlice slice;
  double shadow_fraction = 0.0;  ///< share of the sector's pixels that are shadowed
};

/// Pixel labels of a slice whose in-plane (u, v) coordinates are probe (x, y) mm: a pixel gets a
/// region's label when its centre (Probe::pixel_to_mm) is inside the region (outer ring minus
/// holes, even-odd), else kLabelPixelOutside. Pixels outside the sector are not masked here.
/// Throws GeometryError for region labels outside 1..254.
LabelImage rasterize_labels(const LabeledSlice& slice, const acquisition::Probe& probe);

/// Renders frames of one phantom with one probe. Construction precomputes the scan-conversion
/// tables; render() is const and may run on several threads at once.
class BModeSimulator {
 public:
  /// Throws GeometryError for an empty phantom or labels outside 1..254.
  BModeSimulator(Phantom phantom, const acquisition::Probe& probe,
                 const BModeOptions& options = {});
  ~BModeSimulator();
  BModeSimulator(BModeSimulator&&) noexcept;
  BModeSimulator& operator=(BModeSimulator&&) noexcept;

  const Phantom& phantom() const;
  const acquisition::Probe& probe() const;
  const BModeOptions& options() const;
  /// The point-spread function's Gaussian sigma (mm): the mean of its lateral and axial sigmas
  /// at the probe's frequency (what a segmenter's blooming correction needs).
  double psf_sigma_mm() const;
  /// Whether tissue `label` (1..254) loses the shadow threshold within a millimetre (bone): it
  /// shadows its own inside and what lies beyond it, and keeps its whole cross-section in the
  /// truth (SimulatedFrame::truth), so its section's edge along its shadow is its surface.
  bool casts_shadow(int label) const;

  /// The frame seen by the probe at T_reference_probe; the speckle pattern comes from `seed`
  /// (same seed and pose: the same image, bit for bit).
  SimulatedFrame render(const Eigen::Isometry3d& T_reference_probe, std::uint64_t seed) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sonoshape::simulator
