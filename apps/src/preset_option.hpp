#pragma once
// The --preset NAME option of `segment` and `scan`: a named set of segmentation settings for what
// a kind of recording holds (segmentation::segmentation_presets, docs/segmentation.md "Presets").
#include <string>
#include <vector>

#include "sonoshape/segmentation/config.hpp"

namespace sonoshape::apps {

inline std::vector<std::string> preset_names() {
  std::vector<std::string> names;
  for (const segmentation::SegmentationPreset& p : segmentation::segmentation_presets())
    names.push_back(p.name);
  return names;
}

inline std::string preset_help() {
  std::string text =
      "Segmentation settings for what the recording holds (its models still learnt from the "
      "frames); --config / --segmentation keys and --method override them. Default: "
      "soft-tissue.";
  for (const segmentation::SegmentationPreset& p : segmentation::segmentation_presets())
    text += " " + p.name + ": " + p.summary + ".";
  return text;
}

}  // namespace sonoshape::apps
