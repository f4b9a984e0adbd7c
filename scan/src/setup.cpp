#include "sonoshape/scan/setup.hpp"

#include <algorithm>

#include "sonoshape/tracking/keyframes.hpp"

namespace sonoshape::scan {

std::array<Vec2, 4> keyframe_corners(const ScanSetup& setup) {
  if (!setup.geometry.sector_px.empty())
    return tracking::bounding_corners(setup.geometry.sector_px);
  const double w = std::max(0, setup.geometry.width_px - 1);
  const double h = std::max(0, setup.geometry.height_px - 1);
  return {Vec2(0, 0), Vec2(w, 0), Vec2(w, h), Vec2(0, h)};
}

}  // namespace sonoshape::scan
