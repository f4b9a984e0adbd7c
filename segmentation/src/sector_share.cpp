#include "sonoshape/segmentation/sector_share.hpp"

#include <array>
#include <cmath>
#include <stdexcept>

namespace sonoshape::segmentation {

SectorShareCheck::SectorShareCheck(const ImageU8& sector) : sector_(sector) {
  for (const std::uint8_t v : sector_.pixels) sector_px_ += v ? 1 : 0;
}

void SectorShareCheck::add(const LabelImage& labels) {
  if (labels.width != sector_.width || labels.height != sector_.height ||
      labels.pixels.size() != sector_.pixels.size())
    throw std::invalid_argument("SectorShareCheck: the label map does not match the sector");
  if (sector_px_ == 0) return;  // nothing to fill
  std::array<std::size_t, 256> count{};
  for (std::size_t p = 0; p < labels.pixels.size(); ++p)
    if (sector_.pixels[p]) ++count[labels.pixels[p]];
  ++frames_;
  for (int label = 1; label < 256; ++label)  // the background may fill a sector
    if (static_cast<double>(count[static_cast<std::size_t>(label)]) >=
        kNearlyAll * static_cast<double>(sector_px_))
      ++filled_frames_[label];
}

std::optional<int> SectorShareCheck::dominant_label() const {
  for (const auto& [label, frames] : filled_frames_)
    if (static_cast<double>(frames) > kMost * static_cast<double>(frames_)) return label;
  return std::nullopt;
}

std::optional<std::string> SectorShareCheck::warning(
    const std::map<int, std::string>& names) const {
  const auto label = dominant_label();
  if (!label) return std::nullopt;
  const std::string share = std::to_string(std::lround(100.0 * kNearlyAll)) +
                            "% of the sector in " + std::to_string(filled_frames_.at(*label)) +
                            " of " + std::to_string(frames_) + " frames";
  if (*label == kLabelPixelUnknown)
    return "unknown (no signal: anechoic water or gel, shadows) fills at least " + share +
           ": the models find no tissue in these frames. A phantom in water? Try --preset "
           "wires or --preset water-tank (docs/segmentation.md, Presets)";
  const auto name = names.find(*label);
  return "label " + std::to_string(*label) + " (" +
         (name != names.end() ? name->second : "unnamed") + ") fills at least " + share +
         ": the grey models do not tell apart what these frames hold, so its surface would be "
         "the swept sector. Try the --preset for what the recording holds (wires, water-tank, "
         "bone, soft-tissue) or give models with --config (docs/segmentation.md)";
}

}  // namespace sonoshape::segmentation
