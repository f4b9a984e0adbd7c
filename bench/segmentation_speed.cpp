// Per-frame time of the segmentation, split by stage: what `sonoshape segment` and the live scan
// do to every frame (segmentation::segment_frame, then segmentation::make_slice: contours,
// simplification and the validity check). docs/benchmarks.md, "Segmentation speed";
// bench/segmentation_speed.py runs it.
//
//   sonoshape_seg_speed SWEEP.igs.mha [--calibration FILE] [--threads N] [--repeat R]
//                       [--method threshold|graph-cut] [--json OUT.json] [--dump-labels OUT.raw]
//
// --method graph-cut segments through segmentation::GraphCutLabeller (no prior: the image alone)
// instead of segmentation::segment_frame. --threads N sets OpenCV's pool (cv::setNumThreads);
// without it OpenCV's default is kept. Every frame with a valid pose is segmented R times (after
// one untimed warm-up frame). --dump-labels writes the label maps of the first pass, frame after
// frame (raw bytes), to compare two builds.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/segmentation/contours.hpp"
#include "sonoshape/segmentation/labeller.hpp"
#include "sonoshape/segmentation/segmenter.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "stage_times.hpp"

namespace {

using namespace sonoshape;
using Clock = std::chrono::steady_clock;

struct Options {
  std::string sweep;
  std::optional<std::string> calibration, json, dump_labels;
  int threads = -1;  // -1: OpenCV's default
  int repeat = 3;
  bool graph_cut = false;
};

[[noreturn]] void usage(const std::string& why) {
  std::cerr << "sonoshape_seg_speed: " << why
            << "\nusage: sonoshape_seg_speed SWEEP [--calibration FILE] [--threads N] "
               "[--repeat R] [--method threshold|graph-cut] [--json OUT] [--dump-labels OUT]\n";
  std::exit(2);
}

Options parse(int argc, char** argv) {
  Options o;
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    auto value = [&]() -> std::string {
      if (k + 1 >= argc) usage(arg + " needs a value");
      return argv[++k];
    };
    if (arg == "--calibration")
      o.calibration = value();
    else if (arg == "--threads")
      o.threads = std::atoi(value().c_str());
    else if (arg == "--repeat")
      o.repeat = std::atoi(value().c_str());
    else if (arg == "--method") {
      const std::string method = value();
      if (method != "threshold" && method != "graph-cut")
        usage("--method is threshold or graph-cut, not " + method);
      o.graph_cut = method == "graph-cut";
    } else if (arg == "--json")
      o.json = value();
    else if (arg == "--dump-labels")
      o.dump_labels = value();
    else if (!arg.empty() && arg[0] == '-')
      usage("unknown option " + arg);
    else
      o.sweep = arg;
  }
  if (o.sweep.empty()) usage("no sweep given");
  if (o.repeat < 1) usage("--repeat must be at least 1");
  if (o.threads == 0 || o.threads < -1) usage("--threads must be at least 1");
  return o;
}

double percentile(std::vector<double> values, double q) {
  std::sort(values.begin(), values.end());
  const auto k = static_cast<std::size_t>(q * static_cast<double>(values.size() - 1) + 0.5);
  return values[std::min(k, values.size() - 1)];
}

}  // namespace

int main(int argc, char** argv) {
  const Options options = parse(argc, argv);
  if (options.threads > 0) cv::setNumThreads(options.threads);
  auto file = acquisition::read_sequence_file(options.sweep);
  if (!file) {
    std::cerr << file.message() << "\n";
    return 1;
  }
  std::optional<std::filesystem::path> calibration;
  if (options.calibration) calibration = *options.calibration;
  auto setup = segmentation::prepare_sweep(*file, options.sweep, std::nullopt, calibration);
  if (!setup) {
    std::cerr << setup.message() << "\n";
    return 1;
  }
  std::vector<std::pair<std::size_t, Eigen::Matrix4d>> frames;
  for (std::size_t k = 0; k < file->frame_count(); ++k)
    if (const auto pose = segmentation::reference_from_probe(*file, k, *setup))
      frames.emplace_back(k, *pose);
  if (frames.empty()) {
    std::cerr << options.sweep << ": no frame with a valid pose\n";
    return 1;
  }
  const ImageU8& sector = setup->geometry.sector;
  const cv::Rect box = cv::boundingRect(
      cv::Mat(sector.height, sector.width, CV_8U, const_cast<std::uint8_t*>(sector.pixels.data())));
  std::size_t sector_px = 0;
  for (const std::uint8_t v : sector.pixels) sector_px += v ? 1 : 0;
  std::ofstream dump;
  if (options.dump_labels) dump.open(*options.dump_labels, std::ios::binary);

  std::optional<segmentation::GraphCutLabeller> labeller;
  if (options.graph_cut) labeller.emplace(setup->config, setup->geometry, setup->config.graph_cut);
  auto one_frame = [&](std::size_t k, const Eigen::Matrix4d& pose) {
    const segmentation::Segmentation s =
        labeller ? labeller->segment(file->image(k))
                 : segmentation::segment_frame(file->image(k), setup->geometry, setup->config);
    const segmentation::ImagePlane plane =
        segmentation::image_plane(pose * setup->T_probe_image, pose.block<3, 1>(0, 3));
    std::vector<Repair> repairs;
    const auto slice =
        segmentation::make_slice(s.labels, setup->geometry.sector, setup->geometry.sector_px, plane,
                                 setup->config.simplify_mm, &repairs);
    return std::make_pair(s.labels, slice ? slice->regions.size() : std::size_t{0});
  };
  one_frame(frames.front().first, frames.front().second);  // warm-up: pools, first allocations

  segmentation::detail::StageTimes stages;
  segmentation::detail::stage_times_sink = &stages;
  double contours_ms = 0.0;
  std::vector<double> frame_ms;
  const std::clock_t cpu_start = std::clock();
  std::size_t regions = 0;
  for (int pass = 0; pass < options.repeat; ++pass)
    for (const auto& [k, pose] : frames) {
      const Clock::time_point start = Clock::now();
      const double before = stages.ms[0] + stages.ms[1] + stages.ms[2] + stages.ms[3];
      const auto [labels, n] = one_frame(k, pose);
      const double total = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
      const double segmenting = stages.ms[0] + stages.ms[1] + stages.ms[2] + stages.ms[3] - before;
      contours_ms += total - segmenting;
      frame_ms.push_back(total);
      if (pass == 0) {
        regions += n;
        if (dump)
          dump.write(reinterpret_cast<const char*>(labels.pixels.data()),
                     static_cast<std::streamsize>(labels.pixels.size()));
      }
    }
  segmentation::detail::stage_times_sink = nullptr;
  // Processor time of all threads (OpenCV's pool included): on a machine shared with other
  // work, the wall time includes waiting for a core, this does not.
  const double cpu_ms = 1000.0 * static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;

  const auto n = static_cast<double>(frame_ms.size());
  const char* names[] = {"filter", "confidence", "classify", "cleaning"};
  nlohmann::json out;
  out["sweep"] = options.sweep;
  out["width_px"] = file->width();
  out["height_px"] = file->height();
  out["frames"] = frames.size();
  out["repeat"] = options.repeat;
  out["method"] = options.graph_cut ? "graph-cut" : "threshold";
  out["opencv_threads"] = cv::getNumThreads();
  out["regions_first_pass"] = regions;
  out["sector_fraction"] =
      static_cast<double>(sector_px) / static_cast<double>(sector.pixels.size());
  out["sector_box"] = {box.x, box.y, box.width, box.height};
  for (std::size_t s = 0; s < 4; ++s) out["stage_ms"][names[s]] = stages.ms[s] / n;
  out["stage_ms"]["contours"] = contours_ms / n;
  double sum = 0.0;
  for (const double t : frame_ms) sum += t;
  // Each frame's fastest pass, averaged over the frames: on a machine shared with other work the
  // least disturbed passes, near what an idle machine gives.
  double best_sum = 0.0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    double best = frame_ms[f];
    for (std::size_t k = f; k < frame_ms.size(); k += frames.size())
      best = std::min(best, frame_ms[k]);
    best_sum += best;
  }
  const double best_mean = best_sum / static_cast<double>(frames.size());
  out["frame_ms"] = {{"mean", sum / n},
                     {"median", percentile(frame_ms, 0.5)},
                     {"p90", percentile(frame_ms, 0.9)},
                     {"max", percentile(frame_ms, 1.0)},
                     {"best_of_repeats_mean", best_mean},
                     {"cpu_mean", cpu_ms / n}};
  std::printf("%s: %dx%d (sector %.0f%% of it, box %dx%d), %zu frames x %d, OpenCV threads %d\n",
              options.sweep.c_str(), file->width(), file->height(),
              100.0 * out["sector_fraction"].get<double>(), box.width, box.height, frames.size(),
              options.repeat, cv::getNumThreads());
  for (const char* name : {"filter", "confidence", "classify", "cleaning", "contours"})
    std::printf("  %-10s %7.2f ms\n", name, out["stage_ms"][name].get<double>());
  std::printf(
      "  frame      %7.2f ms mean, %.2f median, %.2f p90, %.2f max, %.2f best of %d; %.2f ms CPU\n",
      sum / n, percentile(frame_ms, 0.5), percentile(frame_ms, 0.9), percentile(frame_ms, 1.0),
      best_mean, options.repeat, cpu_ms / n);
  if (options.json) std::ofstream(*options.json) << out.dump(2) << "\n";
  return 0;
}
