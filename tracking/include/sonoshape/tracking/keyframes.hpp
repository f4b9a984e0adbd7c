#pragma once
// Keyframe selection: not every frame becomes a slice. A frame joins the reconstruction only
// when its plane differs enough from the plane of every slice already in: a freehand sweep at
// 30 fps repeats nearly the same plane many times, and every plane costs the arrangement cells
// (and near-coincident planes make slivers) without adding shape information.
#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <optional>
#include <vector>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::tracking {

/// When two planes count as different. A plane is a near-duplicate of an accepted one when
/// BOTH the angle between them is below min_angle_deg AND no corner of either image moves more
/// than min_distance_mm out of the other's plane; otherwise it is new.
///
/// Defaults measured on 60 s, 30 fps simulated sweeps (1801 frames) of the demo phantom with
/// the 512 x 512 convex probe, hand tremor and drift (docs/benchmarks.md, "Keyframes"): 4 deg /
/// 2.5 mm keeps about 83 slices a minute for a slide and for a fan, with the best IoU of every
/// setting tried (denser keyframes do not improve it: 666 slices score lower), while the
/// arrangement of a fan stays at a third of the cells of 3 deg / 2 mm; at 8 deg / 5 mm the IoU
/// starts to fall. 2.5 mm is also about the elevational thickness of an abdominal probe's beam:
/// closer planes image nearly the same tissue.
struct KeyframeOptions {
  double min_angle_deg = 4.0;
  double min_distance_mm = 2.5;
  /// Long examinations: once this many planes are accepted, a frame must differ from every one
  /// by kPastBudgetScale times both thresholds (0: no budget). Every slice costs memory for as
  /// long as the scan runs, and a hand that keeps returning to the same anatomy with a slow
  /// drift keeps showing planes that differ by just over the thresholds: the count (and the
  /// memory) then grows for as long as the examination lasts, ever more slowly. Past the budget
  /// anatomy already covered at the thresholds' density gets no more slices, while a move to
  /// anatomy not yet covered still does, at a coarser density.
  std::size_t slice_budget = 0;
};

/// How much coarser keyframes are past KeyframeOptions::slice_budget: a plane must lie beyond
/// twice the thresholds from every slice, so that a region sampled at the thresholds' density
/// (neighbouring slices about one threshold apart) offers no plane that is new.
inline constexpr double kPastBudgetScale = 2.0;

/// The plane of a frame for keyframe selection: its image corners in the reference frame.
struct FramePlane {
  std::array<Vec3, 4> corners_mm;  ///< e.g. the corners of the sector's bounding box
  Vec3 normal = Vec3::UnitZ();     ///< unit normal of the image plane
};

/// The plane of an image: `corners_px` (column, row) mapped by T_reference_image (pixels -> mm,
/// PLUS ImageToReference). Throws GeometryError when the image axes are degenerate.
FramePlane frame_plane(const Eigen::Matrix4d& T_reference_image,
                       const std::array<Vec2, 4>& corners_px);

/// The corners of the bounding box of a polygon in pixels (e.g. the sector), in the order
/// (min, min), (max, min), (max, max), (min, max). Throws std::invalid_argument when empty.
std::array<Vec2, 4> bounding_corners(const std::vector<Vec2>& points_px);

/// How much two planes differ.
struct PlaneDifference {
  double angle_deg = 0.0;    ///< angle between the planes (0..90)
  double distance_mm = 0.0;  ///< largest distance of a corner of one to the plane of the other
};

/// The difference of two frame planes (symmetric).
PlaneDifference plane_difference(const FramePlane& a, const FramePlane& b);

/// Chooses keyframes among a stream of frame planes. Not thread-safe (guard it when several
/// pipeline threads use it).
class KeyframeSelector {
 public:
  /// Throws std::invalid_argument for negative thresholds.
  explicit KeyframeSelector(const KeyframeOptions& options = {});

  const KeyframeOptions& options() const { return options_; }

  /// Accepts `plane` when it differs enough from every accepted plane (by the thresholds, or by
  /// kPastBudgetScale times them once slice_budget planes are accepted) and returns its key
  /// (0, 1, 2, ... in acceptance order); none, counted as skipped, for a near-duplicate.
  std::optional<int> offer(const FramePlane& plane);
  /// Forgets an accepted plane (its frame was dropped or failed later), so that a later frame
  /// near it can take its place. False when `key` is not accepted.
  bool withdraw(int key);

  /// Planes accepted and not withdrawn.
  std::size_t accepted() const { return accepted_.size(); }
  /// Near-duplicates offered so far.
  std::size_t skipped() const { return skipped_; }

 private:
  KeyframeOptions options_;
  std::vector<std::pair<int, FramePlane>> accepted_;
  int next_key_ = 0;
  std::size_t skipped_ = 0;
};

}  // namespace sonoshape::tracking
