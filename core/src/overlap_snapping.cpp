#include "overlap_snapping.hpp"

#include <CGAL/Boolean_set_operations_2.h>

#include <algorithm>
#include <optional>
#include <set>
#include <sstream>
#include <tuple>
#include <utility>
#include <vector>

#include "exact_polygons.hpp"
#include "polygon_validity.hpp"
#include "ring_checks.hpp"

namespace sonoshape::detail {
namespace {

// Rings of a region, outer first, each with its repeated points dropped, when all are usable
// polygons; nullopt otherwise (the validation reports them).
std::optional<Region> clean_region(const Region& region) {
  Region clean = region;
  drop_repeated_points(clean.outer);
  if (!ring_problem(clean.outer).empty()) return std::nullopt;
  for (Ring2& hole : clean.holes) {
    drop_repeated_points(hole);
    if (!ring_problem(hole).empty()) return std::nullopt;
  }
  return clean;
}

std::vector<Ring2*> rings_of(Region& region) {
  std::vector<Ring2*> rings{&region.outer};
  for (Ring2& hole : region.holes) rings.push_back(&hole);
  return rings;
}

bool in_box(const Vec2& p, const Box2& box) {
  return (p.array() >= box.lo.array()).all() && (p.array() <= box.hi.array()).all();
}

// Moves every vertex of `moving` in `zone` that lies within `tol` of a vertex of `fixed` onto
// that vertex. Returns how many moved.
// The vertices of `region`'s rings that lie in `zone`.
std::vector<Vec2> vertices_in(Region& region, const Box2& zone) {
  std::vector<Vec2> points;
  for (Ring2* ring : rings_of(region))
    for (const Vec2& p : *ring)
      if (in_box(p, zone)) points.push_back(p);
  return points;
}

std::size_t snap_to_vertices(Region& moving, Region& fixed, const Box2& zone, double tol) {
  const std::vector<Vec2> targets = vertices_in(fixed, zone);
  std::size_t moved = 0;
  for (Ring2* ring : rings_of(moving))
    for (Vec2& q : *ring) {
      if (!in_box(q, zone)) continue;
      const Vec2* nearest = nullptr;
      for (const Vec2& p : targets)
        if ((p - q).norm() <= tol && (!nearest || (p - q).norm() < (*nearest - q).norm()))
          nearest = &p;
      if (nearest && *nearest != q) {
        q = *nearest;
        ++moved;
      }
    }
  return moved;
}

// Inserts into the edges of `target` every vertex of `source` in `zone` that lies within `tol`
// of an edge's interior (a T-junction that rounding moved off the edge), so both regions
// share that point exactly. Returns how many were inserted.
std::size_t insert_near_vertices(Region& target, Region& source, const Box2& zone, double tol) {
  const std::vector<Vec2> points = vertices_in(source, zone);
  std::size_t inserted = 0;
  for (Ring2* ring : rings_of(target)) {
    const std::set<std::pair<double, double>> own = [&] {
      std::set<std::pair<double, double>> s;
      for (const Vec2& p : *ring) s.insert({p.x(), p.y()});
      return s;
    }();
    // (edge, parameter along it, point) of every insertion, applied in order afterwards.
    std::vector<std::tuple<std::size_t, double, Vec2>> insertions;
    for (const Vec2& q : points) {
      if (own.count({q.x(), q.y()})) continue;
      std::optional<std::tuple<std::size_t, double, Vec2>> best;
      double best_distance = tol;
      for (std::size_t k = 0; k < ring->size(); ++k) {
        const Vec2& p0 = (*ring)[k];
        const Vec2& p1 = (*ring)[(k + 1) % ring->size()];
        const Vec2 d = p1 - p0;
        const double t = (q - p0).dot(d) / d.squaredNorm();
        if (!(t > 0.0 && t < 1.0)) continue;
        const double distance = (p0 + t * d - q).norm();
        if (distance <= best_distance) {
          best_distance = distance;
          best = std::make_tuple(k, t, q);
        }
      }
      if (best) insertions.push_back(*best);
    }
    if (insertions.empty()) continue;
    std::sort(insertions.begin(), insertions.end(), [](const auto& x, const auto& y) {
      return std::tie(std::get<0>(x), std::get<1>(x)) < std::tie(std::get<0>(y), std::get<1>(y));
    });
    Ring2 rebuilt;
    std::size_t next = 0;
    for (std::size_t k = 0; k < ring->size(); ++k) {
      rebuilt.push_back((*ring)[k]);
      for (; next < insertions.size() && std::get<0>(insertions[next]) == k; ++next)
        rebuilt.push_back(std::get<2>(insertions[next]));
    }
    inserted += insertions.size();
    *ring = std::move(rebuilt);
  }
  return inserted;
}

// Makes two regions whose overlap is a rounding sliver share its boundary exactly: vertices of
// the later region onto the earlier one's vertices, then each region's vertices near the other's
// edges inserted into those edges. Returns the number of vertices changed, or nullopt (and
// leaves the regions as they were) when the result still overlaps or is not a valid polygon.
std::optional<std::size_t> snap_sliver(Region& a, Region& b, const OverlapMeasure& overlap,
                                       double tol) {
  const Box2 zone{overlap.box.lo - Vec2::Constant(2.0 * tol),
                  overlap.box.hi + Vec2::Constant(2.0 * tol)};
  Region snapped_a = a;
  Region snapped_b = b;
  std::size_t changed = snap_to_vertices(snapped_b, snapped_a, zone, tol);
  changed += insert_near_vertices(snapped_a, snapped_b, zone, tol);
  changed += insert_near_vertices(snapped_b, snapped_a, zone, tol);
  const std::optional<Region> clean_a = clean_region(snapped_a);
  const std::optional<Region> clean_b = clean_region(snapped_b);
  if (changed == 0 || !clean_a || !clean_b) return std::nullopt;
  const ExactPolygonWithHoles exact_a = to_exact(clean_a->outer, clean_a->holes);
  const ExactPolygonWithHoles exact_b = to_exact(clean_b->outer, clean_b->holes);
  if (!valid_for_boolean_ops(exact_a) || !valid_for_boolean_ops(exact_b) ||
      measure_overlap(exact_a, exact_b))
    return std::nullopt;
  a = *clean_a;
  b = *clean_b;
  return changed;
}

// Snaps regions a and b of a slice when their overlap is a rounding sliver; records the repair.
void snap_pair(LabeledSlice& slice, std::size_t index, std::size_t a, std::size_t b,
               const std::string& units, const SliceNaming& naming, RepairLog& repairs) {
  const std::optional<Region> clean_a = clean_region(slice.regions[a]);
  const std::optional<Region> clean_b = clean_region(slice.regions[b]);
  if (!clean_a || !clean_b) return;
  // An earlier snap of this slice may have removed this overlap already.
  const ExactPolygonWithHoles exact_a = to_exact(clean_a->outer, clean_a->holes);
  const ExactPolygonWithHoles exact_b = to_exact(clean_b->outer, clean_b->holes);
  // An earlier snap may have left a region CGAL cannot take; the validation then reports it.
  if (!valid_for_boolean_ops(exact_a) || !valid_for_boolean_ops(exact_b)) return;
  // Cheaper than measuring. Tag_false: the segment traits, whose precondition was checked.
  if (!CGAL::do_intersect(exact_a, exact_b, CGAL::Tag_false())) return;
  const auto overlap = measure_overlap(exact_a, exact_b);
  const double tol = kRoundingOverlapRelTol * slice_extent(slice);
  if (!overlap || overlap->width > tol) return;
  Region snapped_a = *clean_a;
  Region snapped_b = *clean_b;
  const auto changed = snap_sliver(snapped_a, snapped_b, *overlap, tol);
  if (!changed) return;  // the validation reports it
  std::ostringstream width;
  width.precision(2);
  width << overlap->width;
  repairs.add(
      naming.slice(index),
      {"rounding_overlap",
       naming.slice(index) + ", " + naming.region(index, a, slice.regions[a].label) + " and " +
           naming.region(index, b, slice.regions[b].label),
       "overlap of " + overlap_text(slice, *overlap, units) + ", " + width.str() +
           " thick, is a shared edge that rounding moved apart (" + std::to_string(*changed) +
           (*changed == 1 ? " vertex" : " vertices") + " snapped onto the shared boundary)",
       overlap->area});
  for (auto [k, snapped] : {std::pair{a, &snapped_a}, std::pair{b, &snapped_b}}) {
    slice.regions[k].outer = std::move(snapped->outer);
    slice.regions[k].holes = std::move(snapped->holes);
  }
}

}  // namespace

void snap_rounding_overlaps(SliceSet& set, const RegionPairs& pairs, const SliceNaming& naming,
                            RepairLog& repairs) {
  for (const RegionPair& pair : pairs)
    snap_pair(set.slices[pair.slice], pair.slice, pair.a, pair.b, set.units, naming, repairs);
}

}  // namespace sonoshape::detail
