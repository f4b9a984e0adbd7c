#pragma once
// The probe's pose in a PLUS recording, found as PLUS's transform repository finds it: the
// coordinate frames are the nodes of a graph, each transform `<A>To<B>` an edge usable both
// ways (inverted), per-frame ones from the sequence file (`Seq_FrameNNNN_<A>To<B>Transform` with
// its `...TransformStatus`) and fixed ones from a device set's <CoordinateDefinitions>; the pose
// `<P>To<R>` is the product along the shortest path from P to R.
#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "sonoshape/acquisition/plus_config.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition {

/// "ProbeToTracker" (or "ProbeToTrackerTransform") -> {"Probe", "Tracker"}, split as PLUS does:
/// at a "To" followed by an upper-case letter with a non-empty part before it ("ToolToTracker"
/// is Tool -> Tracker). None when there is no such split or more than one.
std::optional<std::pair<std::string, std::string>> split_transform_name(std::string_view name);

/// One edge of a pose chain.
struct PoseChainStep {
  std::string name;       ///< the transform as stored, e.g. "ReferenceToTracker"
  bool per_frame = true;  ///< a field of every frame; else fixed (`matrix`)
  bool inverse = false;   ///< walked from its To frame to its From frame
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();  ///< fixed transform, as stored
};

/// The path from the probe's frame to the reconstruction's frame.
struct PoseChain {
  std::string from = "Probe";        ///< the frame the calibration ImageTo<from> maps into
  std::string to = "Reference";      ///< the reconstruction's frame
  std::vector<PoseChainStep> steps;  ///< in the order they are walked, from `from` to `to`
  std::string chosen_by;  ///< "--pose-transform", "the header's DefaultFrameTransformName", ...

  /// "ProbeToReference = ReferenceToTracker^-1 * ProbeToTracker (per frame)" for messages.
  std::string describe() const;
  /// Names of the per-frame transforms the chain reads.
  std::vector<std::string> per_frame_names() const;
  /// T_to_from of frame k (maps `from` coordinates into `to`); none when a per-frame step's
  /// status is not OK, its field is absent or unreadable, or the product is not finite.
  std::optional<Eigen::Matrix4d> pose(const SequenceFile& file, std::size_t k) const;
};

/// The chain of the classic PLUS freehand recording: ReferenceToTracker^-1 * ProbeToTracker,
/// or ProbeToTracker alone (the tracker as reference) when the file has no ReferenceToTracker.
PoseChain legacy_pose_chain(const SequenceFile& file);

/// Finds the pose chain of `file` (read from `path`, for messages). The pose is, in order:
/// - `requested` (`--pose-transform NAME`, e.g. "ProbeToReference"), when not empty;
/// - the header's `DefaultFrameTransformName` (older PLUS: "ToolToTrackerTransform");
/// - Probe (or Tool, older PLUS's name for it) to the first of Reference, Tracker, Template,
///   StepperHome that a chain reaches.
/// Edges are the file's per-frame transforms and `fixed`'s transforms; transforms from or to
/// Image or CroppedImage are left out (the image side is the calibration's and the crop's).
/// Fails naming the file, the pose asked for and by whom, the transforms there are and the
/// frames reachable from its From frame, with the fix (--pose-transform, a device set).
Result<PoseChain> find_pose_chain(const SequenceFile& file, const std::filesystem::path& path,
                                  std::string_view requested = {}, const PlusConfig& fixed = {});

/// The pixel shift of a cropped recording: its per-frame `ImageToCroppedImageTransform` (PLUS
/// maps the full image's pixels into the crop's), when it has one. Fails naming the file and
/// the frame when it is not a translation in the image plane or differs between frames (a crop
/// that moves cannot be one calibration); none when the file has no such field.
Result<std::optional<Eigen::Matrix4d>> image_to_cropped_image(const SequenceFile& file,
                                                              const std::filesystem::path& path);

/// Flips the frames of a recording whose `UltrasoundImageOrientation` is not MF into MF, as
/// PLUS does on reading (M/U: the columns run from the marked or the unmarked side; F/N: the
/// rows from the far field or the near one), and sets the field to MF (keeping an A/D suffix).
/// Returns whether it flipped. Fails naming the file when the code is not a 2D PLUS
/// orientation (MF, MN, UF, UN with an optional A or D): FM/NM are RF line data.
Result<bool> reorient_to_mf(SequenceFile& file, const std::filesystem::path& path);

/// Gives every frame a `Timestamp` (seconds; k / AcquisitionFrameRate when the header has a
/// positive one, else k / 10 Hz) when no frame has one, so that a replay plays every frame
/// instead of all at one instant. Returns the rate used, none when the file has timestamps.
std::optional<double> fill_missing_timestamps(SequenceFile& file);

}  // namespace sonoshape::acquisition
