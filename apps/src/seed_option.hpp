#pragma once
// The --organ-seed LABEL:X,Y,Z arguments of `segment` and `scan`: a point inside an organ, in the
// reference frame (mm), that names it among organs the image cannot tell apart.
#include <charconv>
#include <cmath>
#include <string>
#include <vector>

#include "sonoshape/core/status.hpp"
#include "sonoshape/segmentation/config.hpp"

namespace sonoshape::apps {

/// Sets LabelModel::seed_mm of the materials the arguments name. Errors name the argument and
/// the fix: a malformed one, or a label that is not among the configuration's materials.
inline Status apply_seeds(const std::vector<std::string>& arguments,
                          segmentation::SegmentationConfig& config) {
  for (const std::string& text : arguments) {
    const auto fail = [&](const std::string& why) {
      return Status::error("--organ-seed '" + text + "': " + why +
                           " (expected LABEL:X,Y,Z in mm in the reference frame, e.g. "
                           "2:10.5,-3,40)");
    };
    const std::size_t colon = text.find(':');
    if (colon == std::string::npos) return fail("no label");
    int label = 0;
    const char* p = text.data();
    const char* end = p + text.size();
    if (auto [at, ec] = std::from_chars(p, p + colon, label); ec != std::errc() || at != p + colon)
      return fail("the label must be an integer");
    double xyz[3] = {0, 0, 0};
    p += colon + 1;
    for (int k = 0; k < 3; ++k) {
      const auto [at, ec] = std::from_chars(p, end, xyz[k]);
      const bool last = k == 2;
      const bool separated = last ? at == end : at != end && *at == ',';
      if (ec != std::errc() || !std::isfinite(xyz[k]) || !separated)
        return fail("three finite numbers separated by commas are needed");
      p = last ? at : at + 1;
    }
    segmentation::LabelModel* model = nullptr;
    std::string known;
    for (segmentation::LabelModel& m : config.materials) {
      if (m.label == label) model = &m;
      known += (known.empty() ? "" : ", ") + std::to_string(m.label) + ":" + m.name;
    }
    if (!model)
      return fail("label " + std::to_string(label) + " is not among the segmentation's " +
                  "materials (" + (known.empty() ? "none" : known) + ")");
    model->seed_mm = Vec3(xyz[0], xyz[1], xyz[2]);
  }
  return Status::ok();
}

}  // namespace sonoshape::apps
