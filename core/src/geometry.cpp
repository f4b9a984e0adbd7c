#include "sonoshape/core/geometry.hpp"

namespace sonoshape {

double signed_area(const Ring2& ring) {
  double twice_area = 0.0;
  const std::size_t n = ring.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2& a = ring[i];
    const Vec2& b = ring[(i + 1) % n];
    twice_area += a.x() * b.y() - a.y() * b.x();
  }
  return 0.5 * twice_area;
}

}  // namespace sonoshape
