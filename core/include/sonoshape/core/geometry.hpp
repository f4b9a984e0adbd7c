#pragma once
// Basic geometric value types shared by every module (Eigen, double precision, millimetres).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

namespace sonoshape {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;

/// A closed polygon boundary in a plane's 2D coordinates (mm); the first point is not repeated.
using Ring2 = std::vector<Vec2>;

/// Axis-aligned box in world coordinates (mm).
struct Box3 {
  Vec3 min = Vec3::Constant(0.0);
  Vec3 max = Vec3::Constant(0.0);

  Vec3 size() const { return max - min; }
  double diagonal() const { return size().norm(); }
  bool contains(const Vec3& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
  /// The box grown by `margin` on every side.
  Box3 padded(double margin) const {
    return Box3{min - Vec3::Constant(margin), max + Vec3::Constant(margin)};
  }
};

/// Signed area of a ring (positive when counter-clockwise), shoelace formula.
double signed_area(const Ring2& ring);

}  // namespace sonoshape
