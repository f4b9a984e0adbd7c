// `replay:FILE`: a PLUS sequence file's frames and poses, as recorded.
#include <algorithm>
#include <limits>
#include <sstream>

#include "sonoshape/acquisition/frame_source.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/reconstruction_box.hpp"
#include "sonoshape/scan/sources.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "sonoshape/tracking/pose_source.hpp"

namespace sonoshape::scan {
namespace {

// The box of the volume a recording's sectors sweep (every frame with a pose), made into a
// reconstruction box as a slice set's default bounds are. A replay knows it before its first
// frame, so the box never grows during the scan: a box that grows rebuilds every cell at each
// update (docs/engine.md, "Online engine"). None when no frame has a pose.
std::optional<Box3> swept_sector_box(const acquisition::SequenceFile& file,
                                     const segmentation::SweepSetup& setup) {
  Box3 extent{Vec3::Constant(std::numeric_limits<double>::infinity()),
              Vec3::Constant(-std::numeric_limits<double>::infinity())};
  bool any = false;
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    const auto pose = segmentation::reference_from_probe(file, k, setup);
    if (!pose) continue;
    const Eigen::Matrix4d T_reference_image = *pose * setup.T_probe_image;
    for (const Vec2& pixel : setup.geometry.sector_px) {
      const Vec3 world =
          (T_reference_image * Eigen::Vector4d(pixel.x(), pixel.y(), 0.0, 1.0)).head<3>();
      extent.min = extent.min.cwiseMin(world);
      extent.max = extent.max.cwiseMax(world);
      any = true;
    }
  }
  if (!any) return std::nullopt;
  return reconstruction_box(extent);
}

}  // namespace

Result<ScanSource> open_replay_source(const SourceRequest& request, const std::string& path_text) {
  if (path_text.empty())
    return Status::error("--source replay: needs a file, e.g. replay:sweep.igs.mha");
  const std::filesystem::path path(path_text);
  auto file = acquisition::read_sequence_file(path);
  if (!file) return file.status();
  if (file->transform_names().empty())
    if (const Status tracked = acquisition::require_tracking(*file, path); !tracked) return tracked;
  // Label maps are checked against the frames as stored (times before any are filled in).
  std::optional<acquisition::LabelSequence> labels;
  if (!request.labels.empty()) {
    auto read =
        acquisition::read_label_sequence(request.labels, *file, path, request.labels_unknown);
    if (!read) return read.status();
    labels = std::move(*read);
  }
  if (const Status normal = segmentation::normalise_recording(*file, path); !normal) return normal;
  auto shared = std::make_shared<const acquisition::SequenceFile>(std::move(*file));
  auto prepared =
      segmentation::prepare_sweep(*shared, path, request.segmentation, request.calibration,
                                  request.pose_transform, request.preset);
  if (!prepared) return prepared.status();
  if (const Status sound =
          acquisition::check_tracked_sweep(*shared, path, prepared->pose_chain->per_frame_names());
      !sound)
    return sound;

  ScanSource source;
  ScanSetup& setup = source.setup;
  setup.T_probe_image = prepared->T_probe_image;
  setup.segmentation = prepared->config;
  setup.geometry = prepared->geometry;
  for (const segmentation::LabelModel& m : setup.segmentation.materials)
    setup.labels.push_back(segmentation::slice_label(m));
  setup.bounds = request.bounds ? request.bounds : swept_sector_box(*shared, *prepared);
  setup.calibration_from = prepared->calibration_from;
  setup.models_from = prepared->models_from;
  setup.sector_from = prepared->sector_from;
  std::size_t first_frame = 0;
  if (request.resume_after_frame) {
    first_frame =
        static_cast<std::size_t>(std::max<std::int64_t>(*request.resume_after_frame + 1, 0));
    if (first_frame >= shared->frame_count())
      return Status::error("--resume: the journal ends at frame " +
                           std::to_string(*request.resume_after_frame) + " but " + path.string() +
                           " has " + std::to_string(shared->frame_count()) +
                           " frames: is it the file the scan was started with?");
  }
  if (labels) {
    // Models learnt by k-means name no organ of the site's label maps.
    if (setup.models_from.rfind("two-class", 0) == 0) setup.labels.clear();
    setup.labels = declared_labels(labels->names, setup.labels);
    setup.models_from = "none: the label maps of --labels " + request.labels;
    source.labels = sequence_label_feed(
        std::make_shared<const acquisition::SequenceFile>(std::move(labels->maps)),
        "label maps of " + request.labels + " (" + labels->timing + ")");
  }
  source.frames =
      std::make_unique<acquisition::ReplayFrameSource>(shared, path.string(), first_frame);
  source.poses =
      std::make_unique<tracking::ReplayPoseSource>(shared, path.string(), *prepared->pose_chain);
  source.device_origin_s = first_frame == 0 ? acquisition::first_timestamp_s(*shared)
                                            : shared->frame(first_frame).timestamp_s;
  // PLUS stores the tracker already interpolated at each frame's time.
  source.tracker_latency_s = 0.0;
  std::ostringstream text;
  text << "replay of " << path.string() << ": " << shared->frame_count() << " frames of "
       << shared->width() << "x" << shared->height() << "; calibration from "
       << setup.calibration_from << "; pose " << prepared->pose_chain->describe() << " (chosen by "
       << prepared->pose_chain->chosen_by
       << (prepared->pose_chain->from != "Probe"
               ? "; " + prepared->pose_chain->from + " taken as the probe of ImageToProbe"
               : "")
       << "); models from " << setup.models_from << "; sector from " << setup.sector_from;
  source.description = text.str();
  return source;
}

}  // namespace sonoshape::scan
