// `igtl:HOST:PORT`: frames and poses from an OpenIGTLink server (SONOSHAPE_WITH_OPENIGTLINK).
#include <algorithm>
#include <cmath>
#include <sstream>

#include "sonoshape/acquisition/igtl_frame_source.hpp"
#include "sonoshape/scan/sources.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "sonoshape/tracking/igtl_pose_source.hpp"

namespace sonoshape::scan {
namespace {

// The first IMAGE of the frames' device, waited for at most request.igtl_wait_s.
Result<acquisition::IgtlMessage> first_image(acquisition::IgtlConnection& connection,
                                             const acquisition::IgtlEndpoint& endpoint,
                                             const SourceRequest& request) {
  const double deadline_s = acquisition::monotonic_s() + request.igtl_wait_s;
  while (acquisition::monotonic_s() < deadline_s) {
    auto message = connection.next(std::max(0.0, deadline_s - acquisition::monotonic_s()));
    if (!message) return message.status();
    if (*message && (*message)->type == "IMAGE" &&
        (request.igtl_image.empty() || (*message)->device == request.igtl_image))
      return std::move(**message);
  }
  std::ostringstream wait;
  wait << request.igtl_wait_s;
  return Status::error("--source igtl:" + endpoint.text() + ": no IMAGE" +
                       (request.igtl_image.empty() ? "" : " named '" + request.igtl_image + "'") +
                       " within " + wait.str() +
                       " s; is the server streaming (PlusServer: an IMAGE in its "
                       "OutputChannel)?");
}

// The probe's poses: the IMAGE's own, a TDATA element's or a TRANSFORM's.
std::unique_ptr<tracking::PoseSource> pose_source(const SourceRequest& request,
                                                  const acquisition::IgtlEndpoint& tracker) {
  const std::string tdata = "tdata:";
  if (request.igtl_transform == "image")
    return std::make_unique<tracking::IgtlPoseSource>(tracker, request.igtl_image,
                                                      tracking::IgtlPoseFrom::kImage);
  if (request.igtl_transform.rfind(tdata, 0) == 0)
    return std::make_unique<tracking::IgtlPoseSource>(tracker,
                                                      request.igtl_transform.substr(tdata.size()),
                                                      tracking::IgtlPoseFrom::kTrackingData);
  return std::make_unique<tracking::IgtlPoseSource>(tracker, request.igtl_transform,
                                                    tracking::IgtlPoseFrom::kTransform);
}

// ImageToProbe: --calibration's, else (poses from the IMAGE) the IMAGE's pixel spacing.
Status set_calibration(const SourceRequest& request, const acquisition::IgtlImage& image,
                       ScanSetup& setup) {
  if (request.calibration) {
    auto read = segmentation::read_calibration(*request.calibration);
    if (!read) return read.status();
    setup.T_probe_image = *read;
    setup.calibration_from = request.calibration->string();
    return Status::ok();
  }
  setup.T_probe_image =
      Eigen::Vector4d(image.spacing_mm[0], image.spacing_mm[1], 1.0, 1.0).asDiagonal();
  setup.calibration_from = "the IMAGE's pixel spacing (poses from the IMAGE)";
  return Status::ok();
}

}  // namespace

// Connects to the frames' server and waits for the first IMAGE: its size (and, for poses from
// the image, its spacing) sets up the segmentation before the scan starts.
Result<ScanSource> open_igtl_source(const SourceRequest& request,
                                    const std::string& endpoint_text) {
  auto endpoint = acquisition::parse_igtl_endpoint(endpoint_text, "--source igtl:");
  if (!endpoint) return endpoint.status();
  const bool pose_from_image = request.igtl_transform == "image";
  if (!pose_from_image && !request.calibration)
    return Status::error(
        "--source igtl: needs --calibration (ImageToProbe) for the poses of "
        "TRANSFORM '" +
        request.igtl_transform + "', or --igtl-transform image to take each IMAGE's own pose");
  auto connection = acquisition::IgtlConnection::connect(*endpoint);
  if (!connection) return connection.status();
  auto first = first_image(*connection, *endpoint, request);
  if (!first) return first.status();
  auto image = acquisition::decode_igtl_image(*first);
  if (!image) return Status::error("--source igtl:" + endpoint->text() + ": " + image.message());

  ScanSource source;
  ScanSetup& setup = source.setup;
  if (const Status calibrated = set_calibration(request, *image, setup); !calibrated)
    return calibrated;
  const double spacing_mm = std::sqrt(setup.T_probe_image.col(0).head<3>().norm() *
                                      setup.T_probe_image.col(1).head<3>().norm());
  setup.geometry =
      segmentation::full_image_geometry(image->image.width, image->image.height, spacing_mm);
  setup.sector_from = "the whole image";
  segmentation::SegmentationConfig config;
  setup.models_from = "two-class k-means on the first frame";
  if (request.segmentation || !request.preset.empty()) {
    auto read = segmentation::load_segmentation_config(request.segmentation, request.preset);
    if (!read) return read.status();
    config = std::move(*read);
    setup.models_from =
        request.segmentation ? request.segmentation->string() : "preset " + request.preset;
  }
  const bool organs_named = !config.materials.empty();  // by the configuration
  if (config.materials.empty())
    config = segmentation::auto_two_class(image->image.pixels, config);
  else if (config.learn_models)
    config = segmentation::learn_models_from_samples(image->image.pixels, config);
  if (const Status valid = config.validate(); !valid) return valid;
  setup.segmentation = std::move(config);
  for (const segmentation::LabelModel& m : setup.segmentation.materials)
    setup.labels.push_back(segmentation::slice_label(m));
  setup.bounds = request.bounds;

  acquisition::IgtlEndpoint tracker = *endpoint;
  if (!request.igtl_tracker.empty()) {
    auto parsed = acquisition::parse_igtl_endpoint(request.igtl_tracker, "--igtl-tracker");
    if (!parsed) return parsed.status();
    tracker = *parsed;
  }
  const std::string size =
      std::to_string(image->image.width) + "x" + std::to_string(image->image.height);
  source.frames = std::make_unique<acquisition::IgtlFrameSource>(
      *endpoint, request.igtl_image, std::move(*connection), std::move(*first));
  source.poses = pose_source(request, tracker);
  if (!request.labels.empty()) {
    if (request.labels.rfind("igtl:", 0) != 0)
      return Status::error("--labels " + request.labels +
                           ": with --source igtl: the label maps come over OpenIGTLink too; give "
                           "their IMAGE device name, e.g. --labels igtl:LabelMap");
    auto feed = igtl_label_feed(request.labels, endpoint->text(), request.labels_unknown,
                                request.labels_wait_s);
    if (!feed) return feed.status();
    source.labels = std::move(*feed);
    setup.models_from = "none: the label maps of --labels " + request.labels;
    // No header names the organs of a live stream: the configuration's names, if it has any.
    if (!organs_named) setup.labels.clear();
  }
  source.device_origin_s = 0.0;
  source.tracker_latency_s = 0.0;  // both stamped by the server (PlusServer: one clock)
  source.description = "OpenIGTLink " + endpoint->text() + ": " + size + " frames; poses from " +
                       source.poses->describe() + "; calibration from " + setup.calibration_from +
                       "; models " + setup.models_from;
  return source;
}

}  // namespace sonoshape::scan
