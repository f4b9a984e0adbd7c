#pragma once
// The scan's sources chosen by a string (design.md, "Devices"): `PREFIX:REST`, where each
// PREFIX is a kind of source in a SourceRegistry. This module holds the registry and the
// backends it can build without a simulator: `replay:FILE.igs.mha` (a PLUS sequence file:
// frames, poses, statuses), `igtl:HOST:PORT` (an OpenIGTLink server such as PlusServer: IMAGE
// and TRANSFORM messages) and `v4l2:/dev/videoN?...` (a frame grabber: frames only;
// ScanSource::poses is left empty for the tracker; needs calibration, segmentation and crop= or
// size=; see v4l2_source.hpp). The program fills the registry in one place (apps/: the
// simulated `sim:` source beside these, each backend under its build option's guard).
#include <cstdint>
#include <filesystem>
#include <functional>
#include <iosfwd>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "sonoshape/acquisition/label_sequence.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/scan/pipeline.hpp"

namespace sonoshape::scan {

/// What to open.
struct SourceRequest {
  /// "sim:", "sim:default", "sim:1:liver.obj:liver,2:kidney.obj", "replay:sweep.igs.mha".
  std::string spec;
  /// ImageToProbe from a PLUS device-set XML or JSON (segmentation::read_calibration). Default:
  /// sim: the simulated probe's exact calibration; replay: the file's header, else the sidecar
  /// <name>.plus.xml.
  std::optional<std::filesystem::path> calibration;
  /// replay: the probe's pose as PLUS names it (acquisition::find_pose_chain); empty: the header's
  /// DefaultFrameTransformName, else the default search.
  std::string pose_transform;
  /// Segmentation configuration JSON (docs/segmentation.md). Default: sim: label models
  /// learnt from a few rendered frames and their ground truth (a preset of the simulated
  /// probe); replay: the file's header models, else a two-class split of its frames.
  std::optional<std::filesystem::path> segmentation;
  /// A named set of segmentation settings (segmentation::segmentation_presets) under
  /// `segmentation`'s keys; empty: the defaults.
  std::string preset;
  /// The reconstruction box; default: sim: the phantom's box padded by 10 % of its diagonal;
  /// replay: none (grown from the slices).
  std::optional<Box3> bounds;
  /// A live tracker that replaces the source's poses: "usb:trakstar[:sensor=N,rate=HZ,...]"
  /// (tracking::parse_trakstar_options). Empty: the source's own poses.
  std::string tracker;
  /// A resumed scan: the last frame its journal holds. Recorded and simulated sources (sim:,
  /// replay:) start at the frame after it; live sources (igtl:, v4l2:) have no past to seek and
  /// go on from the frame they deliver now. None: from the start.
  std::optional<std::int64_t> resume_after_frame;
  /// `--labels`: a site's own label maps instead of the segmenter (label_maps.hpp). replay: a
  /// label-map sequence FILE, frame k for frame k (acquisition::read_label_sequence); igtl:
  /// `igtl:DEVICE` (or `igtl:DEVICE@HOST:PORT`), IMAGE messages paired by timestamp. Empty: the
  /// segmenter.
  std::string labels;
  int labels_unknown = acquisition::kDefaultUnknownLabelValue;  ///< the label maps' unknown value
  double labels_wait_s = 1.0;  ///< igtl: how long a frame waits for its label map

  // igtl: only (an OpenIGTLink server such as PlusServer; needs SONOSHAPE_WITH_OPENIGTLINK).
  std::string igtl_image;  ///< IMAGE device name of the frames ("": any)
  /// TRANSFORM device name carrying T_reference_probe; "tdata:NAME": the element NAME of TDATA
  /// messages; "image": the IMAGE's own pose (the probe frame is then the image's, and the
  /// calibration its pixel spacing).
  std::string igtl_transform = "ProbeToReference";
  std::string igtl_tracker;  ///< HOST:PORT sending the TRANSFORMs ("": the --source server)
  double igtl_wait_s = 5.0;  ///< how long to wait for the first IMAGE (its size sets the setup)
};

/// Opens one kind of source: `rest` is the spec after "PREFIX:".
using SourceOpener =
    std::function<Result<ScanSource>(const SourceRequest& request, const std::string& rest)>;

/// Where a kind of source takes `--labels` (a site's own label maps) from.
enum class LabelMapsFrom {
  kNone,    ///< it takes none
  kFile,    ///< a label-map sequence file beside the recording, frame k for frame k
  kStream,  ///< `igtl:DEVICE` IMAGE messages beside the frames, paired by timestamp
};

/// One kind of source: what its specs start with, what it is, and how it opens.
struct SourceKind {
  std::string prefix;  ///< "replay": specs "replay:REST"
  std::string usage;   ///< how to write one, for the unknown-source message ("replay:FILE.igs.mha")
  /// A recording or a simulation: its frames carry their own clock, it can be played in real
  /// time or as fast as the pipeline goes, and a resumed scan seeks to the frame after the
  /// journal's last. Live sources go on from the frame they deliver now.
  bool playback = false;
  /// Frames stamped with CLOCK_MONOTONIC, as `--tracker`'s samples are (a frame grabber).
  bool monotonic_clock = false;
  LabelMapsFrom label_maps = LabelMapsFrom::kNone;
  /// Non-empty: this build lacks the backend; opening fails with "--source PREFIX: " and this
  /// (why, and how to build it in).
  std::string not_built;
  SourceOpener open;  ///< empty when not built
  /// `sonoshape devices`: writes this kind's attached devices (or why they cannot be listed);
  /// empty for kinds without devices.
  std::function<void(std::ostream& out)> list_devices;
};

/// The kinds of source a program offers, by prefix (as OpenCV's videoio lists its backends).
class SourceRegistry {
 public:
  /// Adds a kind; a second kind with the same prefix replaces the first.
  void add(SourceKind kind);
  /// The kind of `spec` by its prefix (the text before the first ':'); null when unknown.
  const SourceKind* find(std::string_view spec) const;
  /// Every kind, in the order added.
  const std::vector<SourceKind>& kinds() const { return kinds_; }

  /// Opens the sources of `request` and prepares the setup; attaches `request.tracker` when
  /// given. Fails with a message that names the problem and the fix: unknown prefix, a backend
  /// not built, unreadable file or meshes, missing calibration, invalid segmentation
  /// configuration, label maps the kind cannot take.
  Result<ScanSource> open(const SourceRequest& request) const;

 private:
  std::vector<SourceKind> kinds_;
};

/// The backends of this module, for a registry (each defined where the build has it).
Result<ScanSource> open_replay_source(const SourceRequest& request, const std::string& path);
/// SONOSHAPE_WITH_OPENIGTLINK only.
Result<ScanSource> open_igtl_source(const SourceRequest& request, const std::string& endpoint);
/// SONOSHAPE_WITH_V4L2 only.
Result<ScanSource> open_v4l2_source(const SourceRequest& request, const std::string& spec);

}  // namespace sonoshape::scan
