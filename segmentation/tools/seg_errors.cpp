// Which pixels of one label the segmenter gets wrong, against a simulated sweep's truth label
// frames (`sonoshape simulate --truth DIR` writes DIR/labels.mha): every error pixel of the
// label (a miss: truth has it, we do not; an extra: we have it, the truth has another known
// label) is counted by where it lies:
// - by its distance (px) to the truth's boundary of the label (1: on the boundary's pixels);
// - for the boundary pixels, on which side of the organ along the beam (the image columns):
//   "top" (the beam enters the organ there), "bottom" (it leaves) or "side";
// - what the other map says there (background, another organ, unknown);
// - whether it lies in a thin part of the organ (what an opening of the truth's mask with a disk
//   of --thin-mm radius removes), and whether the frame is one of the organ's ends (its truth
//   area below --end-mm2).
// Usage:
//   sonoshape_seg_errors SWEEP TRUTH_LABELS --label L [--every K] [--config JSON]
//                        [--preset NAME] [--thin-mm R] [--end-mm2 A]
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/segmentation/sweep.hpp"

namespace {

using namespace sonoshape;

struct Options {
  std::filesystem::path sweep, truth;
  std::optional<std::filesystem::path> config;
  std::string preset;
  int label = 2;
  int every = 1;
  double thin_mm = 1.5;
  double end_mm2 = 40.0;
};

std::optional<Options> parse(int argc, char** argv) {
  Options o;
  int positional = 0;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    auto next = [&]() -> std::string { return k + 1 < argc ? argv[++k] : ""; };
    if (a == "--label")
      o.label = std::atoi(next().c_str());
    else if (a == "--every")
      o.every = std::atoi(next().c_str());
    else if (a == "--config")
      o.config = next();
    else if (a == "--preset")
      o.preset = next();
    else if (a == "--thin-mm")
      o.thin_mm = std::atof(next().c_str());
    else if (a == "--end-mm2")
      o.end_mm2 = std::atof(next().c_str());
    else if (positional == 0 && ++positional)
      o.sweep = a;
    else if (positional == 1 && ++positional)
      o.truth = a;
    else
      return std::nullopt;
  }
  if (positional != 2 || o.every < 1 || o.label < 1 || o.label > 254) return std::nullopt;
  return o;
}

cv::Mat wrap(const ImageU8& image) {
  return cv::Mat(image.height, image.width, CV_8U, const_cast<std::uint8_t*>(image.pixels.data()));
}

// Error pixel counts by category name.
using Tally = std::map<std::string, double>;

// The side of the organ a boundary pixel lies on along the image columns (the beam, near enough
// for these figures): the organ's truth pixel right below it (top), right above it (bottom).
std::string side_of(const cv::Mat& organ, int i, int j, bool inside) {
  auto has = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < organ.cols && y < organ.rows && organ.at<std::uint8_t>(y, x);
  };
  // For a pixel inside the organ the question is where its outside neighbour lies.
  const bool below = inside ? !has(i, j + 1) : has(i, j + 1);
  const bool above = inside ? !has(i, j - 1) : has(i, j - 1);
  if (inside ? above : below) return "top";
  if (inside ? below : above) return "bottom";
  return "side";
}

std::string other_name(std::uint8_t v, int label) {
  if (v == kLabelPixelOutside) return "background";
  if (v == kLabelPixelUnknown) return "unknown";
  return v == label ? "itself" : "organ " + std::to_string(v);
}

void count_frame(const LabelImage& ours_image, const LabelImage& truth_image, const ImageU8& sector,
                 const Options& o, double px_mm, Tally& misses, Tally& extras, double& both,
                 std::map<std::string, double>& frames) {
  const cv::Mat ours = wrap(ours_image), truth = wrap(truth_image), in = wrap(sector) > 0;
  const cv::Mat organ = (truth == o.label) & in;
  const double truth_mm2 = cv::countNonZero(organ) * px_mm * px_mm;
  const bool end = truth_mm2 > 0.0 && truth_mm2 < o.end_mm2;
  cv::Mat outside_dist, inside_dist, opened;
  // Distance of every pixel to the nearest organ pixel, and of every organ pixel to the nearest
  // other pixel (1 on the boundary's pixels).
  cv::distanceTransform(~organ, outside_dist, cv::DIST_L2, cv::DIST_MASK_5);
  cv::distanceTransform(organ, inside_dist, cv::DIST_L2, cv::DIST_MASK_5);
  const int r = static_cast<int>(std::lround(o.thin_mm / px_mm));
  cv::morphologyEx(organ, opened, cv::MORPH_OPEN,
                   cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
  const cv::Mat thin = organ & ~opened;
  // The truth's boundary pixels (organ pixels with an outside 4-neighbour) by side, to weigh
  // the boundary errors by the boundary's length.
  for (int j = 0; j < organ.rows; ++j)
    for (int i = 0; i < organ.cols; ++i)
      if (organ.at<std::uint8_t>(j, i) && inside_dist.at<float>(j, i) < 1.5f &&
          truth.at<std::uint8_t>(j, i) != kLabelPixelUnknown)
        frames["boundary pixels, " + side_of(organ, i, j, true)] += 1;
  double frame_miss = 0, frame_extra = 0, frame_both = 0;
  for (int j = 0; j < ours.rows; ++j)
    for (int i = 0; i < ours.cols; ++i) {
      if (!in.at<std::uint8_t>(j, i)) continue;
      const std::uint8_t t = truth.at<std::uint8_t>(j, i), u = ours.at<std::uint8_t>(j, i);
      if (t == kLabelPixelUnknown) continue;
      const bool truth_has = t == o.label, ours_has = u == o.label;
      if (truth_has && ours_has) {
        ++frame_both;
        continue;
      }
      if (!truth_has && !ours_has) continue;
      Tally& tally = truth_has ? misses : extras;
      const double d = truth_has ? inside_dist.at<float>(j, i) : outside_dist.at<float>(j, i);
      const int ring = std::min(3, static_cast<int>(std::lround(d)));
      tally["all"] += 1;
      tally["distance " + std::string(ring >= 3 ? ">=3" : std::to_string(ring)) + " px"] += 1;
      if (ring <= 1) tally["boundary, " + side_of(organ, i, j, truth_has)] += 1;
      tally["other map: " + other_name(truth_has ? u : t, o.label)] += 1;
      if (truth_has && thin.at<std::uint8_t>(j, i)) tally["thin part"] += 1;
      if (end) tally["end frame"] += 1;
      (truth_has ? frame_miss : frame_extra) += 1;
    }
  both += frame_both;
  if (truth_mm2 > 0.0 || frame_extra > 0) {
    const std::string bin = truth_mm2 == 0.0            ? "no truth"
                            : truth_mm2 < o.end_mm2     ? "end (< end-mm2)"
                            : truth_mm2 < 4 * o.end_mm2 ? "small"
                                                        : "large";
    frames[bin + " frames"] += 1;
    frames[bin + " misses"] += frame_miss;
    frames[bin + " extras"] += frame_extra;
    frames[bin + " both"] += frame_both;
  }
}

void print(const std::string& title, const Tally& tally, double errors) {
  std::cout << title << '\n';
  for (const auto& [name, n] : tally)
    std::cout << "  " << std::left << std::setw(32) << name << std::right << std::setw(9)
              << static_cast<long>(n) << "  " << std::fixed << std::setprecision(1)
              << 100.0 * n / std::max(errors, 1.0) << " % of all errors\n";
}

}  // namespace

int main(int argc, char** argv) {
  const auto options = parse(argc, argv);
  if (!options) {
    std::cerr << "usage: sonoshape_seg_errors SWEEP TRUTH_LABELS --label L [--every K] "
                 "[--config JSON] [--preset NAME] [--thin-mm R] [--end-mm2 A]\n";
    return 2;
  }
  auto file = acquisition::read_sequence_file(options->sweep);
  auto truth = acquisition::read_sequence_file(options->truth);
  if (!file || !truth) {
    std::cerr << "error: " << (!file ? file.message() : truth.message()) << '\n';
    return 1;
  }
  auto setup = segmentation::prepare_sweep(*file, options->sweep, options->config, std::nullopt, {},
                                           options->preset);
  if (!setup) {
    std::cerr << "error: " << setup.message() << '\n';
    return 1;
  }
  Tally misses, extras;
  std::map<std::string, double> frames;
  double both = 0.0;
  segmentation::SweepLabels labels;
  labels.on_label_map = [&](std::size_t k, const LabelImage& ours) {
    count_frame(ours, truth->image(k), setup->geometry.sector, *options, setup->geometry.spacing_mm,
                misses, extras, both, frames);
  };
  segmentation::segment_sweep(*file, *setup, options->every, {}, {}, labels);
  const double errors = misses["all"] + extras["all"];
  std::cout << "label " << options->label << ": both " << static_cast<long>(both) << ", misses "
            << static_cast<long>(misses["all"]) << ", extras " << static_cast<long>(extras["all"])
            << ", Dice " << std::setprecision(3) << 2 * both / (2 * both + errors) << '\n';
  print("misses (truth has it, ours not):", misses, errors);
  print("extras (ours has it, truth another known label):", extras, errors);
  std::cout << "by frame (truth area):\n";
  for (const auto& [name, n] : frames)
    std::cout << "  " << std::left << std::setw(32) << name << std::right << static_cast<long>(n)
              << '\n';
  return 0;
}
