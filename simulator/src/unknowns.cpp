#include "sonoshape/simulator/unknowns.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

#include "sonoshape/core/region_clipping.hpp"

namespace sonoshape::simulator {
namespace {

// Clips (or cuts away) `shape` from every material region of the slice.
void apply_to_materials(LabeledSlice& slice, const Ring2& shape, bool keep_inside) {
  std::vector<Region> out;
  for (const Region& region : slice.regions) {
    if (region.label == kUnknownLabel) {
      out.push_back(region);
      continue;
    }
    for (Region& r : clip_region(region, shape, keep_inside)) out.push_back(std::move(r));
  }
  slice.regions = std::move(out);
}

// Inserts into `ring` every vertex of `others` that lies on one of its edges, so that two
// polygons meeting along that edge share it vertex for vertex after rounding.
void insert_touching_vertices(Ring2& ring, const std::vector<Region>& others, double tolerance) {
  std::vector<Vec2> candidates;
  for (const Region& r : others) {
    if (r.label == kUnknownLabel) continue;
    candidates.insert(candidates.end(), r.outer.begin(), r.outer.end());
    for (const Ring2& h : r.holes) candidates.insert(candidates.end(), h.begin(), h.end());
  }
  Ring2 out;
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const Vec2& a = ring[i];
    const Vec2& b = ring[(i + 1) % ring.size()];
    out.push_back(a);
    std::vector<std::pair<double, Vec2>> on_edge;
    const Vec2 d = b - a;
    const double length2 = d.squaredNorm();
    for (const Vec2& c : candidates) {
      if (c == a || c == b) continue;
      const double t = (c - a).dot(d) / length2;
      if (t <= 0.0 || t >= 1.0) continue;
      if ((a + t * d - c).norm() <= tolerance) on_edge.emplace_back(t, c);
    }
    std::sort(on_edge.begin(), on_edge.end(),
              [](const auto& x, const auto& y) { return x.first < y.first; });
    for (const auto& [t, c] : on_edge)
      if (out.back() != c) out.push_back(c);
  }
  ring = std::move(out);
}

}  // namespace

FovShape parse_fov_shape(const std::string& name) {
  if (name == "none") return FovShape::kNone;
  if (name == "sector") return FovShape::kSector;
  if (name == "rect") return FovShape::kRect;
  throw std::invalid_argument("unknown field of view '" + name +
                              "' (expected none, sector or rect)");
}

namespace {

// The field of view of one slice around `target` (the material's centroid), its axis at
// `angle`; with fov_covers_material, placed and sized to hold every point of `contour`.
Ring2 make_fov(const UnknownOptions& options, const Vec2& target, const std::vector<Vec2>& contour,
               double angle, double diagonal) {
  const Vec2 axis(std::cos(angle), std::sin(angle));
  const Vec2 side(-axis.y(), axis.x());
  const double half = 0.5 * options.fan_angle_deg * std::numbers::pi / 180.0;
  double depth = options.fov_depth_mm;
  Vec2 apex = target - 0.5 * depth * axis;
  double rect_width = options.rect_width_mm;
  if (options.fov_covers_material) {
    // The material's bounding box centre and the radius around it that holds every contour
    // point (a tenth of the box diagonal on slices without material), 10 % margin.
    Vec2 lo = target, hi = target;
    for (const Vec2& p : contour) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const Vec2 centre = 0.5 * (lo + hi);
    double radius = contour.empty() ? 0.1 * diagonal : 0.0;
    for (const Vec2& p : contour) radius = std::max(radius, (p - centre).norm());
    radius *= 1.1;
    if (options.fov == FovShape::kSector) {
      const double apex_distance = radius / std::sin(half);  // the fan's sides touch the circle
      apex = centre - apex_distance * axis;
      depth = apex_distance + radius;
    } else {
      apex = centre - radius * axis;
      depth = rect_width = 2.0 * radius;
    }
  }
  Ring2 fov;
  if (options.fov == FovShape::kSector) {
    fov.push_back(apex);
    for (int k = 0; k <= 16; ++k) {
      const double a = -half + 2.0 * half * k / 16.0;
      fov.push_back(apex + depth * (std::cos(a) * axis + std::sin(a) * side));
    }
  } else {
    const double w = 0.5 * rect_width;
    fov = {apex - w * side, apex - w * side + depth * axis, apex + w * side + depth * axis,
           apex + w * side};
  }
  if (signed_area(fov) < 0.0) std::reverse(fov.begin(), fov.end());
  return fov;
}

// An unknown blob over a random contour vertex of the slice's materials (inside the fov when
// there is one); false when the slice has no material.
bool add_blob(LabeledSlice& slice, const UnknownOptions& options, double diagonal,
              std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Vec2> candidates;
  for (const Region& r : slice.regions)
    if (r.label != kUnknownLabel)
      candidates.insert(candidates.end(), r.outer.begin(), r.outer.end());
  if (candidates.empty()) return false;
  const Vec2 center =
      candidates[static_cast<std::size_t>(unit(rng) * candidates.size()) % candidates.size()];
  const double radius = options.blob_radius * (0.67 + 0.66 * unit(rng)) * diagonal;
  Ring2 blob;
  for (int k = 0; k < 16; ++k) {
    const double a = 2.0 * std::numbers::pi * (k + 0.3 * unit(rng)) / 16.0;
    const double r = radius * (0.7 + 0.6 * unit(rng));
    blob.push_back(center + r * Vec2(std::cos(a), std::sin(a)));
  }
  apply_to_materials(slice, blob, false);
  insert_touching_vertices(blob, slice.regions, 1e-9 * diagonal);
  slice.regions.push_back({kUnknownLabel, blob, {}});
  return true;
}

}  // namespace

void add_unknowns(SliceSet& set, const UnknownOptions& options) {
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const Box3 bounds = set.effective_bounds();
  const double diagonal = bounds.diagonal();
  for (LabeledSlice& slice : set.slices) {
    // Where the material of this slice is (or the box centre when there is none).
    Vec2 target = slice.to_plane(0.5 * (bounds.min + bounds.max));
    std::vector<Vec2> contour;
    for (const Region& r : slice.regions)
      if (r.label != kUnknownLabel) contour.insert(contour.end(), r.outer.begin(), r.outer.end());
    if (!contour.empty()) {
      Vec2 sum = Vec2::Zero();
      for (const Vec2& p : contour) sum += p;
      target = sum / static_cast<double>(contour.size());
    }
    if (options.fov != FovShape::kNone) {
      const double angle = 2.0 * std::numbers::pi * unit(rng);
      const Ring2 fov = make_fov(options, target, contour, angle, diagonal);
      apply_to_materials(slice, fov, true);
      slice.fov = fov;
    }
    if (unit(rng) >= options.fraction) continue;
    add_blob(slice, options, diagonal, rng);
  }
}

}  // namespace sonoshape::simulator
