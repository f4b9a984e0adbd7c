// `sonoshape segment`: a tracked sweep (PLUS sequence file, MetaImage or NRRD) -> slice set,
// one slice per frame with a valid pose: label map by segmentation/ (or, for a simulated sweep,
// the truth label frames: --perfect-labels), polygons in the reference frame, fov = sector.
// --truth-labels scores every frame's label map against the simulator's truth.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "commands.hpp"
#include "option_checks.hpp"
#include "preset_option.hpp"
#include "seed_option.hpp"
#include "sonoshape/acquisition/label_sequence.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/scan/label_maps.hpp"
#include "sonoshape/scan/label_prior.hpp"
#include "sonoshape/segmentation/overlay.hpp"
#include "sonoshape/segmentation/sweep.hpp"

namespace sonoshape::apps {
namespace {

struct SegmentOptions {
  std::filesystem::path input;
  std::filesystem::path config;
  std::string preset;  ///< --preset NAME: a named set of configuration settings
  std::filesystem::path calibration;
  std::string pose_transform;  ///< --pose-transform FROMToTO; empty: the header's or default
  int every = 1;
  bool strict = false;
  std::filesystem::path output = "slices.json";
  std::filesystem::path truth_labels;    ///< score against these label frames
  std::filesystem::path perfect_labels;  ///< use these label frames instead of the segmenter
  std::filesystem::path labels;          ///< --labels: the site's own label-map sequence
  int labels_unknown = acquisition::kDefaultUnknownLabelValue;  ///< its value for unknown pixels
  std::filesystem::path report;                                 ///< JSON of the scores
  std::filesystem::path overlays;        ///< directory for the overlay pictures
  int overlay_every = 1;                 ///< picture every K-th segmented frame
  std::string method;                    ///< "", "threshold" or "graph-cut": overrides the config
  std::string prior = "reconstruction";  ///< graph cut's prior: "reconstruction" or "none"
  int prior_depth = 6;                   ///< octree depth of the prior's reconstruction
  std::vector<std::string> seeds;        ///< LABEL:X,Y,Z, see seed_option.hpp
};

// The box (mm, reference frame) of the sectors of every frame with a valid pose, padded by a
// tenth of its diagonal; none when no frame has one.
std::optional<Box3> sweep_box(const acquisition::SequenceFile& file,
                              const segmentation::SweepSetup& setup) {
  std::optional<Box3> box;
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    const auto pose = segmentation::reference_from_probe(file, k, setup);
    if (!pose) continue;
    const Eigen::Matrix4d T_reference_image = *pose * setup.T_probe_image;
    for (const Vec2& p : setup.geometry.sector_px) {
      const Vec3 q = (T_reference_image * Eigen::Vector4d(p.x(), p.y(), 0.0, 1.0)).head<3>();
      box = box ? Box3{box->min.cwiseMin(q), box->max.cwiseMax(q)} : Box3{q, q};
    }
  }
  if (box) *box = box->padded(0.1 * box->diagonal());
  return box;
}

// Writes DIR/frame_NNNN.png for every `every`-th label map it is called with; remembers the
// first failure (a full disk must not stop the segmentation, but the run reports it).
class OverlayWriter {
 public:
  OverlayWriter(const SegmentOptions& options, const acquisition::SequenceFile& sweep,
                const ImageU8& sector, const acquisition::SequenceFile* truth)
      : options_(options), sweep_(sweep), sector_(sector), truth_(truth) {}
  void operator()(std::size_t frame, const LabelImage& labels) {
    if (seen_++ % static_cast<std::size_t>(options_.overlay_every) != 0 || !status_) return;
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04zu.png", frame);
    const LabelImage truth = truth_ ? truth_->image(frame) : LabelImage();
    status_ = segmentation::write_overlay(options_.overlays / name, sweep_.image(frame), labels,
                                          sector_, truth_ ? &truth : nullptr);
    if (status_) ++written_;
  }
  const Status& status() const { return status_; }
  std::size_t written() const { return written_; }

 private:
  const SegmentOptions& options_;
  const acquisition::SequenceFile& sweep_;
  const ImageU8& sector_;
  const acquisition::SequenceFile* truth_;
  std::size_t seen_ = 0, written_ = 0;
  Status status_ = Status::ok();
};

// Reads label frames given by `option` and checks them against the sweep; none when not given.
Result<std::optional<acquisition::SequenceFile>> read_label_frames(
    const acquisition::SequenceFile& sweep, const SegmentOptions& options,
    const std::filesystem::path& path, const std::string& option) {
  if (path.empty()) return std::optional<acquisition::SequenceFile>();
  if (!std::filesystem::is_regular_file(path))
    return Status::error(option + " " + path.string() +
                         ": no such file; give DIR/labels.mha as `sonoshape simulate --truth DIR` "
                         "writes it");
  auto labels = acquisition::read_sequence_file(path);
  if (!labels) return Status::error(option + ": " + labels.message());
  if (const Status same = segmentation::check_truth_labels(sweep, options.input, *labels, path);
      !same)
    return Status::error(option + ": " + same.message());
  return std::optional<acquisition::SequenceFile>(std::move(*labels));
}

// --labels replaces the segmenter: the options that tune or replace it do not go with it.
Status own_labels_usable(const SegmentOptions& options) {
  if (!options.perfect_labels.empty())
    return Status::error("--labels and --perfect-labels both replace the segmenter; give one");
  if (!options.method.empty() || !options.seeds.empty())
    return Status::error(std::string("--labels replaces sonoshape's segmenter, so ") +
                         (options.method.empty() ? "--organ-seed" : "--method") +
                         " does not apply; leave it out");
  return Status::ok();
}

// The organs of a site's label maps: as their header names them; without names, the
// configuration's or the recording header's models, never the k-means classes (which name no
// organ of the site).
void declare_own_labels(const acquisition::LabelSequence& labels, const SegmentOptions& options,
                        segmentation::SweepSetup& setup) {
  std::vector<LabelInfo> fallback;
  if (!options.config.empty() || setup.models_from.rfind("header", 0) == 0)
    for (const segmentation::LabelModel& m : setup.config.materials)
      fallback.push_back({m.label, m.name});
  setup.config.materials.clear();
  for (const LabelInfo& l : scan::declared_labels(labels.names, fallback)) {
    segmentation::LabelModel model;
    model.label = l.id;
    model.name = l.name;
    setup.config.materials.push_back(model);
  }
  setup.models_from =
      labels.names.empty()
          ? "--labels (organs named by " +
                (fallback.empty() ? std::string("their values") : setup.models_from) + ")"
          : "--labels (organs named by its header)";
}

// The table on stderr and the JSON report of --truth-labels.
int report_comparison(const segmentation::SweepSegmentation& result,
                      const segmentation::SweepSetup& setup, const SegmentOptions& options) {
  std::map<int, std::string> names{{setup.config.background.label, "background"}};
  for (const auto& m : setup.config.materials) names[m.label] = m.name;
  std::cerr << segmentation::format_comparison(result.comparison_total, names);
  if (options.report.empty()) return 0;
  std::error_code ec;
  if (!options.report.parent_path().empty())
    std::filesystem::create_directories(options.report.parent_path(), ec);
  if (const Status written = segmentation::write_comparison_report(
          result.comparisons, result.comparison_total, names, options.report);
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  return 0;
}

// The recording, tracked and normalised, with the site's own label maps when --labels gives
// them (checked against the frames as stored, before any time is filled).
struct Recording {
  acquisition::SequenceFile file;
  std::optional<acquisition::LabelSequence> own_labels;
};
Result<Recording> read_recording(const SegmentOptions& options) {
  auto file = acquisition::read_sequence_file(options.input);
  if (!file) return file.status();
  // A file without any per-frame transform: the image-only and untracked cases explained.
  if (file->transform_names().empty())
    if (const Status tracked = acquisition::require_tracking(*file, options.input); !tracked)
      return tracked;
  Recording recording{std::move(*file), std::nullopt};
  if (!options.labels.empty()) {
    if (Status usable = own_labels_usable(options); !usable) return usable;
    auto read = acquisition::read_label_sequence(options.labels, recording.file, options.input,
                                                 options.labels_unknown);
    if (!read) return read.status();
    recording.own_labels = std::move(*read);
    log_info("segment: label maps from " + options.labels.string() + " instead of the " +
             "segmenter (" + recording.own_labels->timing + ")");
  }
  if (const Status normal = segmentation::normalise_recording(recording.file, options.input);
      !normal)
    return normal;
  return recording;
}

// The sweep's setup (calibration, pose chain, sector, models) with the options' method and
// seeds, or the organs of the site's label maps.
Result<segmentation::SweepSetup> setup_sweep(const SegmentOptions& options,
                                             const Recording& recording) {
  auto optional_path = [](const std::filesystem::path& p) {
    return p.empty() ? std::nullopt : std::optional<std::filesystem::path>(p);
  };
  auto setup = segmentation::prepare_sweep(
      recording.file, options.input, optional_path(options.config),
      optional_path(options.calibration), options.pose_transform, options.preset);
  if (!setup) return setup.status();
  if (const Status sound = acquisition::check_tracked_sweep(recording.file, options.input,
                                                            setup->pose_chain->per_frame_names());
      !sound)
    return sound;
  const acquisition::PoseChain& chain = *setup->pose_chain;
  log_info("segment: pose " + chain.describe() + ", chosen by " + chain.chosen_by +
           (chain.from != "Probe"
                ? "; " + chain.from + " is taken as the probe that ImageToProbe maps into"
                : ""));
  if (!options.method.empty())
    setup->config.method = options.method == "graph-cut"
                               ? segmentation::LabellingMethod::kGraphCut
                               : segmentation::LabellingMethod::kThreshold;
  if (const Status seeded = apply_seeds(options.seeds, setup->config); !seeded) return seeded;
  if (recording.own_labels) declare_own_labels(*recording.own_labels, options, *setup);
  return setup;
}

// Says where the models, calibration and sector come from.
void log_models(const segmentation::SweepSetup& setup, bool own_labels) {
  std::ostringstream models;
  if (own_labels) {
    models << "organs";
    for (const auto& m : setup.config.materials) models << " " << m.label << ":" << m.name;
  } else {
    models << "grey means: background " << setup.config.background.grey_mean;
    for (const auto& m : setup.config.materials)
      models << ", " << m.label << ":" << m.name << " " << m.grey_mean;
  }
  log_info("segment: models from " + setup.models_from + " (" + models.str() +
           "); calibration from " + setup.calibration_from + "; sector from " + setup.sector_from);
}

// What segmenting gave, checked: no frame refused under --strict, some slices, a valid set.
Status check_segmentation(const SegmentOptions& options,
                          const segmentation::SweepSegmentation& result) {
  if (!result.refused.empty())
    return Status::error(
        options.input.string() + ", " + result.refused +
        "\n(--strict refuses frames whose polygons needed a repair; nothing written. Leave out "
        "--strict to drop what cannot be made valid and go on)");
  if (result.slices.slices.empty())
    return Status::error(
        "no frame of " + options.input.string() +
        " gave a slice (frames with INVALID pose: " + std::to_string(result.invalid_pose) +
        ", failed: " + std::to_string(result.failed) + "); nothing written");
  if (const Status valid = validate_slice_set(result.slices, options.output.string()); !valid)
    return Status::error(
        "the segmented slices are not a valid slice set (a bug; please report it with the "
        "input):\n" +
        valid.message());
  return Status::ok();
}

// The summary line of a written slice set.
void log_summary(const SegmentOptions& options, const segmentation::SweepSegmentation& result,
                 double seconds) {
  std::size_t regions = 0, unknown = 0;
  for (const LabeledSlice& s : result.slices.slices)
    for (const Region& r : s.regions) (r.label == kUnknownLabel ? unknown : regions) += 1;
  std::ostringstream summary;
  summary << "segment: " << result.slices.slices.size() << " slices from " << result.frames
          << " frames (every " << options.every << ": " << result.considered << " considered, "
          << result.invalid_pose << " skipped for INVALID pose, " << result.coincident
          << " coinciding with an earlier plane, " << result.failed << " failed, "
          << result.repairs.size() << " repairs); " << regions << " material regions, " << unknown
          << " unknown regions, " << static_cast<int>(100.0 * result.unknown_fraction + 0.5)
          << "% of the sector unknown on average; " << seconds << " s -> "
          << options.output.string();
  log_info(summary.str());
}

// Every organ the models name must be in the output, or the summary says why not.
void warn_missing_labels(const SegmentOptions& options, const segmentation::SweepSetup& setup,
                         const segmentation::SweepSegmentation& result, bool own_labels) {
  for (const segmentation::LabelModel& m : setup.config.materials) {
    if (result.slices_with_label.count(m.label)) continue;
    const auto frames = result.frames_with_label.find(m.label);
    log_warning(
        "segment: label " + std::to_string(m.label) + " (" + m.name + ") is in no slice: " +
        (frames == result.frames_with_label.end() && own_labels
             ? "no label map of " + options.labels.string() +
                   " holds it inside the sector (its header names it)"
         : frames == result.frames_with_label.end()
             ? "no frame's pixels were given it (its grey model, mean " +
                   std::to_string(static_cast<int>(std::lround(m.grey_mean))) +
                   ", matched nothing that survived the cleaning: check the model, or lower "
                   "min_region_mm2 / opening_mm for small organs)"
             : "its regions in " + std::to_string(frames->second) +
                   " frames were all dropped as invalid polygons (see the repairs)"));
  }
}

// Segments the sweep with the label sources given (the site's maps, perfect labels, the truth
// to score against, the overlays, the graph cut's prior).
Result<segmentation::SweepSegmentation> segment(
    const SegmentOptions& options, const Recording& recording,
    const segmentation::SweepSetup& setup, const std::optional<acquisition::SequenceFile>& truth,
    const std::optional<acquisition::SequenceFile>& perfect) {
  const acquisition::SequenceFile& file = recording.file;
  const std::size_t considered =
      (file.frame_count() + static_cast<std::size_t>(options.every) - 1) /
      static_cast<std::size_t>(options.every);
  const acquisition::SequenceFile* replacing = recording.own_labels ? &recording.own_labels->maps
                                               : perfect            ? &*perfect
                                                                    : nullptr;
  segmentation::SweepLabels sources{replacing, truth ? &*truth : nullptr, {}};
  std::optional<OverlayWriter> overlays;
  if (!options.overlays.empty()) {
    std::error_code made;
    std::filesystem::create_directories(options.overlays, made);
    if (made)
      return Status::error("cannot create the --overlays directory " + options.overlays.string() +
                           ": " + made.message());
    overlays.emplace(options, file, setup.geometry.sector, truth ? &*truth : nullptr);
    sources.on_label_map = [&](std::size_t k, const LabelImage& labels) { (*overlays)(k, labels); };
  }
  // The graph cut's prior: an online reconstruction of the slices made so far, in the box
  // that every frame's sector spans (a fixed box: a growing one would rebuild every time).
  std::optional<scan::ReconstructionPrior> prior;
  if (setup.config.method == segmentation::LabellingMethod::kGraphCut && !replacing &&
      options.prior == "reconstruction") {
    recon::ReconstructorOptions recon_options;
    recon_options.engine.max_depth = options.prior_depth;
    recon_options.bounds = sweep_box(file, setup);
    prior.emplace(recon_options);
    sources.predictor = &*prior;
  }
  segmentation::SweepSegmentation result;
  {
    Progress progress("segment", considered);
    result = segmentation::segment_sweep(
        file, setup, options.every, [&](std::size_t done) { progress.update(done); },
        ReadOptions{options.strict}, sources);
  }
  if (overlays) {
    if (!overlays->status()) return overlays->status();
    log_info("segment: " + std::to_string(overlays->written()) + " overlay pictures in " +
             options.overlays.string());
  }
  return result;
}

int run_segment(const SegmentOptions& options) {
  Stopwatch clock;
  auto recording = read_recording(options);
  if (!recording) return print_error(recording.message());
  auto setup = setup_sweep(options, *recording);
  if (!setup) return print_error(setup.message());
  if (!options.report.empty() && options.truth_labels.empty())
    return print_error("--report " + options.report.string() +
                       " needs --truth-labels DIR/labels.mha (the frames to score against)");
  const auto truth =
      read_label_frames(recording->file, options, options.truth_labels, "--truth-labels");
  const auto perfect =
      read_label_frames(recording->file, options, options.perfect_labels, "--perfect-labels");
  for (const auto* read : {&truth, &perfect})
    if (!*read) return print_error(read->message());
  log_models(*setup, recording->own_labels.has_value());
  const auto result = segment(options, *recording, *setup, *truth, *perfect);
  if (!result) return print_error(result.message());
  if (const Status checked = check_segmentation(options, *result); !checked)
    return print_error(checked.message());
  std::error_code ec;
  if (!options.output.parent_path().empty())
    std::filesystem::create_directories(options.output.parent_path(), ec);
  if (const Status written = write_slice_set(result->slices, options.output); !written)
    return print_error(written.message());
  log_summary(options, *result, clock.seconds());
  warn_missing_labels(options, *setup, *result, recording->own_labels.has_value());
  return options.truth_labels.empty() ? 0 : report_comparison(*result, *setup, options);
}

// The recording, its calibration and configuration, and the output.
void add_input_options(CLI::App& app, SegmentOptions* options) {
  app.add_option("sweep", options->input,
                 "Tracked sweep: PLUS sequence file (.igs.mha, .seq.mha, .igs.nrrd; NRRD is "
                 "recognised by its content)")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--config", options->config,
                 "Segmentation config JSON (label grey models, filters, sector; see "
                 "docs/segmentation.md). Default: the models `sonoshape simulate` writes in the "
                 "header, else a two-class split of the data")
      ->check(CLI::ExistingFile);
  app.add_option("--preset", options->preset, preset_help())->check(CLI::IsMember(preset_names()));
  app.add_option("--calibration", options->calibration,
                 "ImageToProbe calibration: PLUS device-set XML, PLUS calibration result "
                 "(.results.xml) or JSON {\"ImageToProbe\": [16 numbers]}. Default: the "
                 "header's ImageToProbeTransform, else <name>.plus.xml next to the sweep")
      ->check(CLI::ExistingFile);
  app.add_option("--pose-transform", options->pose_transform,
                 "The probe's pose as PLUS names it, FROMToTO (e.g. ProbeToReference, "
                 "ToolToTracker, ProbeToTemplate): composed from the frames' transforms and "
                 "the calibration device set's <CoordinateDefinitions> along any chain. "
                 "Default: the header's DefaultFrameTransformName, else Probe (or Tool) to the "
                 "first of Reference, Tracker, Template, StepperHome that a chain reaches");
  app.add_option("--every", options->every, "Keep every K-th frame (from the first)")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_flag("--strict", options->strict,
               "Refuse instead of repairing: the first frame whose polygons could only be made "
               "valid by dropping a region stops the run with an error naming the frame "
               "(exit 1, nothing written). Without it such regions are dropped with one warning "
               "per frame");
  app.add_option("-o,--output", options->output, "Slice set to write (.slices.json / .json)")
      ->capture_default_str();
}

// Label maps from elsewhere (the truth to score against, perfect labels, the site's own), the
// labelling method and the organ seeds.
void add_labelling_options(CLI::App& app, SegmentOptions* options) {
  app.add_option("--truth-labels", options->truth_labels,
                 "Truth label frames of a simulated sweep (DIR/labels.mha of `simulate --truth "
                 "DIR`): score every frame's label map against them (Dice per label, precision/"
                 "recall of the unknown area; a table on stderr)");
  app.add_option("--perfect-labels", options->perfect_labels,
                 "Use these truth label frames instead of the segmenter (same contours and "
                 "placement): the upper bound of the sweep");
  app.add_option("--labels", options->labels,
                 "The site's own label maps instead of sonoshape's segmenter: a label-map "
                 "sequence with one map per frame of the sweep, same size, in order (3D Slicer "
                 ".seq.nrrd, PLUS .mha); 0 background, 1..254 organs (named by Slicer's "
                 "Segment<i>_Name / _LabelValue keys), --labels-unknown for unknown; the same "
                 "outlines and placement as the segmenter's label maps (docs/segmentation.md, "
                 "\"Bring your own labels\")")
      ->check(CLI::ExistingFile);
  app.add_option("--labels-unknown", options->labels_unknown,
                 "With --labels: the label value that marks unknown pixels (shadow, not "
                 "judged); 255 is sonoshape's own")
      ->check(number_in(1, 255))
      ->capture_default_str();
  app.add_option("--method", options->method,
                 "Labelling: threshold (nearest grey model after smoothing) or graph-cut (that "
                 "refined by a multi-label graph cut with learnt appearance models); default: "
                 "the config's `method`, else threshold")
      ->check(CLI::IsMember({"threshold", "graph-cut"}));
  app.add_option("--prior", options->prior,
                 "With --method graph-cut: reconstruction (the surfaces built from the slices so "
                 "far predict each new frame) or none (the image alone)")
      ->check(CLI::IsMember({"reconstruction", "none"}))
      ->capture_default_str();
  app.add_option("--prior-depth", options->prior_depth,
                 "Octree depth of the prior's reconstruction (coarser is faster)")
      ->check(number_in(3, 10))
      ->capture_default_str();
  // --seed is the old spelling (elsewhere --seed is a random seed); kept for scripts.
  app.add_option("--organ-seed,--seed", options->seeds,
                 "LABEL:X,Y,Z (mm, reference frame; repeatable): a point inside that organ. With "
                 "--method graph-cut, organs whose grey models look alike are told apart by "
                 "where they are: a region the reconstruction does not predict takes the label "
                 "of the nearest seed");
}

// Pictures and the score report.
void add_report_options(CLI::App& app, SegmentOptions* options) {
  app.add_option("--overlays", options->overlays,
                 "Directory for pictures of the frames with our label outlines (and the truth's "
                 "in white with --truth-labels): DIR/frame_NNNN.png");
  app.add_option("--overlay-every", options->overlay_every,
                 "With --overlays: a picture of every K-th segmented frame")
      ->check(kPositiveNumber)
      ->capture_default_str();
  app.add_option("--report", options->report,
                 "With --truth-labels: write the scores per frame and in total as JSON");
}

}  // namespace

CommandRunner add_segment_command(CLI::App& app) {
  auto options = std::make_shared<SegmentOptions>();
  add_input_options(app, options.get());
  add_labelling_options(app, options.get());
  add_report_options(app, options.get());
  return [options] { return run_segment(*options); };
}

}  // namespace sonoshape::apps
