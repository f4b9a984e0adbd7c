#include "sonoshape/segmentation/scoring.hpp"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

namespace sonoshape::segmentation {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double ratio(std::size_t numerator, std::size_t denominator) {
  return denominator ? static_cast<double>(numerator) / static_cast<double>(denominator) : kNaN;
}

// JSON has no NaN: an undefined ratio (a class in neither map) is null.
nlohmann::json number_or_null(double x) {
  return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(nullptr);
}

nlohmann::json counts_json(const PixelCounts& c) {
  return {{"truth_px", c.truth_px}, {"ours_px", c.ours_px}, {"both_px", c.both_px}};
}

nlohmann::json comparison_json(const LabelComparison& c, const std::map<int, std::string>& names) {
  nlohmann::json labels = nlohmann::json::object();
  for (const auto& [label, counts] : c.labels) {
    nlohmann::json entry = counts_json(counts);
    entry["dice"] = number_or_null(counts.dice());
    if (const auto it = names.find(label); it != names.end()) entry["name"] = it->second;
    labels[std::to_string(label)] = entry;
  }
  nlohmann::json unknown = counts_json(c.unknown);
  unknown["precision"] = number_or_null(c.unknown.precision());
  unknown["recall"] = number_or_null(c.unknown.recall());
  return {{"sector_px", c.sector_px}, {"labels", labels}, {"unknown", unknown}};
}

std::string fixed(double x) {
  if (!std::isfinite(x)) return "-";
  std::ostringstream text;
  text << std::fixed << std::setprecision(3) << x;
  return text.str();
}

}  // namespace

double PixelCounts::dice() const { return ratio(2 * both_px, truth_px + ours_px); }
double PixelCounts::precision() const { return ratio(both_px, ours_px); }
double PixelCounts::recall() const { return ratio(both_px, truth_px); }

void PixelCounts::add(const PixelCounts& other) {
  truth_px += other.truth_px;
  ours_px += other.ours_px;
  both_px += other.both_px;
}

void LabelComparison::add(const LabelComparison& other) {
  for (const auto& [label, counts] : other.labels) labels[label].add(counts);
  unknown.add(other.unknown);
  sector_px += other.sector_px;
}

LabelComparison compare_labels(const LabelImage& truth, const LabelImage& ours,
                               const ImageU8& sector) {
  if (truth.width != ours.width || truth.height != ours.height || truth.width != sector.width ||
      truth.height != sector.height || truth.pixels.size() != ours.pixels.size() ||
      truth.pixels.size() != sector.pixels.size())
    throw std::invalid_argument(
        "compare_labels: the truth, our label map and the sector differ "
        "in size");
  // Counted in flat arrays first: a map lookup per pixel would dominate the time.
  std::vector<std::size_t> truth_px(256, 0), ours_px(256, 0), both_px(256, 0);
  LabelComparison out;
  for (std::size_t p = 0; p < truth.pixels.size(); ++p) {
    if (!sector.pixels[p]) continue;
    ++out.sector_px;
    const std::uint8_t t = truth.pixels[p], o = ours.pixels[p];
    const bool truth_unknown = t == kLabelPixelUnknown, ours_unknown = o == kLabelPixelUnknown;
    out.unknown.truth_px += truth_unknown ? 1 : 0;
    out.unknown.ours_px += ours_unknown ? 1 : 0;
    out.unknown.both_px += truth_unknown && ours_unknown ? 1 : 0;
    if (truth_unknown) continue;  // labels are scored where the truth is known
    ++truth_px[t];
    if (!ours_unknown) ++ours_px[o];
    if (t == o) ++both_px[t];
  }
  for (int l = 0; l < kLabelPixelUnknown; ++l) {
    const auto k = static_cast<std::size_t>(l);
    if (truth_px[k] || ours_px[k]) out.labels[l] = {truth_px[k], ours_px[k], both_px[k]};
  }
  return out;
}

Status check_truth_labels(const acquisition::SequenceFile& sweep,
                          const std::filesystem::path& sweep_path,
                          const acquisition::SequenceFile& truth,
                          const std::filesystem::path& truth_path) {
  const std::string fix =
      "; give the labels.mha that `sonoshape simulate --truth DIR` wrote "
      "together with " +
      sweep_path.string();
  if (truth.frame_count() != sweep.frame_count())
    return Status::error(truth_path.string() + " has " + std::to_string(truth.frame_count()) +
                         " label frames but " + sweep_path.string() + " has " +
                         std::to_string(sweep.frame_count()) + " frames" + fix);
  for (std::size_t k = 0; k < truth.frame_count(); ++k) {
    const LabelImage& t = truth.image(k);
    const GreyImage& s = sweep.image(k);
    if (t.width != s.width || t.height != s.height)
      return Status::error(truth_path.string() + ", frame " + std::to_string(k) + ": the label " +
                           "frame is " + std::to_string(t.width) + "x" + std::to_string(t.height) +
                           " but the frame of " + sweep_path.string() + " is " +
                           std::to_string(s.width) + "x" + std::to_string(s.height) + fix);
  }
  return Status::ok();
}

std::string comparison_json_text(const LabelComparison& comparison,
                                 const std::map<int, std::string>& names) {
  return comparison_json(comparison, names).dump();
}

std::string format_comparison(const LabelComparison& total,
                              const std::map<int, std::string>& names) {
  std::ostringstream text;
  text << "segmentation against the truth (" << total.sector_px << " sector pixels):\n"
       << "  label                 Dice\n";
  for (const auto& [label, counts] : total.labels) {
    const auto it = names.find(label);
    const std::string name = std::to_string(label) + ":" +
                             (it != names.end() ? it->second : "label_" + std::to_string(label));
    text << "  " << std::left << std::setw(20) << name << "  " << fixed(counts.dice()) << '\n';
  }
  text << "  unknown area: precision " << fixed(total.unknown.precision()) << ", recall "
       << fixed(total.unknown.recall()) << '\n';
  return text.str();
}

Status write_comparison_report(const std::vector<FrameComparison>& frames,
                               const LabelComparison& total,
                               const std::map<int, std::string>& names,
                               const std::filesystem::path& path) {
  nlohmann::json doc;
  doc["frames"] = nlohmann::json::array();
  for (const FrameComparison& f : frames) {
    nlohmann::json entry = comparison_json(f.comparison, names);
    entry["frame"] = f.frame;
    doc["frames"].push_back(entry);
  }
  doc["total"] = comparison_json(total, names);
  std::ofstream out(path);
  if (!out) return Status::error("cannot write the report " + path.string() + ": check the path");
  out << doc.dump(2) << '\n';
  if (!out) return Status::error("cannot write the report " + path.string() + ": disk full?");
  return Status::ok();
}

}  // namespace sonoshape::segmentation
