#include "mean_value.hpp"

#include <cmath>

namespace sonoshape::recon {

double projected_angle(const Vec2* points, std::size_t count, const Vec2& foot, double height) {
  if (count < 2 || !(height > 0.0)) return 0.0;
  const double h2 = height * height;
  double sum = 0.0;
  Vec2 a = points[count - 1] - foot;
  for (std::size_t i = 0; i < count; ++i) {
    const Vec2 b = points[i] - foot;
    const Vec2 d = b - a;
    const double length_sq = d.squaredNorm();
    if (length_sq > 0.0) {
      const double length = std::sqrt(length_sq);
      const double c = (a.x() * b.y() - a.y() * b.x()) / length;
      if (c != 0.0) {
        const double s_a = a.dot(d) / length;
        const double s_b = b.dot(d) / length;
        const double q2 = c * c + h2;
        const double q = std::sqrt(q2);
        sum += (c / q) * std::atan2(q * length, q2 + s_a * s_b);
      }
    }
    a = b;
  }
  return sum;
}

int winding_number(const Vec2* points, std::size_t count, const Vec2& p) {
  // Sunday's crossing rule with the orientation sign; boundary points count as inside.
  int winding = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const Vec2& a = points[i];
    const Vec2& b = points[(i + 1) % count];
    const double side = (b.x() - a.x()) * (p.y() - a.y()) - (p.x() - a.x()) * (b.y() - a.y());
    if (side == 0.0 && (p - a).dot(p - b) <= 0.0) return 1;  // on the edge
    if (a.y() <= p.y()) {
      if (b.y() > p.y() && side > 0.0) ++winding;
    } else if (b.y() <= p.y() && side < 0.0) {
      --winding;
    }
  }
  return winding;
}

}  // namespace sonoshape::recon
