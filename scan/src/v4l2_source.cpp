// `v4l2:/dev/videoN?...`: a frame grabber's frames (SONOSHAPE_WITH_V4L2).
#include "sonoshape/acquisition/v4l2_source.hpp"

#include <cmath>
#include <sstream>

#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/scan/sources.hpp"
#include "sonoshape/segmentation/sweep.hpp"

namespace sonoshape::scan {
namespace {

// The sector of live frames: a live source has no header probe and no recording to find the
// sector in, so the configuration says it (whole image or polygon).
Result<segmentation::ImageGeometry> live_geometry(const segmentation::SegmentationConfig& config,
                                                  int width_px, int height_px, double spacing_mm,
                                                  std::string& from) {
  if (config.sector == segmentation::SectorSource::kPolygon) {
    SliceSet check;
    check.slices.emplace_back().fov = config.sector_polygon_px;
    if (const Status valid = validate_slice_set(check, "the config's sector polygon"); !valid)
      return Status::error(valid.message() + " (the \"sector\" of the segmentation config)");
    from = "config polygon";
    return segmentation::polygon_geometry(width_px, height_px, spacing_mm,
                                          config.sector_polygon_px);
  }
  if (config.sector == segmentation::SectorSource::kAuto)
    return Status::error(
        "--source v4l2: a live source cannot find the sector from a recording; "
        "set \"sector\" to \"full\" or a polygon in --segmentation");
  from = "full image";
  return segmentation::full_image_geometry(width_px, height_px, spacing_mm);
}

// A frame grabber: frames from the device, poses from the tracker (--tracker, which the caller
// attaches: ScanSource::poses stays empty here). The image size is the crop's (or size=), known
// before the first frame; calibration and label models must be given.
}  // namespace

Result<ScanSource> open_v4l2_source(const SourceRequest& request, const std::string& spec) {
  auto options = acquisition::parse_v4l2_spec(spec);
  if (!options) return options.status();
  const int width_px = options->crop ? options->crop->width_px : options->width_px;
  const int height_px = options->crop ? options->crop->height_px : options->height_px;
  if (width_px <= 0)
    return Status::error("--source v4l2:" + spec +
                         ": give crop=X,Y,W,H (the scanner's image area) or size=WxH, so that "
                         "the image the calibration applies to is known");
  if (!request.calibration)
    return Status::error("--source v4l2: needs --calibration (the probe's ImageToProbe for the " +
                         std::to_string(width_px) + "x" + std::to_string(height_px) +
                         " cropped image: PLUS device-set XML or JSON)");
  if (!request.segmentation && request.preset.empty())
    return Status::error(
        "--source v4l2: needs --segmentation or --preset (the label models of this probe "
        "and preset, docs/segmentation.md)");
  ScanSource source;
  ScanSetup& setup = source.setup;
  auto calibration = segmentation::read_calibration(*request.calibration);
  if (!calibration) return calibration.status();
  setup.T_probe_image = *calibration;
  setup.calibration_from = request.calibration->string();
  const double spacing_mm = std::sqrt(setup.T_probe_image.block<3, 1>(0, 0).norm() *
                                      setup.T_probe_image.block<3, 1>(0, 1).norm());
  if (!(spacing_mm > 0.0) || !std::isfinite(spacing_mm))
    return Status::error(setup.calibration_from + ": the ImageToProbe calibration is degenerate");
  auto config = segmentation::load_segmentation_config(request.segmentation, request.preset);
  if (!config) return config.status();
  const std::string models_from =
      request.segmentation ? request.segmentation->string() : "preset " + request.preset;
  if (config->materials.empty())
    return Status::error(models_from + ": no materials; a live source needs the label models");
  if (const Status valid = config->validate(); !valid) return valid;
  setup.segmentation = std::move(*config);
  setup.models_from = models_from;
  auto geometry =
      live_geometry(setup.segmentation, width_px, height_px, spacing_mm, setup.sector_from);
  if (!geometry) return geometry.status();
  setup.geometry = std::move(*geometry);
  for (const segmentation::LabelModel& m : setup.segmentation.materials)
    setup.labels.push_back(segmentation::slice_label(m));
  setup.bounds = request.bounds;
  std::ostringstream text;
  text << "V4L2 grabber " << options->device << ", " << width_px << "x" << height_px
       << " image; calibration from " << setup.calibration_from << "; models from "
       << setup.models_from << "; sector from " << setup.sector_from;
  source.description = text.str();
  source.frames = std::make_unique<acquisition::V4l2FrameSource>(std::move(*options));
  return source;
}

}  // namespace sonoshape::scan
