#pragma once
// A whole tracked sweep (PLUS sequence file) -> slice set: the setup (label models, sector,
// calibration) from a configuration, the header `sonoshape simulate` writes, or the data, then
// one slice per frame with a valid pose.
#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>

#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/acquisition/pose_chain.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/repairs.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/segmentation/config.hpp"
#include "sonoshape/segmentation/labeller.hpp"
#include "sonoshape/segmentation/scoring.hpp"
#include "sonoshape/segmentation/sector_share.hpp"
#include "sonoshape/segmentation/segmenter.hpp"

namespace sonoshape::segmentation {

/// Everything segment_sweep needs besides the frames.
struct SweepSetup {
  SegmentationConfig config;
  ImageGeometry geometry;
  /// PLUS ImageToProbe of the frames as stored: a cropped recording's crop is folded in
  /// (ImageToProbe * ImageToCroppedImage^-1), so that pixel (i, j) of a cropped frame lands
  /// where pixel (i + x0, j + y0) of the full frame does.
  Eigen::Matrix4d T_probe_image = Eigen::Matrix4d::Identity();
  /// How each frame's pose is found (the probe's frame to the reconstruction's); none: the
  /// classic ReferenceToTracker^-1 * ProbeToTracker (legacy_pose_chain).
  std::optional<acquisition::PoseChain> pose_chain;
  std::string models_from;       ///< "config", "header", "two-class k-means"
  std::string calibration_from;  ///< where T_probe_image came from
  std::string sector_from;       ///< "header probe", "auto", "full", "config polygon"
};

/// The sector, its outline and the beam depth of a simulated sweep, rebuilt from the probe
/// fields `sonoshape simulate` writes in the header (SonoshapeProbeType, ...); fails naming the
/// missing or invalid field.
Result<ImageGeometry> geometry_from_header(const acquisition::FieldList& fields);

/// Reads the calibration ImageToProbe from a PLUS device-set XML or a PLUS calibration result
/// (*.results.xml; <Transform From="Image" To="Probe">) or a JSON file ({"ImageToProbe": [16
/// numbers, row-major]}).
Result<Eigen::Matrix4d> read_calibration(const std::filesystem::path& path);

/// Resolves the setup of a sweep read from `sequence_path`:
/// - models: `config_path` and `preset` when given (load_segmentation_config: the file's keys
///   over the preset's; its materials, refined on the frames with learn_models; when it has
///   none, the header's), else the header's SonoshapeLabelGreyMean/Std, else auto_two_class on
///   the frames;
/// - calibration: `calibration_path`, else the header's ImageToProbeTransform, else the
///   sidecar `<name>.plus.xml` next to the file; fails saying how to give one;
/// - sector: the config's choice; by default the header's probe, else found from the frames;
/// - pose: acquisition::find_pose_chain with `pose_transform` (empty: the header's or the default)
/// over
///   the file's transforms and those of the calibration's device set (or sidecar);
/// - crop: a per-frame ImageToCroppedImage folded into T_probe_image (fails when it moves).
Result<SweepSetup> prepare_sweep(const acquisition::SequenceFile& file,
                                 const std::filesystem::path& sequence_path,
                                 const std::optional<std::filesystem::path>& config_path,
                                 const std::optional<std::filesystem::path>& calibration_path,
                                 std::string_view pose_transform = {},
                                 std::string_view preset = {});
/// The same from an in-memory configuration (no file), for tests and tools; `config` replaces
/// the defaults but its empty materials are still taken from the header. `coordinates`: fixed
/// transforms for the pose chain (a device set's).
Result<SweepSetup> prepare_sweep(const acquisition::SequenceFile& file,
                                 const std::filesystem::path& sequence_path,
                                 const std::optional<SegmentationConfig>& config,
                                 const std::optional<Eigen::Matrix4d>& T_probe_image,
                                 std::string_view pose_transform = {},
                                 const acquisition::PlusConfig& coordinates = {});

/// Brings a PLUS recording read from `path` to what a sweep expects, as PLUS does on reading:
/// frames flipped to MF (acquisition::reorient_to_mf, logged), and every frame a Timestamp when
/// none has one (acquisition::fill_missing_timestamps, one warning), so that `segment` and `scan
/// --source replay:` get the same frames. Fails as reorient_to_mf does.
Status normalise_recording(acquisition::SequenceFile& file, const std::filesystem::path& path);

/// The pose of frame k: ReferenceToTracker^-1 * ProbeToTracker (ProbeToTracker alone when the
/// file has no ReferenceToTracker); none when a status is not OK or a transform is unreadable.
std::optional<Eigen::Matrix4d> reference_from_probe(const acquisition::SequenceFile& file,
                                                    std::size_t k);
/// The pose of frame k along `setup`'s pose chain (the legacy one when it has none).
std::optional<Eigen::Matrix4d> reference_from_probe(const acquisition::SequenceFile& file,
                                                    std::size_t k, const SweepSetup& setup);

/// A repair the segmenter made in one frame (see make_slice).
struct FrameRepair {
  std::size_t frame = 0;  ///< index of the frame in the file
  Repair repair;
};

/// What segment_sweep did.
struct SweepSegmentation {
  SliceSet slices;
  std::size_t frames = 0;         ///< frames in the file
  std::size_t considered = 0;     ///< frames kept by `every`
  std::size_t invalid_pose = 0;   ///< skipped: INVALID or unreadable pose
  std::size_t coincident = 0;     ///< skipped: same plane as the previous slice
  std::size_t failed = 0;         ///< skipped: no valid polygons (see the log)
  double unknown_fraction = 0.0;  ///< mean share of the sector left unknown
  /// What was dropped to make the polygons of a frame valid, in frame order.
  std::vector<FrameRepair> repairs;
  /// With SweepLabels::truth: each segmented frame's label map against its truth frame, in frame
  /// order, and their sum.
  std::vector<FrameComparison> comparisons;
  LabelComparison comparison_total;
  /// Per material label of the setup: the frames whose label map holds it and the slices with a
  /// region of it (a label with frames but no slices lost every region to the repairs).
  std::map<int, std::size_t> frames_with_label;
  std::map<int, std::size_t> slices_with_label;
  /// SectorShareCheck over the segmented frames: the label (kLabelPixelUnknown for unknown) that
  /// fills nearly all of most sectors and the warning segment_sweep logged about it; none when
  /// no label does.
  std::optional<int> dominant_label;
  std::string dominant_warning;
  /// With ReadOptions::strict: the first repair as an error ("frame 12, unknown: ..."), after
  /// which the sweep stopped; empty otherwise.
  std::string refused;
};

/// Other sources and checks of the label maps, for simulated sweeps whose truth label frames
/// (`sonoshape simulate --truth DIR`: DIR/labels.mha) are known. Each file must hold one frame
/// per frame of the sweep, of the same size (check_truth_labels).
struct SweepLabels {
  /// When set, frame k's label map is this file's frame k instead of the segmenter's ("perfect
  /// labels"): the same contours and placement, so the run is the upper bound of the sweep.
  const acquisition::SequenceFile* perfect = nullptr;
  /// When set, every segmented frame's label map is compared with this file's frame of the
  /// same index (SweepSegmentation::comparisons).
  const acquisition::SequenceFile* truth = nullptr;
  /// When set, called with the index and the label map of every frame that gets one (the
  /// segmenter's or the perfect one), before its contours are traced: pictures, diagnostics.
  std::function<void(std::size_t frame, const LabelImage& labels)> on_label_map;
  /// With the graph-cut method: the reconstruction that predicts each frame (the cut's prior)
  /// and is given every slice made; none: the image alone.
  LabelPredictor* predictor = nullptr;
};

/// Called with the number of considered frames done.
using SweepProgress = std::function<void(std::size_t done)>;

/// Segments every `every`-th frame (from frame 0) of `file` into one slice each (in the
/// reference frame, fov = the sector, timestamp from the file). When one label fills nearly all
/// of most sectors (SectorShareCheck), one warning says so. A frame whose polygons needed a
/// repair logs one warning naming the frame and what was dropped; with `options.strict` the
/// first such frame stops the sweep instead (SweepSegmentation::refused). Throws
/// std::invalid_argument when `every` < 1, the frames do not match the setup's geometry, or a
/// file of `labels` does not match the frames (check_truth_labels says which).
SweepSegmentation segment_sweep(const acquisition::SequenceFile& file, const SweepSetup& setup,
                                int every = 1, const SweepProgress& progress = {},
                                const ReadOptions& options = {}, const SweepLabels& labels = {});

}  // namespace sonoshape::segmentation
