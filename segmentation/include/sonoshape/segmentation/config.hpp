#pragma once
// What the segmenter knows about the materials of an image: one grey-level model per label, and
// the parameters of filtering, shadow detection, morphology and simplification (all lengths in
// mm, so one configuration serves images of any pixel spacing). The JSON form is documented in
// docs/segmentation.md.
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::segmentation {

/// Grey-level model of one label: the mean and spread of its B-mode grey (0..255) over the
/// known pixels of typical frames (what the simulator writes as SonoshapeLabelGreyMean/Std).
struct LabelModel {
  int label = 1;  ///< material id 1..254; 0 for the background (the outside material)
  std::string name;
  double grey_mean = 128.0;
  double grey_std = 25.0;
  /// For a strong reflector that shadows its own inside (bone): its extent along the beam below
  /// its surface echo (mm), the anatomy that fills its cross-section (see segment_frame); 0:
  /// unknown, only the visible surface band gets the label.
  double thickness_mm = 0.0;
  /// A point inside the organ in the reference frame (mm), as a clinician marks it once: where
  /// organs look alike (grey models the image cannot tell apart), a region the reconstruction
  /// does not predict takes the label of the nearest seed (see GraphCutLabeller). None: unknown.
  std::optional<Vec3> seed_mm = std::nullopt;
};

/// Where the image sector (the part of the frame the probe sees) comes from.
enum class SectorSource {
  kDefault,  ///< the sequence header's probe (simulated sweeps), else kAuto
  kAuto,     ///< pixels that carry signal in some frame (largest component, filled)
  kFull,     ///< the whole image
  kPolygon,  ///< SegmentationConfig::sector_polygon_px
};

/// Parameters of the graph-cut labelling (nats: natural-log likelihood units per pixel).
struct GraphCutOptions {
  double cell_mm = 0.6;          ///< grid cell size (a cell is a block of pixels)
  double smoothness = 1.5;       ///< Potts weight per pixel of boundary between equal greys
  double prior_weight = 1.0;     ///< cost per pixel of disagreeing with a confident prior
  double prior_margin_mm = 2.0;  ///< the prior's confidence grows over this distance from its
                                 ///< own boundaries (the reconstruction is least sure there)
  double model_update = 0.3;     ///< weight of each frame in the running appearance models
  int cycles = 1;                ///< expansion passes over all labels (a second pass changed no
                                 ///< pixel of the benchmark sweeps: it is off)

  /// Errors name the field as the configuration's "graph_cut" object does.
  Status validate() const;
};

/// How a frame's pixels get their labels.
enum class LabellingMethod {
  kThreshold,  ///< nearest grey model per pixel after smoothing, then morphology
  kGraphCut,   ///< that labelling refined by a graph cut (see GraphCutLabeller)
};

/// Segmentation parameters. Defaults suit the simulator's frames; lengths are in mm.
struct SegmentationConfig {
  LabelModel background{0, "background", 120.0, 28.0};
  std::vector<LabelModel> materials;  ///< ids >= 1, distinct; empty: see auto_two_class

  /// Speckle reduction: median filter (pixels, odd, >= 1) then Gaussian of this sigma (mm).
  int median_px = 5;
  double smoothing_mm = 0.8;
  /// Boundary echoes (a specular line along a boundary, brighter than the tissues on both sides)
  /// are filled from both sides before the speckle reduction, so that the boundary lies at the
  /// line's middle instead of the brighter tissue taking the line: a line counts when it stands
  /// out by more than this many background grey spreads (grey_std). 0: off (the presets whose
  /// targets are such lines: wires, water-tank, bone).
  double boundary_echo_contrast = 1.0;
  /// Window (Gaussian sigma, mm) of the local mean and standard deviation behind confidence.
  double confidence_window_mm = 1.0;
  /// A pixel is dark when its grey is at most shadow_grey; where more than shadow_fraction of
  /// the pixels in the confidence window are dark, there is no signal (shadow, lost signal):
  /// unknown. Speckle of any tissue keeps a large spread in log-compressed grey, so even dark
  /// tissue rarely passes. Negative shadow_grey: derived from the darkest label (see
  /// effective_shadow_grey).
  double shadow_grey = -1.0;
  double shadow_fraction = 0.85;
  /// Unknown areas grow by this margin (mm): their edges are where confidence is lowest.
  double shadow_margin_mm = 1.5;
  /// Beyond this depth (mm along the beam) nothing is trusted; 0: no limit.
  double max_depth_mm = 0.0;
  /// The imaging system's point-spread function, Gaussian sigma (mm, mean of lateral and axial)
  /// and the log compression's range (dB): where two tissues meet, the blurred echo power puts
  /// the grey midpoint inside the darker one (blooming); the labelling moves such boundaries
  /// back by the shift these imply. Negative: the simulated sweep's header gives them
  /// (SonoshapePsfSigmaMm, SonoshapeDynamicRangeDb), else no correction; 0: no correction (a
  /// probe's data sheet gives its resolution).
  double psf_sigma_mm = -1.0;
  double dynamic_range_db = 50.0;
  /// Removes the residual depth trend of the grey (attenuation not undone by time-gain
  /// compensation), fitted per frame as a line in depth.
  bool depth_compensation = true;
  /// Morphological opening radius (mm) of every label's mask: thinner bits are re-labelled from
  /// their neighbours.
  double opening_mm = 0.6;
  /// Connected components smaller than this (mm^2) are re-labelled from their surroundings.
  double min_region_mm2 = 25.0;  // speckle grains misread as tissue stay below a 5 x 5 mm patch
  /// Polygon simplification tolerance (mm, approxPolyDP); reduced per slice where the
  /// simplified polygons would not be valid.
  double simplify_mm = 0.3;
  /// The segmented outlines' error (standard deviation, mm) written with every slice
  /// (LabeledSlice::outline_sd_mm): the thin-plate field fits outlines with an error as a
  /// smoothing spline. The default scan's outlines lie 0.34-0.53 mm from the truth's on average
  /// (bench/outline_bias.py's mean distance: rib, cheburashka, spot), a standard deviation of
  /// about 0.4-0.7 mm if the errors were normal. 0: interpolate them. Label
  /// maps that replace the segmenter (--labels, --perfect-labels) are taken as drawn (0).
  double outline_sd_mm = 0.6;

  /// The label models above are starting points: prepare_sweep refines them on the recording's
  /// grey levels (learn_models_from_samples), keeping their names and roles. What a preset
  /// gives: the kinds of echo it expects, not the grey levels of one scanner's settings.
  bool learn_models = false;

  LabellingMethod method = LabellingMethod::kThreshold;
  GraphCutOptions graph_cut;

  SectorSource sector = SectorSource::kDefault;
  Ring2 sector_polygon_px;  ///< kPolygon: the sector in pixel coordinates (column, row)
  /// kAuto: a pixel carries signal when its median-filtered grey exceeds this in some frame.
  double sector_signal_grey = 6.0;

  /// The shadow grey in effect: shadow_grey, or 40% of the darkest label's mean, in [6, 50].
  double effective_shadow_grey() const;
  /// Checks ranges and label ids; the message names the field and the fix.
  Status validate() const;
};

/// The slice set's entry of a material the segmenter labels: a model with a thickness is a bone
/// whose section is drawn whole (to that thickness below its surface echo), so its section ends
/// where it ends, also along its shadow (LabelInfo::casts_shadow). Without a thickness only the
/// visible surface band is labelled, and its edge along the shadow is not the bone's end.
LabelInfo slice_label(const LabelModel& model);

/// Parses the JSON form (docs/segmentation.md); `source_name` names the input in messages.
/// Unknown keys are errors (a misspelt key must not be silently ignored).
Result<SegmentationConfig> parse_segmentation_config(const std::string& json_text,
                                                     const std::string& source_name);
/// Reads a JSON configuration file.
Result<SegmentationConfig> read_segmentation_config(const std::filesystem::path& path);

/// A named set of configuration settings for what a kind of recording holds (docs/segmentation.md,
/// "Presets"): `json` holds the keys it sets, in the configuration's JSON form.
struct SegmentationPreset {
  std::string name;
  std::string summary;  ///< one line for --help and messages
  std::string json;
};
/// The presets: soft-tissue (the defaults), wires, water-tank, bone.
const std::vector<SegmentationPreset>& segmentation_presets();
/// The configuration of `preset` (empty: the defaults), with the keys of the JSON file at
/// `path` (when given) over it: a key the file gives replaces the preset's (its "labels" all of
/// the preset's labels), "graph_cut" key by key. Fails for an unknown preset (naming the known
/// ones) and as read_segmentation_config does.
Result<SegmentationConfig> load_segmentation_config(
    const std::optional<std::filesystem::path>& path, std::string_view preset);
/// The JSON form of a configuration (round trips through parse_segmentation_config).
std::string to_json(const SegmentationConfig& config);

/// Learns the grey models of every label of a labelled example: `labels` holds 0 for the
/// background, material ids, and kLabelPixelUnknown (ignored). Sizes must match (throws
/// std::invalid_argument otherwise). Other parameters are copied from `base`. With
/// `interior_px` > 0 each label is learnt from its pixels at least that far (px) from any other
/// label's (or from all of its pixels when none is that far): the point-spread function mixes
/// the grey of the pixels near a boundary with the neighbour's, which pulls a small organ's
/// mean towards its surroundings.
SegmentationConfig learn_label_models(const GreyImage& image, const LabelImage& labels,
                                      const SegmentationConfig& base = {},
                                      double interior_px = 0.0);

/// The models of `base` (background and materials) refined on the grey levels of `samples` (any
/// pixels of the sector) by k-means started from their grey means: each model's mean and spread
/// become those of the samples nearest it (ids, names and thickness kept; a model no sample is
/// nearest keeps its own). Used for a configuration with learn_models.
SegmentationConfig learn_models_from_samples(const std::vector<std::uint8_t>& samples,
                                             const SegmentationConfig& base);

/// A two-class model for data nobody has labelled: the grey levels of `samples` (any pixels of
/// the sector) split in two by k-means; the darker class is the background and the brighter
/// one material 1 ("echogenic"). Used when neither a configuration nor the header gives models.
SegmentationConfig auto_two_class(const std::vector<std::uint8_t>& samples,
                                  const SegmentationConfig& base = {});

}  // namespace sonoshape::segmentation
