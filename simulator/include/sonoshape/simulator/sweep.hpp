#pragma once
// A whole simulated acquisition as PLUS sequence files: the B-mode sweep (with the probe
// calibration, sector geometry and per-label grey levels in its header, so a segmenter needs
// nothing else) and the ground-truth label frames.
//
// Header fields written (global, besides the MetaImage layout):
//   UltrasoundImageOrientation = MFA, UltrasoundImageType = BRIGHTNESS, ElementSpacing = 1 1 1
//   ImageToProbeTransform = 16 numbers (pixels -> probe mm, PLUS ImageToProbe)
//   SonoshapeProbeType = linear | convex, SonoshapeProbeDepthMm, SonoshapeProbeWidthMm,
//   SonoshapeProbeFanAngleDeg, SonoshapeProbeRadiusMm, SonoshapeProbeFrequencyMhz,
//   SonoshapePixelSpacingMm  (the sector: acquisition/probe.hpp's probe_fields)
//   SonoshapeLabels = 1:name 2:name ...; SonoshapeLabelEchogenicity = 0:e0 1:e1 ...
//   SonoshapeLabelGreyMean / SonoshapeLabelGreyStd = 0:m0 1:m1 ... (measured on the known
//   pixels of the whole sweep; 0 is the background)
//   SonoshapeUnknownLabel = 255, SonoshapeShadowThresholdDb, SonoshapeSeed, SonoshapeTrajectory,
//   SonoshapeFrameRateHz, SonoshapeTracker{RateHz,LatencySec,PositionNoiseMm,AngleNoiseDeg}
// Per frame: Timestamp, ImageStatus = OK, ProbeToTrackerTransform(+Status) as tracked (noise,
// latency, INVALID), ReferenceToTrackerTransform = identity (the phantom is the tracker's
// reference), TrueProbeToReferenceTransform (the exact pose, for evaluation only).
#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <vector>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace sonoshape::simulator {

/// The simulated sweep and its ground truth.
struct SimulatedSweep {
  acquisition::SequenceFile bmode;  ///< B-mode frames with the fields above
  acquisition::SequenceFile
      truth;  ///< label frames (0 background, ids, 255 unknown), same frame fields
  std::vector<LabeledSlice> slices;  ///< exact cut per frame (true pose), fov = the sector
  double mean_shadow_fraction = 0.0;
};

/// Called with the number of frames done (from the calling thread).
using SweepProgress = std::function<void(std::size_t done)>;

/// Renders every frame of `acquisition` at its true pose (speckle seeded by seed and frame
/// index, so the result does not depend on threading) and records the tracked poses. Frames run
/// in parallel (TBB).
SimulatedSweep simulate_sweep(const BModeSimulator& simulator,
                              const SimulatedAcquisition& acquisition, std::uint64_t seed,
                              const SweepProgress& progress = {});

/// The longest run (pixels) of each label down an image column of the frame's truth, for the
/// labels that keep their pixels inside their own shadow (bone; see SimulatedFrame::truth); 0
/// for the others.
std::array<int, 256> shadow_caster_runs_px(const SimulatedFrame& frame);
/// The thickness along the beam (mm) of each such organ over many frames: the median of its
/// runs in the frames that show it (runs from shadow_caster_runs_px), times the pixel spacing.
std::map<int, double> shadow_caster_thickness_mm(const std::vector<std::array<int, 256>>& runs_px,
                                                 double spacing_mm);

}  // namespace sonoshape::simulator
