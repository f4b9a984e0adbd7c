#pragma once
// The scan's sources chosen by a string (design.md, "Devices"): `sim:PHANTOM_SPEC` (a simulated
// probe and tracker), `replay:FILE.igs.mha` (a PLUS sequence file: frames, poses, statuses) or
// `igtl:HOST:PORT` (an OpenIGTLink server such as PlusServer: IMAGE and TRANSFORM messages).
// `v4l2:/dev/videoN?...` (a frame grabber: frames only; ScanSource::poses is left empty for the
// tracker; needs calibration, segmentation and crop= or size=; see v4l2_source.hpp).
// Hardware backends add their prefix here without changing the pipeline.
#include <filesystem>
#include <optional>
#include <string>

#include "sonoshape/acquisition/label_sequence.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/scan/pipeline.hpp"
#include "sonoshape/scan/sim_scenario.hpp"

namespace sonoshape::scan {

/// What to open.
struct SourceRequest {
  /// "sim:", "sim:default", "sim:1:liver.obj:liver,2:kidney.obj", "replay:sweep.igs.mha".
  std::string spec;
  /// ImageToProbe from a PLUS device-set XML or JSON (seg::read_calibration). Default: sim:
  /// the simulated probe's exact calibration; replay: the file's header, else the sidecar
  /// <name>.plus.xml.
  std::optional<std::filesystem::path> calibration;
  /// replay: the probe's pose as PLUS names it (acq::find_pose_chain); empty: the header's
  /// DefaultFrameTransformName, else the default search.
  std::string pose_transform;
  /// Segmentation configuration JSON (docs/segmentation.md). Default: sim: label models
  /// learnt from a few rendered frames and their ground truth (a preset of the simulated
  /// probe); replay: the file's header models, else a two-class split of its frames.
  std::optional<std::filesystem::path> segmentation;
  /// A named set of segmentation settings (seg::segmentation_presets) under `segmentation`'s
  /// keys; empty: the defaults.
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
  /// label-map sequence FILE, frame k for frame k (acq::read_label_sequence); igtl: `igtl:DEVICE`
  /// (or `igtl:DEVICE@HOST:PORT`), IMAGE messages paired by timestamp. Empty: the segmenter.
  std::string labels;
  int labels_unknown = acq::kDefaultUnknownLabelValue;  ///< the label maps' unknown value
  double labels_wait_s = 1.0;  ///< igtl: how long a frame waits for its label map

  // sim: only.
  SimScenarioOptions sim;
  double sim_duration_s = 20.0;  ///< length of the simulated sweep (s)
  double sim_fail_after_s = -1;  ///< fault injection: the probe vanishes at this time (< 0: never)
  std::filesystem::path models_dir;  ///< bundled models of the built-in demo phantom

  // igtl: only (an OpenIGTLink server such as PlusServer; needs SONOSHAPE_WITH_OPENIGTLINK).
  std::string igtl_image;  ///< IMAGE device name of the frames ("": any)
  /// TRANSFORM device name carrying T_reference_probe; "tdata:NAME": the element NAME of TDATA
  /// messages; "image": the IMAGE's own pose (the probe frame is then the image's, and the
  /// calibration its pixel spacing).
  std::string igtl_transform = "ProbeToReference";
  std::string igtl_tracker;  ///< HOST:PORT sending the TRANSFORMs ("": the --source server)
  double igtl_wait_s = 5.0;  ///< how long to wait for the first IMAGE (its size sets the setup)
};

/// Opens the sources of `request` and prepares the setup. Fails with a message that names the
/// problem and the fix: unknown prefix, unreadable file or meshes, missing calibration, invalid
/// segmentation configuration.
Result<ScanSource> open_scan_source(const SourceRequest& request);

}  // namespace sonoshape::scan
