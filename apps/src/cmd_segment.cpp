// `sonoshape segment`: a tracked sweep (PLUS sequence file, MetaImage or NRRD) -> slice set,
// one slice per frame with a valid pose: label map by segmentation/ (or, for a simulated sweep,
// the truth label frames: --perfect-labels), polygons in the reference frame, fov = sector.
// --truth-labels scores every frame's label map against the simulator's truth.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "commands.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/segmentation/sweep.hpp"

namespace sonoshape::apps {
namespace {

struct SegmentOptions {
  std::filesystem::path input;
  std::filesystem::path config;
  std::filesystem::path calibration;
  int every = 1;
  bool strict = false;
  std::filesystem::path output = "slices.json";
  std::filesystem::path truth_labels;    ///< score against these label frames
  std::filesystem::path perfect_labels;  ///< use these label frames instead of the segmenter
  std::filesystem::path report;          ///< JSON of the scores
};

// Reads label frames given by `option` and checks them against the sweep; none when not given.
Result<std::optional<acq::SequenceFile>> read_label_frames(const acq::SequenceFile& sweep,
                                                           const SegmentOptions& options,
                                                           const std::filesystem::path& path,
                                                           const std::string& option) {
  if (path.empty()) return std::optional<acq::SequenceFile>();
  if (!std::filesystem::is_regular_file(path))
    return Status::error(option + " " + path.string() +
                         ": no such file; give DIR/labels.mha as `sonoshape simulate --truth DIR` "
                         "writes it");
  auto labels = acq::read_sequence_file(path);
  if (!labels) return Status::error(option + ": " + labels.message());
  if (const Status same = seg::check_truth_labels(sweep, options.input, *labels, path); !same)
    return Status::error(option + ": " + same.message());
  return std::optional<acq::SequenceFile>(std::move(*labels));
}

// The table on stderr and the JSON report of --truth-labels.
int report_comparison(const seg::SweepSegmentation& result, const seg::SweepSetup& setup,
                      const SegmentOptions& options) {
  std::map<int, std::string> names{{setup.config.background.label, "background"}};
  for (const auto& m : setup.config.materials) names[m.label] = m.name;
  std::cerr << seg::format_comparison(result.comparison_total, names);
  if (options.report.empty()) return 0;
  std::error_code ec;
  if (!options.report.parent_path().empty())
    std::filesystem::create_directories(options.report.parent_path(), ec);
  if (const Status written = seg::write_comparison_report(
          result.comparisons, result.comparison_total, names, options.report);
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  return 0;
}

int run_segment(const SegmentOptions& options) {
  Stopwatch clock;
  const auto file = acq::read_sequence_file(options.input);
  if (!file) {
    std::cerr << "error: " << file.message() << '\n';
    return 1;
  }
  if (const Status tracked = acq::require_tracking(*file, options.input); !tracked) {
    std::cerr << "error: " << tracked.message() << '\n';
    return 1;
  }
  auto optional_path = [](const std::filesystem::path& p) {
    return p.empty() ? std::nullopt : std::optional<std::filesystem::path>(p);
  };
  const auto setup = seg::prepare_sweep(*file, options.input, optional_path(options.config),
                                        optional_path(options.calibration));
  if (!setup) {
    std::cerr << "error: " << setup.message() << '\n';
    return 1;
  }
  if (!options.report.empty() && options.truth_labels.empty()) {
    std::cerr << "error: --report " << options.report.string()
              << " needs --truth-labels DIR/labels.mha (the frames to score against)\n";
    return 1;
  }
  const auto truth = read_label_frames(*file, options, options.truth_labels, "--truth-labels");
  const auto perfect =
      read_label_frames(*file, options, options.perfect_labels, "--perfect-labels");
  for (const auto* read : {&truth, &perfect})
    if (!*read) {
      std::cerr << "error: " << read->message() << '\n';
      return 1;
    }
  std::ostringstream models;
  models << "background " << setup->config.background.grey_mean;
  for (const auto& m : setup->config.materials)
    models << ", " << m.label << ":" << m.name << " " << m.grey_mean;
  log_info("segment: models from " + setup->models_from + " (grey means: " + models.str() +
           "); calibration from " + setup->calibration_from + "; sector from " +
           setup->sector_from);

  const std::size_t considered =
      (file->frame_count() + static_cast<std::size_t>(options.every) - 1) /
      static_cast<std::size_t>(options.every);
  seg::SweepSegmentation result;
  {
    Progress progress("segment", considered);
    result = seg::segment_sweep(
        *file, *setup, options.every, [&](std::size_t done) { progress.update(done); },
        ReadOptions{options.strict},
        seg::SweepLabels{*perfect ? &**perfect : nullptr, *truth ? &**truth : nullptr});
  }
  if (!result.refused.empty()) {
    std::cerr << "error: " << options.input.string() << ", " << result.refused
              << "\n(--strict refuses frames whose polygons needed a repair; nothing written. "
                 "Leave out --strict to drop what cannot be made valid and go on)\n";
    return 1;
  }
  if (result.slices.slices.empty()) {
    std::cerr << "error: no frame of " << options.input.string()
              << " gave a slice (frames with INVALID pose: " << result.invalid_pose
              << ", failed: " << result.failed << "); nothing written\n";
    return 1;
  }
  if (const Status valid = validate_slice_set(result.slices, options.output.string()); !valid) {
    std::cerr << "error: the segmented slices are not a valid slice set (a bug; please report "
                 "it with the input):\n"
              << valid.message() << '\n';
    return 1;
  }
  std::error_code ec;
  if (!options.output.parent_path().empty())
    std::filesystem::create_directories(options.output.parent_path(), ec);
  if (const Status written = write_slice_set(result.slices, options.output); !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
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
          << "% of the sector unknown on average; " << clock.seconds() << " s -> "
          << options.output.string();
  log_info(summary.str());
  return options.truth_labels.empty() ? 0 : report_comparison(result, *setup, options);
}

}  // namespace

CommandRunner add_segment_command(CLI::App& app) {
  auto options = std::make_shared<SegmentOptions>();
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
  app.add_option("--calibration", options->calibration,
                 "ImageToProbe calibration: PLUS device-set XML or JSON {\"ImageToProbe\": [16 "
                 "numbers]}. Default: the header's ImageToProbeTransform, else <name>.plus.xml "
                 "next to the sweep")
      ->check(CLI::ExistingFile);
  app.add_option("--every", options->every, "Keep every K-th frame (from the first)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_flag("--strict", options->strict,
               "Refuse instead of repairing: the first frame whose polygons could only be made "
               "valid by dropping a region stops the run with an error naming the frame "
               "(exit 1, nothing written). Without it such regions are dropped with one warning "
               "per frame");
  app.add_option("-o,--output", options->output, "Slice set to write (.slices.json / .json)")
      ->capture_default_str();
  app.add_option("--truth-labels", options->truth_labels,
                 "Truth label frames of a simulated sweep (DIR/labels.mha of `simulate --truth "
                 "DIR`): score every frame's label map against them (Dice per label, precision/"
                 "recall of the unknown area; a table on stderr)");
  app.add_option("--perfect-labels", options->perfect_labels,
                 "Use these truth label frames instead of the segmenter (same contours and "
                 "placement): the upper bound of the sweep");
  app.add_option("--report", options->report,
                 "With --truth-labels: write the scores per frame and in total as JSON");
  return [options] { return run_segment(*options); };
}

}  // namespace sonoshape::apps
