#include "sonoshape/tracking/keyframes.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "sonoshape/core/errors.hpp"

namespace sonoshape::tracking {

FramePlane frame_plane(const Eigen::Matrix4d& T_reference_image,
                       const std::array<Vec2, 4>& corners_px) {
  const Vec3 column = T_reference_image.block<3, 1>(0, 0);
  const Vec3 row = T_reference_image.block<3, 1>(0, 1);
  const Vec3 normal = column.cross(row);
  if (!(normal.norm() > 1e-12) || !normal.allFinite())
    throw GeometryError("frame_plane: the image axes of T_reference_image are degenerate");
  FramePlane plane;
  plane.normal = normal.normalized();
  for (std::size_t k = 0; k < 4; ++k)
    plane.corners_mm[k] =
        (T_reference_image * Eigen::Vector4d(corners_px[k].x(), corners_px[k].y(), 0.0, 1.0))
            .head<3>();
  return plane;
}

std::array<Vec2, 4> bounding_corners(const std::vector<Vec2>& points_px) {
  if (points_px.empty()) throw std::invalid_argument("bounding_corners: no points");
  Vec2 lo = points_px.front(), hi = points_px.front();
  for (const Vec2& p : points_px) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return {Vec2(lo.x(), lo.y()), Vec2(hi.x(), lo.y()), Vec2(hi.x(), hi.y()), Vec2(lo.x(), hi.y())};
}

PlaneDifference plane_difference(const FramePlane& a, const FramePlane& b) {
  PlaneDifference d;
  const double cosine = std::min(1.0, std::abs(a.normal.dot(b.normal)));
  d.angle_deg = std::acos(cosine) * 180.0 / std::numbers::pi;
  // Corner distances both ways: with the planes' own corners as origins.
  for (const Vec3& c : a.corners_mm)
    d.distance_mm = std::max(d.distance_mm, std::abs(b.normal.dot(c - b.corners_mm[0])));
  for (const Vec3& c : b.corners_mm)
    d.distance_mm = std::max(d.distance_mm, std::abs(a.normal.dot(c - a.corners_mm[0])));
  return d;
}

KeyframeSelector::KeyframeSelector(const KeyframeOptions& options) : options_(options) {
  if (!(options.min_angle_deg >= 0.0) || !(options.min_distance_mm >= 0.0))
    throw std::invalid_argument("KeyframeSelector: thresholds must be >= 0");
}

std::optional<int> KeyframeSelector::offer(const FramePlane& plane) {
  const bool past_budget = options_.slice_budget > 0 && accepted_.size() >= options_.slice_budget;
  const double scale = past_budget ? kPastBudgetScale : 1.0;
  const double min_angle_deg = scale * options_.min_angle_deg;
  const double min_distance_mm = scale * options_.min_distance_mm;
  for (const auto& [key, accepted] : accepted_) {
    const PlaneDifference d = plane_difference(plane, accepted);
    if (d.angle_deg < min_angle_deg && d.distance_mm < min_distance_mm) {
      ++skipped_;
      return std::nullopt;
    }
  }
  const int key = next_key_++;
  accepted_.emplace_back(key, plane);
  return key;
}

bool KeyframeSelector::withdraw(int key) {
  const auto it = std::find_if(accepted_.begin(), accepted_.end(),
                               [&](const auto& entry) { return entry.first == key; });
  if (it == accepted_.end()) return false;
  accepted_.erase(it);
  return true;
}

}  // namespace sonoshape::tracking
