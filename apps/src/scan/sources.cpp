#include "sonoshape/scan/sources.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>

#include "sonoshape/acquisition/frame_source.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/reconstruction_box.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/sim_source.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/tracking/pose_source.hpp"
#include "sonoshape/tracking/trakstar_source.hpp"
#ifdef SONOSHAPE_WITH_OPENIGTLINK
#include "sonoshape/acquisition/igtl_frame_source.hpp"
#include "sonoshape/tracking/igtl_pose_source.hpp"
#endif
#ifdef SONOSHAPE_WITH_V4L2
#include "sonoshape/acquisition/v4l2_source.hpp"
#endif

namespace sonoshape::scan {
namespace {

// Frames rendered (with their ground truth) to learn the simulated probe's grey-level models:
// spread over the sweep so that every organ is seen.
constexpr int kModelFrames = 6;

// The box of the volume a recording's sectors sweep (every frame with a pose), made into a
// reconstruction box as a slice set's default bounds are. A replay knows it before its first
// frame, so the box never grows during the scan: a box that grows rebuilds every cell at each
// update (docs/engine.md, "Online engine"). None when no frame has a pose.
std::optional<Box3> swept_sector_box(const acq::SequenceFile& file, const seg::SweepSetup& setup) {
  Box3 extent{Vec3::Constant(std::numeric_limits<double>::infinity()),
              Vec3::Constant(-std::numeric_limits<double>::infinity())};
  bool any = false;
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    const auto pose = seg::reference_from_probe(file, k, setup);
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

Result<ScanSource> open_replay(const SourceRequest& request, const std::string& path_text) {
  if (path_text.empty())
    return Status::error("--source replay: needs a file, e.g. replay:sweep.igs.mha");
  const std::filesystem::path path(path_text);
  auto file = acq::read_sequence_file(path);
  if (!file) return file.status();
  if (file->transform_names().empty())
    if (const Status tracked = acq::require_tracking(*file, path); !tracked) return tracked;
  // Label maps are checked against the frames as stored (times before any are filled in).
  std::optional<acq::LabelSequence> labels;
  if (!request.labels.empty()) {
    auto read = acq::read_label_sequence(request.labels, *file, path, request.labels_unknown);
    if (!read) return read.status();
    labels = std::move(*read);
  }
  if (const Status normal = seg::normalise_recording(*file, path); !normal) return normal;
  auto shared = std::make_shared<const acq::SequenceFile>(std::move(*file));
  auto prepared = seg::prepare_sweep(*shared, path, request.segmentation, request.calibration,
                                     request.pose_transform, request.preset);
  if (!prepared) return prepared.status();
  if (const Status sound =
          acq::check_tracked_sweep(*shared, path, prepared->pose_chain->per_frame_names());
      !sound)
    return sound;

  ScanSource source;
  ScanSetup& setup = source.setup;
  setup.T_probe_image = prepared->T_probe_image;
  setup.segmentation = prepared->config;
  setup.geometry = prepared->geometry;
  for (const seg::LabelModel& m : setup.segmentation.materials)
    setup.labels.push_back({m.label, m.name});
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
    source.labels =
        sequence_label_feed(std::make_shared<const acq::SequenceFile>(std::move(labels->maps)),
                            "label maps of " + request.labels + " (" + labels->timing + ")");
  }
  source.frames = std::make_unique<acq::ReplayFrameSource>(shared, path.string(), first_frame);
  source.poses =
      std::make_unique<tracking::ReplayPoseSource>(shared, path.string(), *prepared->pose_chain);
  source.device_origin_s =
      first_frame == 0 ? acq::first_timestamp_s(*shared) : shared->frame(first_frame).timestamp_s;
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

// Label models of the simulated probe, learnt from a few frames and their ground truth (what a
// preset of a real probe holds). Names come from the phantom.
seg::SegmentationConfig learn_sim_models(const sim::BModeSimulator& simulator,
                                         const sim::Trajectory& trajectory,
                                         const seg::SegmentationConfig& base, std::uint64_t seed) {
  const sim::Probe& probe = simulator.probe();
  const int w = probe.width_px(), h = probe.height_px();
  GreyImage grey(w, h * kModelFrames);
  LabelImage visible(w, h * kModelFrames);
  std::vector<std::array<int, 256>> caster_runs_px;
  for (int k = 0; k < kModelFrames; ++k) {
    const double t_s = trajectory.duration_s() * (k + 0.5) / kModelFrames;
    // Seeds apart from the scan's frames: the models must not have seen the frames they read.
    const sim::SimulatedFrame frame =
        simulator.render(trajectory.T_reference_probe(t_s),
                         sim::frame_seed(seed ^ 0x5EEDull, static_cast<std::size_t>(k)));
    std::copy(frame.bmode.pixels.begin(), frame.bmode.pixels.end(),
              grey.pixels.begin() + static_cast<std::ptrdiff_t>(k) * w * h);
    // Grey models from what the probe sees: not a bone's shadowed inside.
    const LabelImage shown = frame.visible_truth();
    std::copy(shown.pixels.begin(), shown.pixels.end(),
              visible.pixels.begin() + static_cast<std::ptrdiff_t>(k) * w * h);
    caster_runs_px.push_back(sim::shadow_caster_runs_px(frame));
  }
  seg::SegmentationConfig config = seg::learn_label_models(grey, visible, base);
  if (config.psf_sigma_mm < 0.0) {
    config.psf_sigma_mm = simulator.psf_sigma_mm();
    config.dynamic_range_db = simulator.options().dynamic_range_db;
  }
  const auto thickness = sim::shadow_caster_thickness_mm(caster_runs_px, probe.spacing_mm());
  for (seg::LabelModel& m : config.materials)
    if (const auto t = thickness.find(m.label); t != thickness.end()) m.thickness_mm = t->second;
  return config;
}

Result<ScanSource> open_sim(const SourceRequest& request, const std::string& phantom_spec) {
  SimScenarioOptions options = request.sim;
  options.phantoms = parse_phantom_spec(phantom_spec);
  if (!(request.sim_duration_s > 0.0) || !(options.frame_rate_hz > 0.0))
    return Status::error("sim: the sweep duration and the frame rate must be positive");
  const int frame_count =
      static_cast<int>(std::floor(request.sim_duration_s * options.frame_rate_hz)) + 1;
  const double duration_s = std::max(frame_count - 1, 1) / options.frame_rate_hz;
  auto scenario = make_sim_scenario(options, duration_s, request.models_dir);
  if (!scenario) return scenario.status();

  ScanSource source;
  ScanSetup& setup = source.setup;
  std::shared_ptr<const sim::BModeSimulator> simulator;
  try {
    simulator =
        std::make_shared<const sim::BModeSimulator>(scenario->phantom, sim::Probe(scenario->probe));
  } catch (const GeometryError& e) {
    return Status::error(std::string("sim: ") + e.what());
  }
  const sim::Probe& probe = simulator->probe();
  const sim::Trajectory trajectory(scenario->motion);

  // Calibration: the simulated probe's own, unless the user gives one (to study a bad one).
  setup.T_probe_image = probe.T_probe_image().matrix();
  setup.calibration_from = "the simulated probe";
  if (request.calibration) {
    auto read = seg::read_calibration(*request.calibration);
    if (!read) return read.status();
    setup.T_probe_image = *read;
    setup.calibration_from = request.calibration->string();
  }
  auto geometry = seg::geometry_from_header(sim::probe_fields(probe));
  if (!geometry) return geometry.status();
  setup.geometry = std::move(*geometry);
  setup.sector_from = "the simulated probe (" + sim::to_string(probe.type()) + ")";

  seg::SegmentationConfig base;
  setup.models_from = "learnt from " + std::to_string(kModelFrames) + " simulated frames";
  if (request.segmentation || !request.preset.empty()) {
    auto read = seg::load_segmentation_config(request.segmentation, request.preset);
    if (!read) return read.status();
    base = std::move(*read);
    setup.models_from =
        request.segmentation ? request.segmentation->string() : "preset " + request.preset;
  }
  if (base.materials.empty()) {
    for (const auto& m : scenario->phantom.meshes)
      if (std::none_of(base.materials.begin(), base.materials.end(),
                       [&](const seg::LabelModel& b) { return b.label == m.label; }))
        base.materials.push_back({m.label, m.name, 128.0, 25.0});
    base = learn_sim_models(*simulator, trajectory, base, options.seed);
    if (request.segmentation) setup.models_from += " (models learnt from simulated frames)";
  }
  if (const Status valid = base.validate(); !valid) return valid;
  setup.segmentation = std::move(base);
  for (const int label : scenario->phantom.labels()) {
    std::string name;
    for (const auto& m : scenario->phantom.meshes)
      if (m.label == label) name = m.name;
    setup.labels.push_back({label, name});
  }
  const Box3 box = scenario->phantom.bounds();
  setup.bounds = request.bounds ? *request.bounds : box.padded(0.1 * box.diagonal());

  sim::SimFrameOptions frame_options;
  frame_options.frame_rate_hz = options.frame_rate_hz;
  frame_options.frame_count = frame_count;
  frame_options.seed = options.seed;
  if (request.resume_after_frame) {
    frame_options.first_frame =
        static_cast<long>(std::max<std::int64_t>(*request.resume_after_frame + 1, 0));
    source.device_origin_s = static_cast<double>(frame_options.first_frame) / options.frame_rate_hz;
  }
  if (request.sim_fail_after_s >= 0.0)
    frame_options.fail_after_frames =
        static_cast<long>(std::floor(request.sim_fail_after_s * options.frame_rate_hz));
  frame_options.truth = std::make_shared<sim::FrameTruthStore>();
  source.truth_of_frame = [truth = frame_options.truth](std::int64_t index) {
    return truth->take(index);
  };
  const std::string name = "sim:" + (phantom_spec.empty() ? std::string("default") : phantom_spec);
  source.frames = std::make_unique<sim::SimFrameSource>(simulator, trajectory, frame_options, name);
  // The tracker samples the whole sweep (and a margin for its latency), as sim::acquire does.
  const double margin_s = 1.0 + std::abs(scenario->tracker.latency_s);
  source.poses = std::make_unique<tracking::RecordedPoseSource>(
      sim::track(trajectory, scenario->tracker, -margin_s, duration_s + margin_s),
      name + " (tracker)");
  source.tracker_latency_s = scenario->tracker.latency_s;
  std::ostringstream text;
  text << "simulated " << sim::to_string(probe.type()) << " probe " << probe.width_px() << "x"
       << probe.height_px() << " at " << options.frame_rate_hz << " fps, " << options.trajectory
       << " of " << duration_s << " s (" << frame_count << " frames), "
       << scenario->phantom.labels().size() << " labels, tracker " << scenario->tracker.rate_hz
       << " Hz; models " << setup.models_from;
  source.description = text.str();
  return source;
}

// --tracker: a live tracker instead of the source's poses. Its samples are stamped with
// CLOCK_MONOTONIC minus its own latency option, so the scan adds no latency of its own.
Status open_tracker(const std::string& spec, ScanSource& source) {
  const std::string trakstar = "usb:trakstar";
  if (spec.compare(0, trakstar.size(), trakstar) != 0 ||
      (spec.size() > trakstar.size() && spec[trakstar.size()] != ':'))
    return Status::error("--tracker '" + spec +
                         "': unknown tracker; use usb:trakstar[:sensor=N,rate=HZ,range=36|72,"
                         "latency_ms=MS,product=0xID]");
  auto options = tracking::parse_trakstar_options(
      spec.size() > trakstar.size() ? std::string_view(spec).substr(trakstar.size() + 1) : "");
  if (!options) return options.status();
  source.poses = std::make_unique<tracking::TrakstarPoseSource>(*options);
  source.tracker_latency_s = 0.0;
  source.description += "; poses from " + source.poses->describe();
  return Status::ok();
}

#ifdef SONOSHAPE_WITH_V4L2
// The sector of live frames: a live source has no header probe and no recording to find the
// sector in, so the configuration says it (whole image or polygon).
Result<seg::ImageGeometry> live_geometry(const seg::SegmentationConfig& config, int width_px,
                                         int height_px, double spacing_mm, std::string& from) {
  if (config.sector == seg::SectorSource::kPolygon) {
    SliceSet check;
    check.slices.emplace_back().fov = config.sector_polygon_px;
    if (const Status valid = validate_slice_set(check, "the config's sector polygon"); !valid)
      return Status::error(valid.message() + " (the \"sector\" of the segmentation config)");
    from = "config polygon";
    return seg::polygon_geometry(width_px, height_px, spacing_mm, config.sector_polygon_px);
  }
  if (config.sector == seg::SectorSource::kAuto)
    return Status::error(
        "--source v4l2: a live source cannot find the sector from a recording; "
        "set \"sector\" to \"full\" or a polygon in --segmentation");
  from = "full image";
  return seg::full_image_geometry(width_px, height_px, spacing_mm);
}

// A frame grabber: frames from the device, poses from the tracker (--tracker, which the caller
// attaches: ScanSource::poses stays empty here). The image size is the crop's (or size=), known
// before the first frame; calibration and label models must be given.
Result<ScanSource> open_v4l2(const SourceRequest& request, const std::string& spec) {
  auto options = acq::parse_v4l2_spec(spec);
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
  auto calibration = seg::read_calibration(*request.calibration);
  if (!calibration) return calibration.status();
  setup.T_probe_image = *calibration;
  setup.calibration_from = request.calibration->string();
  const double spacing_mm = std::sqrt(setup.T_probe_image.block<3, 1>(0, 0).norm() *
                                      setup.T_probe_image.block<3, 1>(0, 1).norm());
  if (!(spacing_mm > 0.0) || !std::isfinite(spacing_mm))
    return Status::error(setup.calibration_from + ": the ImageToProbe calibration is degenerate");
  auto config = seg::load_segmentation_config(request.segmentation, request.preset);
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
  for (const seg::LabelModel& m : setup.segmentation.materials)
    setup.labels.push_back({m.label, m.name});
  setup.bounds = request.bounds;
  std::ostringstream text;
  text << "V4L2 grabber " << options->device << ", " << width_px << "x" << height_px
       << " image; calibration from " << setup.calibration_from << "; models from "
       << setup.models_from << "; sector from " << setup.sector_from;
  source.description = text.str();
  source.frames = std::make_unique<acq::V4l2FrameSource>(std::move(*options));
  return source;
}
#endif

#ifdef SONOSHAPE_WITH_OPENIGTLINK
// Connects to the frames' server and waits for the first IMAGE: its size (and, for poses from
// the image, its spacing) sets up the segmentation before the scan starts.
Result<ScanSource> open_igtl(const SourceRequest& request, const std::string& endpoint_text) {
  auto endpoint = acq::parse_igtl_endpoint(endpoint_text, "--source igtl:");
  if (!endpoint) return endpoint.status();
  const bool pose_from_image = request.igtl_transform == "image";
  if (!pose_from_image && !request.calibration)
    return Status::error(
        "--source igtl: needs --calibration (ImageToProbe) for the poses of "
        "TRANSFORM '" +
        request.igtl_transform + "', or --igtl-transform image to take each IMAGE's own pose");
  auto connection = acq::IgtlConnection::connect(*endpoint);
  if (!connection) return connection.status();
  std::optional<acq::IgtlMessage> first;
  const double deadline_s = acq::monotonic_s() + request.igtl_wait_s;
  while (!first && acq::monotonic_s() < deadline_s) {
    auto message = connection->next(std::max(0.0, deadline_s - acq::monotonic_s()));
    if (!message) return message.status();
    if (*message && (*message)->type == "IMAGE" &&
        (request.igtl_image.empty() || (*message)->device == request.igtl_image))
      first = std::move(*message);
  }
  if (!first) {
    std::ostringstream wait;
    wait << request.igtl_wait_s;
    return Status::error("--source igtl:" + endpoint->text() + ": no IMAGE" +
                         (request.igtl_image.empty() ? "" : " named '" + request.igtl_image + "'") +
                         " within " + wait.str() +
                         " s; is the server streaming (PlusServer: an IMAGE in its "
                         "OutputChannel)?");
  }
  auto image = acq::decode_igtl_image(*first);
  if (!image) return Status::error("--source igtl:" + endpoint->text() + ": " + image.message());

  ScanSource source;
  ScanSetup& setup = source.setup;
  if (request.calibration) {
    auto read = seg::read_calibration(*request.calibration);
    if (!read) return read.status();
    setup.T_probe_image = *read;
    setup.calibration_from = request.calibration->string();
  } else {
    setup.T_probe_image =
        Eigen::Vector4d(image->spacing_mm[0], image->spacing_mm[1], 1.0, 1.0).asDiagonal();
    setup.calibration_from = "the IMAGE's pixel spacing (poses from the IMAGE)";
  }
  const double spacing_mm = std::sqrt(setup.T_probe_image.col(0).head<3>().norm() *
                                      setup.T_probe_image.col(1).head<3>().norm());
  setup.geometry = seg::full_image_geometry(image->image.width, image->image.height, spacing_mm);
  setup.sector_from = "the whole image";
  seg::SegmentationConfig config;
  setup.models_from = "two-class k-means on the first frame";
  if (request.segmentation || !request.preset.empty()) {
    auto read = seg::load_segmentation_config(request.segmentation, request.preset);
    if (!read) return read.status();
    config = std::move(*read);
    setup.models_from =
        request.segmentation ? request.segmentation->string() : "preset " + request.preset;
  }
  const bool organs_named = !config.materials.empty();  // by the configuration
  if (config.materials.empty())
    config = seg::auto_two_class(image->image.pixels, config);
  else if (config.learn_models)
    config = seg::learn_models_from_samples(image->image.pixels, config);
  if (const Status valid = config.validate(); !valid) return valid;
  setup.segmentation = std::move(config);
  for (const seg::LabelModel& m : setup.segmentation.materials)
    setup.labels.push_back({m.label, m.name});
  setup.bounds = request.bounds;

  acq::IgtlEndpoint tracker = *endpoint;
  if (!request.igtl_tracker.empty()) {
    auto parsed = acq::parse_igtl_endpoint(request.igtl_tracker, "--igtl-tracker");
    if (!parsed) return parsed.status();
    tracker = *parsed;
  }
  const std::string size =
      std::to_string(image->image.width) + "x" + std::to_string(image->image.height);
  source.frames = std::make_unique<acq::IgtlFrameSource>(*endpoint, request.igtl_image,
                                                         std::move(*connection), std::move(first));
  const std::string tdata = "tdata:";
  if (pose_from_image) {
    source.poses = std::make_unique<tracking::IgtlPoseSource>(tracker, request.igtl_image,
                                                              tracking::IgtlPoseFrom::kImage);
  } else if (request.igtl_transform.rfind(tdata, 0) == 0) {
    source.poses = std::make_unique<tracking::IgtlPoseSource>(
        tracker, request.igtl_transform.substr(tdata.size()),
        tracking::IgtlPoseFrom::kTrackingData);
  } else {
    source.poses = std::make_unique<tracking::IgtlPoseSource>(tracker, request.igtl_transform,
                                                              tracking::IgtlPoseFrom::kTransform);
  }
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
#endif

Result<ScanSource> open_frames_and_poses(const SourceRequest& request) {
  const std::size_t colon = request.spec.find(':');
  const std::string prefix = request.spec.substr(0, colon);
  const std::string rest = colon == std::string::npos ? "" : request.spec.substr(colon + 1);
  if (prefix == "sim") return open_sim(request, rest);
  if (prefix == "replay") return open_replay(request, rest);
#ifdef SONOSHAPE_WITH_OPENIGTLINK
  if (prefix == "igtl") return open_igtl(request, rest);
#else
  if (prefix == "igtl")
    return Status::error(
        "--source igtl: this sonoshape was built without OpenIGTLink; install "
        "libopenigtlink-dev (scripts/install-deps) and configure with "
        "-DSONOSHAPE_WITH_OPENIGTLINK=ON");
#endif
#ifdef SONOSHAPE_WITH_V4L2
  if (prefix == "v4l2") return open_v4l2(request, rest);
  const std::string live = ", v4l2:/dev/videoN (`sonoshape devices` lists them)";
#else
  const std::string live;
#endif
  return Status::error("--source '" + request.spec +
                       "': unknown source; use sim:PHANTOM_SPEC (e.g. sim:default), "
                       "replay:FILE.igs.mha, igtl:HOST:PORT" +
                       live);
}

}  // namespace

Result<ScanSource> open_scan_source(const SourceRequest& request) {
  const bool recorded = request.spec.rfind("replay:", 0) == 0;
  if (!request.labels.empty() && !recorded && request.spec.rfind("igtl:", 0) != 0)
    return Status::error("--labels with --source " + request.spec +
                         ": label maps come from a file beside a recording (--source "
                         "replay:FILE --labels LABELS.seq.nrrd) or over OpenIGTLink (--source "
                         "igtl:HOST:PORT --labels igtl:DEVICE)");
  if (recorded && request.labels.rfind("igtl:", 0) == 0)
    return Status::error("--labels " + request.labels +
                         ": a recording's label maps come from a file (--labels "
                         "LABELS.seq.nrrd or .mha, one label map per frame)");
  auto source = open_frames_and_poses(request);
  if (!source || request.tracker.empty()) return source;
  if (Status opened = open_tracker(request.tracker, *source); !opened) return opened;
  // A grabber stamps frames with CLOCK_MONOTONIC, as the tracker does its samples; sim: and
  // replay: frames carry their own clock.
  if (request.spec.rfind("v4l2:", 0) == 0) return source;
  log_warning("--tracker with --source " + request.spec +
              ": the frames are not stamped with CLOCK_MONOTONIC, so the tracker's poses will "
              "not pair with them; use a live frame source");
  return source;
}

}  // namespace sonoshape::scan
