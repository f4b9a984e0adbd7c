#pragma once
// Labelled cross-sections: what the segmentation produces and the reconstruction consumes.
// See docs/formats/slices.md for the file form of these types.
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/repairs.hpp"

namespace sonoshape {

/// Label of everything a slice does not cover with a region (the null material).
constexpr int kOutsideLabel = 0;
/// Label of regions whose content is not known (shadow, noise, outside the field of view).
constexpr int kUnknownLabel = -1;

/// One connected labelled area of a slice: an outer ring minus holes, in the slice's (u, v)
/// coordinates in mm. Rings have at least 3 points, any orientation, first point not repeated.
struct Region {
  int label = 1;  ///< material id (>= 1) or kUnknownLabel
  Ring2 outer;
  std::vector<Ring2> holes;
};

/// A planar cross-section: the plane through `origin_mm` spanned by the orthonormal `u`, `v`.
/// The in-plane point (a, b) is the world point origin_mm + a*u + b*v; the normal is u x v.
struct LabeledSlice {
  Vec3 origin_mm = Vec3::Zero();
  Vec3 u = Vec3::UnitX();
  Vec3 v = Vec3::UnitY();
  std::optional<double> timestamp_s;
  /// How far the outlines may lie from the true boundaries (standard deviation, mm): a
  /// segmented frame's outlines carry the segmentation's error. 0: exact outlines, which the
  /// reconstruction interpolates; above 0 the thin-plate field fits them as a smoothing spline.
  double outline_sd_mm = 0.0;
  /// Field of view: points of the plane outside it are unknown. None: the whole plane is seen.
  std::optional<Ring2> fov;
  std::vector<Region> regions;

  Vec3 normal() const { return u.cross(v); }
  Vec3 to_world(const Vec2& p) const { return origin_mm + p.x() * u + p.y() * v; }
  Vec2 to_plane(const Vec3& p) const {
    const Vec3 d = p - origin_mm;
    return Vec2(d.dot(u), d.dot(v));
  }
};

/// A material of a slice set.
struct LabelInfo {
  int id = 1;
  std::string name;
  /// The material casts an acoustic shadow over what lies beyond it (bone: the echo stops at
  /// its surface), so its drawn section ends where the labeller put its end, even along an
  /// unknown region (its shadow): those edges are its boundaries, where for other materials
  /// they are where the slice stops seeing (docs/formats/slices.md, docs/engine.md section 8).
  bool casts_shadow = false;
};

/// Everything an offline reconstruction needs.
struct SliceSet {
  std::string units = "mm";
  std::vector<LabelInfo> labels;  ///< declared materials (may be empty for one-label sets)
  std::optional<Box3> bounds;     ///< reconstruction box; none: derived (see default_bounds)
  std::vector<LabeledSlice> slices;
  /// What the reader repaired to make this set usable, in file order (empty for clean input).
  std::vector<Repair> repairs;

  /// Sorted ids of every material used by a region or declared in `labels`.
  std::vector<int> material_ids() const;
  /// The name of a material id ("label_<id>" when not declared).
  std::string label_name(int id) const;
  /// The declared entry of a material id, or {id, label_name(id)} when not declared.
  LabelInfo label_info(int id) const;
  /// `bounds` if given, else the box of all region vertices padded by 10% of its diagonal.
  Box3 effective_bounds() const;
};

}  // namespace sonoshape
