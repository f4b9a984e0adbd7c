#pragma once
// Shapes the engine's tests cut into slices.
#include <cmath>
#include <numbers>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon::test {

/// A circle of `n` vertices, counter-clockwise, in plane coordinates (mm).
inline Ring2 circle(const Vec2& center, double radius, int n) {
  Ring2 ring;
  for (int i = 0; i < n; ++i) {
    const double t = 2.0 * std::numbers::pi * i / n;
    ring.emplace_back(center.x() + radius * std::cos(t), center.y() + radius * std::sin(t));
  }
  return ring;
}

}  // namespace sonoshape::recon::test
