// The rules of docs/formats/slices.md, one named function each, run in the order of their
// messages by validate_slice_set_named; and the end every reader shares (finish_parsed_set).
#include "slice_rules.hpp"

#include <CGAL/Boolean_set_operations_2.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "exact_polygons.hpp"
#include "overlap_snapping.hpp"
#include "polygon_validity.hpp"
#include "ring_checks.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/slice_compare.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "text_io.hpp"

namespace sonoshape::detail {

std::string SliceNaming::slice(std::size_t slice) const { return "slice " + std::to_string(slice); }

std::string SliceNaming::region(std::size_t /*slice*/, std::size_t region, int label) const {
  return "region " + std::to_string(region) + " (label " + label_text(label) + ")";
}

std::string SliceNaming::outer(std::size_t slice, std::size_t region, int label) const {
  return this->slice(slice) + ", " + this->region(slice, region, label) + ", outer ring";
}

std::string SliceNaming::hole(std::size_t slice, std::size_t region, int label,
                              std::size_t hole) const {
  return this->slice(slice) + ", " + this->region(slice, region, label) + ", hole " +
         std::to_string(hole);
}

namespace {

std::string join_ids(const std::set<int>& ids) {
  std::string text;
  for (int id : ids) text += (text.empty() ? "" : ", ") + std::to_string(id);
  return text;
}

std::string vec_text(const Vec3& v) {
  return "(" + format_double(v.x()) + ", " + format_double(v.y()) + ", " + format_double(v.z()) +
         ")";
}

// Same point set in world coordinates, up to `tol`, whatever the order or the slice basis.
bool same_world_points(const LabeledSlice& sa, const Ring2& a, const LabeledSlice& sb,
                       const Ring2& b, double tol) {
  if (a.size() != b.size()) return false;
  std::vector<Vec3> wb;
  wb.reserve(b.size());
  for (const Vec2& p : b) wb.push_back(sb.to_world(p));
  std::vector<bool> used(wb.size(), false);
  for (const Vec2& p : a) {
    const Vec3 w = sa.to_world(p);
    bool found = false;
    for (std::size_t k = 0; k < wb.size() && !found; ++k) {
      if (!used[k] && (wb[k] - w).norm() <= tol) used[k] = found = true;
    }
    if (!found) return false;
  }
  return true;
}

// Empty when both coincident slices hold the same content; else the difference, in words.
std::string content_difference(const LabeledSlice& a, const LabeledSlice& b, double tol) {
  if (identical_slices(a, b)) return {};  // a copy: no need to match points up to `tol`
  if (a.fov.has_value() != b.fov.has_value()) return "only one of them has a fov";
  if (a.outline_sd_mm != b.outline_sd_mm) return "their outline_sd_mm differ";
  if (a.fov && !same_world_points(a, *a.fov, b, *b.fov, tol)) return "their fov differ";
  if (a.regions.size() != b.regions.size())
    return std::to_string(a.regions.size()) + " regions against " +
           std::to_string(b.regions.size());
  std::vector<bool> used(b.regions.size(), false);
  for (const Region& ra : a.regions) {
    bool found = false;
    for (std::size_t k = 0; k < b.regions.size() && !found; ++k) {
      const Region& rb = b.regions[k];
      if (used[k] || rb.label != ra.label || rb.holes.size() != ra.holes.size() ||
          !same_world_points(a, ra.outer, b, rb.outer, tol))
        continue;
      std::vector<bool> hole_used(rb.holes.size(), false);
      bool holes_match = true;
      for (const Ring2& ha : ra.holes) {
        bool hole_found = false;
        for (std::size_t h = 0; h < rb.holes.size() && !hole_found; ++h)
          if (!hole_used[h] && same_world_points(a, ha, b, rb.holes[h], tol))
            hole_used[h] = hole_found = true;
        holes_match = holes_match && hole_found;
      }
      if (holes_match) used[k] = found = true;
    }
    if (!found)
      return "a region of label " + label_text(ra.label) + " has no identical counterpart";
  }
  return {};
}

// Does the plane of `slice` cross the box (closed, grown by `tol`)?
bool plane_meets_box(const LabeledSlice& slice, const Box3& box, double tol) {
  const Vec3 n = slice.normal().normalized();
  double lo = std::numeric_limits<double>::infinity();
  double hi = -lo;
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3 p((corner & 1) ? box.max.x() : box.min.x(), (corner & 2) ? box.max.y() : box.min.y(),
                 (corner & 4) ? box.max.z() : box.min.z());
    const double d = n.dot(p - slice.origin_mm);
    lo = std::min(lo, d);
    hi = std::max(hi, d);
  }
  return lo <= tol && hi >= -tol;
}

constexpr std::size_t kMaxReportedErrors = 20;

// The problems a validation finds, in the order found: reported together (up to
// kMaxReportedErrors), one per line, each starting with the input's name.
class Problems {
 public:
  explicit Problems(const std::string& source_name) : source_name_(source_name) {}
  void add(const std::string& where, const std::string& what) {
    errors_.push_back(source_name_ + ": " + where + ": " + what);
  }
  bool empty() const { return errors_.empty(); }
  Status status() const {
    if (errors_.empty()) return Status::ok();
    std::string message;
    for (std::size_t k = 0; k < errors_.size() && k < kMaxReportedErrors; ++k)
      message += (k ? "\n" : "") + errors_[k];
    if (errors_.size() > kMaxReportedErrors)
      message +=
          "\n... and " + std::to_string(errors_.size() - kMaxReportedErrors) + " more problems";
    return Status::error(message);
  }

 private:
  const std::string& source_name_;
  std::vector<std::string> errors_;
};

// Rule: material ids in "labels" are positive and declared once. Returns the declared ids.
std::set<int> check_declared_labels(const SliceSet& set, Problems& problems) {
  std::set<int> declared;
  for (const LabelInfo& label : set.labels) {
    if (label.id < 1)
      problems.add("labels", "id " + std::to_string(label.id) +
                                 " is not a positive integer; material ids start at 1 (0 is the "
                                 "outside)");
    else if (!declared.insert(label.id).second)
      problems.add("labels", "id " + std::to_string(label.id) +
                                 " is declared twice; give each material one entry");
  }
  return declared;
}

// Rule: bounds are finite with min below max on every axis. True when there are bounds to
// test slices against.
bool check_bounds_box(const SliceSet& set, Problems& problems) {
  if (!set.bounds) return false;
  const Box3& b = *set.bounds;
  if (!b.min.allFinite() || !b.max.allFinite()) {
    problems.add("bounds", "min and max must be finite numbers");
    return false;
  }
  bool bounds_ok = true;
  for (int k = 0; k < 3; ++k) {
    if (b.min[k] >= b.max[k]) {
      problems.add("bounds", "min[" + std::to_string(k) + "] = " + format_double(b.min[k]) +
                                 " is not below max[" + std::to_string(k) +
                                 "] = " + format_double(b.max[k]) +
                                 "; give a box with min < max on every axis");
      bounds_ok = false;
    }
  }
  return bounds_ok;
}

// Rule: origin, u and v are finite; u and v are unit and orthogonal. True when they are.
bool check_slice_basis(const LabeledSlice& s, const std::string& where, Problems& problems) {
  if (!s.origin_mm.allFinite() || !s.u.allFinite() || !s.v.allFinite()) {
    problems.add(where, "origin, u and v must be finite numbers");
    return false;
  }
  const double u_len = s.u.norm();
  const double v_len = s.v.norm();
  const double u_dot_v = s.u.dot(s.v);
  const std::string hint =
      "; write unit orthogonal vectors, or add \"normalize\": true at the top level of the "
      "file to let the reader normalise them";
  if (std::abs(u_len - 1.0) > kBasisTol)
    problems.add(where, "u is not unit length (|u| = " + format_double(u_len) + ")" + hint);
  else if (std::abs(v_len - 1.0) > kBasisTol)
    problems.add(where, "v is not unit length (|v| = " + format_double(v_len) + ")" + hint);
  else if (std::abs(u_dot_v) > kBasisTol)
    problems.add(where, "u and v are not orthogonal (u.v = " + format_double(u_dot_v) + ")" + hint);
  else
    return true;
  return false;
}

// Rule: a timestamp is a finite number, and so is the outlines' error, at least 0.
void check_timestamp(const LabeledSlice& s, const std::string& where, Problems& problems) {
  if (s.timestamp_s && !std::isfinite(*s.timestamp_s))
    problems.add(where, "timestamp is not a finite number");
  if (!(s.outline_sd_mm >= 0.0) || !std::isfinite(s.outline_sd_mm))
    problems.add(where, "outline_sd_mm is not a finite number of 0 or more");
}

// Rule: a fov is a usable polygon.
void check_fov(const LabeledSlice& s, const std::string& where, Problems& problems) {
  if (!s.fov) return;
  Ring2 fov = *s.fov;
  drop_repeated_points(fov);
  const std::string problem = ring_problem(fov);
  if (!problem.empty()) problems.add(where + ", fov", problem);
}

// Rule: a region's label is "unknown" or a positive material id, one that "labels" declares
// when it lists materials.
void check_region_label(const Region& r, const std::string& region_where,
                        const std::set<int>& declared, Problems& problems) {
  if (r.label == kOutsideLabel) {
    problems.add(region_where,
                 "label 0 is the outside (the null material), which needs no region; remove the "
                 "region or give it a material id");
  } else if (r.label < kOutsideLabel && r.label != kUnknownLabel) {
    problems.add(region_where, "label " + std::to_string(r.label) +
                                   " is neither \"unknown\" nor a positive material id");
  } else if (r.label > 0 && !declared.empty() && !declared.count(r.label)) {
    problems.add(region_where, "label " + std::to_string(r.label) +
                                   " is not declared in \"labels\" (declared: " +
                                   join_ids(declared) + "); declare it or use a declared id");
  }
}

// A region of a slice under the ring rules: its rings with repeated points dropped, and their
// exact boundaries for the overlap tests.
struct CheckedRegion {
  std::size_t slice = 0, index = 0;
  int label = 0;
  Ring2 outer;
  std::vector<Ring2> holes;
  RegionRings rings;
  std::vector<Segments> hole_segments;
  Box2 box{Vec2::Zero(), Vec2::Zero()};
};

// Rule: the outer ring and every hole are usable polygons. Fills the region's rings.
bool check_region_rings(const Region& r, const SliceNaming& naming, CheckedRegion& region,
                        Problems& problems) {
  region.outer = r.outer;
  drop_repeated_points(region.outer);
  if (std::string problem = ring_problem(region.outer); !problem.empty()) {
    problems.add(naming.outer(region.slice, region.index, r.label), problem);
    return false;
  }
  bool holes_ok = true;
  for (std::size_t k = 0; k < r.holes.size(); ++k) {
    Ring2 hole = r.holes[k];
    drop_repeated_points(hole);
    if (std::string problem = ring_problem(hole); !problem.empty()) {
      problems.add(naming.hole(region.slice, region.index, r.label, k), problem);
      holes_ok = false;
    }
    region.holes.push_back(std::move(hole));
  }
  return holes_ok;
}

// The exact boundaries of a region whose rings are usable.
void build_boundaries(CheckedRegion& region) {
  RegionRings& rings = region.rings;
  rings.outer = to_points(region.outer);
  add_segments(rings.outer, rings.segments);
  for (std::size_t k = 0; k < region.holes.size(); ++k) {
    rings.holes.push_back(to_points(region.holes[k]));
    region.hole_segments.push_back(segments_of(rings.holes.back()));
    add_segments(rings.holes.back(), rings.segments);
  }
}

// Rule: every hole lies inside its region's outer ring and is not the whole of it. Sets
// `boundaries_touch` when a hole's boundary meets the outer ring's.
bool check_holes_inside(const CheckedRegion& region, const SliceNaming& naming,
                        bool& boundaries_touch, Problems& problems) {
  // Exact Boolean operations only where boundaries meet; disjoint ones need point tests.
  const Segments outer_segments = segments_of(region.rings.outer);
  bool holes_ok = true;
  for (std::size_t k = 0; k < region.holes.size(); ++k) {
    const Ring2& hole = region.holes[k];
    const bool meets_outer = boundaries_meet(region.hole_segments[k], outer_segments);
    boundaries_touch = boundaries_touch || meets_outer;
    const bool inside = meets_outer
                            ? exact_inside(to_exact(hole, CGAL::COUNTERCLOCKWISE),
                                           to_exact(region.outer, CGAL::COUNTERCLOCKWISE))
                            : strictly_inside(region.rings.holes[k].front(), region.rings.outer);
    const std::string where = naming.hole(region.slice, region.index, region.label, k);
    if (!inside) {
      problems.add(where,
                   "hole is not inside the region's outer ring; a hole must lie within its "
                   "polygon (touching the boundary is fine), fix it or make it a separate region");
      holes_ok = false;
    } else if (std::abs(signed_area(hole)) >= std::abs(signed_area(region.outer))) {
      // Inside and as large: the outer ring itself. Nothing is left of the region (and the
      // exact overlap test cannot take such a polygon).
      problems.add(where,
                   "hole is the region's whole outer ring, so the region has no area; remove the "
                   "region or the hole");
      holes_ok = false;
    }
  }
  return holes_ok;
}

// Rule: two holes of a region do not overlap. Sets `boundaries_touch` when two holes meet.
bool check_holes_apart(const CheckedRegion& region, const SliceNaming& naming,
                       bool& boundaries_touch, Problems& problems) {
  const std::vector<Ring2>& holes = region.holes;
  const std::vector<Segments>& hole_segments = region.hole_segments;
  std::vector<Box2> hole_boxes;
  for (const Ring2& hole : holes) hole_boxes.push_back(box_of(hole));
  bool holes_ok = true;
  for (std::size_t a = 0; a < holes.size(); ++a)
    for (std::size_t b = a + 1; b < holes.size(); ++b) {
      if (!hole_boxes[a].interiors_overlap(hole_boxes[b])) {
        // Boxes that touch: the holes may meet at a corner, which is no overlap.
        if (hole_boxes[a].meets(hole_boxes[b]))
          boundaries_touch =
              boundaries_touch || boundaries_meet(hole_segments[a], hole_segments[b]);
        continue;
      }
      const Points& ring_a = region.rings.holes[a];
      const Points& ring_b = region.rings.holes[b];
      const bool overlap =
          boundaries_meet(hole_segments[a], hole_segments[b])
              ? CGAL::do_intersect(to_exact(holes[a], CGAL::COUNTERCLOCKWISE),
                                   to_exact(holes[b], CGAL::COUNTERCLOCKWISE))
              : strictly_inside(ring_a.front(), ring_b) || strictly_inside(ring_b.front(), ring_a);
      if (overlap) {
        problems.add(naming.hole(region.slice, region.index, region.label, a),
                     "overlaps hole " + std::to_string(b) +
                         " of the same region; merge the two holes into one");
        holes_ok = false;
      }
    }
  return holes_ok;
}

// Rule: holes inside and apart from each other make a valid polygon with holes; where their
// boundaries touch, CGAL decides whether its overlap tests (segment traits) can take the region.
bool check_polygon_with_holes(const CheckedRegion& region, bool boundaries_touch,
                              const std::string& region_where, Problems& problems) {
  if (!boundaries_touch || valid_for_boolean_ops(to_exact(region.outer, region.holes))) return true;
  problems.add(region_where,
               "its holes meet the outer ring or each other along an edge, or in corners that "
               "cut the region apart, so it is not a valid polygon with holes; a hole may touch "
               "the outer ring or another hole only at single corners: cut such a hole into the "
               "outer ring, or merge the holes");
  return false;
}

// The rules of one region, in order: its label, its rings, its holes. The region, ready for the
// overlap tests, when its rings passed.
std::optional<CheckedRegion> check_region(const LabeledSlice& s, std::size_t i, std::size_t j,
                                          const std::set<int>& declared, const SliceNaming& naming,
                                          Problems& problems) {
  const Region& r = s.regions[j];
  const std::string region_where = naming.slice(i) + ", " + naming.region(i, j, r.label);
  check_region_label(r, region_where, declared, problems);
  CheckedRegion region;
  region.slice = i;
  region.index = j;
  region.label = r.label;
  if (!check_region_rings(r, naming, region, problems)) return std::nullopt;
  build_boundaries(region);
  bool boundaries_touch = false;  // a hole's boundary meets the outer ring's or another's
  const bool inside = check_holes_inside(region, naming, boundaries_touch, problems);
  const bool apart = check_holes_apart(region, naming, boundaries_touch, problems);
  if (!inside || !apart) return std::nullopt;
  if (!check_polygon_with_holes(region, boundaries_touch, region_where, problems))
    return std::nullopt;
  region.box = box_of(region.outer);
  return region;
}

// Rule: regions of one slice do not share area. Overlaps no thicker than rounding go to
// `thin_overlaps` when it is given (the readers snap them).
void check_regions_apart(const SliceSet& set, std::size_t i,
                         const std::vector<CheckedRegion>& regions, const SliceNaming& naming,
                         RegionPairs* thin_overlaps, Problems& problems) {
  const LabeledSlice& s = set.slices[i];
  for (std::size_t a = 0; a < regions.size(); ++a)
    for (std::size_t b = a + 1; b < regions.size(); ++b) {
      if (!regions[a].box.interiors_overlap(regions[b].box)) continue;
      const ExactPolygonWithHoles exact_a = to_exact(regions[a].outer, regions[a].holes);
      const ExactPolygonWithHoles exact_b = to_exact(regions[b].outer, regions[b].holes);
      const bool overlapping =
          boundaries_meet(regions[a].rings.segments, regions[b].rings.segments)
              ? CGAL::do_intersect(exact_a, exact_b, CGAL::Tag_false())
              : disjoint_boundaries_overlap(regions[a].rings, regions[b].rings);
      // Measured only when there is something to report: the intersection costs more.
      const std::optional<OverlapMeasure> overlap =
          overlapping ? measure_overlap(exact_a, exact_b) : std::nullopt;
      if (!overlap) continue;
      const bool thin = overlap->width <= kRoundingOverlapRelTol * slice_extent(s);
      if (thin && thin_overlaps) {
        thin_overlaps->push_back({i, a, b});
        continue;
      }
      problems.add(naming.slice(i),
                   naming.region(i, a, s.regions[a].label) + " and " +
                       naming.region(i, b, s.regions[b].label) + " overlap by " +
                       overlap_text(s, *overlap, set.units) +
                       (thin ? " (a sliver thinner than the rounding tolerance: an edge "
                               "the two share, moved apart by rounding; the file readers "
                               "snap such slivers, this one is not snapped)"
                             : "") +
                       "; regions of one slice may share edges or sit in each other's holes "
                       "but not share area, fix the contours or cut one out of the other with "
                       "a hole");
    }
}

// Rule: a slice does not lie entirely outside bounds: its plane misses the box, or what it
// sees does. A slice with a fov sees its fov (outside where no region is), so it lies outside
// only when its fov does: a frame whose regions lie beyond the box but whose sector crosses it
// says "outside" there. A slice without a fov is judged by its regions (a misplaced origin or
// wrong units put them all beyond the box).
void check_slice_meets_bounds(const LabeledSlice& s, const Box3& box, const std::string& where,
                              Problems& problems) {
  const double tol = 1e-9 * box.diagonal();
  bool outside = !plane_meets_box(s, box, tol);
  if (!outside && (s.fov || !s.regions.empty())) {
    // Box of the seen vertices in world coordinates: when it misses the bounds, so does what
    // they outline (a conservative test: it never rejects a slice that reaches the box).
    Box3 seen{Vec3::Constant(std::numeric_limits<double>::infinity()),
              Vec3::Constant(-std::numeric_limits<double>::infinity())};
    const auto take = [&](const Ring2& ring) {
      for (const Vec2& p : ring) {
        const Vec3 w = s.to_world(p);
        seen.min = seen.min.cwiseMin(w);
        seen.max = seen.max.cwiseMax(w);
      }
    };
    if (s.fov)
      take(*s.fov);
    else
      for (const Region& r : s.regions) take(r.outer);
    outside = ((seen.max.array() < box.min.array() - tol).any() ||
               (seen.min.array() > box.max.array() + tol).any());
  }
  if (outside)
    problems.add(where, "the slice lies entirely outside bounds (min " + vec_text(box.min) +
                            ", max " + vec_text(box.max) +
                            "); check its origin and the units, or enlarge bounds");
}

// The rules of one slice, in order: its plane, timestamp and fov, its regions one by one, their
// overlaps (once every region passed), its place in the bounds.
void check_slice(const SliceSet& set, std::size_t i, const std::set<int>& declared, bool bounds_ok,
                 const SliceNaming& naming, RegionPairs* thin_overlaps, Problems& problems) {
  const LabeledSlice& s = set.slices[i];
  const std::string where = naming.slice(i);
  const bool basis_ok = check_slice_basis(s, where, problems);
  check_timestamp(s, where, problems);
  check_fov(s, where, problems);
  std::vector<CheckedRegion> regions;
  bool regions_ok = true;
  for (std::size_t j = 0; j < s.regions.size(); ++j) {
    std::optional<CheckedRegion> region = check_region(s, i, j, declared, naming, problems);
    if (region)
      regions.push_back(std::move(*region));
    else
      regions_ok = false;
  }
  if (regions_ok) check_regions_apart(set, i, regions, naming, thin_overlaps, problems);
  if (bounds_ok && basis_ok && s.origin_mm.allFinite())
    check_slice_meets_bounds(s, *set.bounds, where, problems);
}

// Rule: slices in one plane hold the same content. Identical ones are not an error: the later
// of each such pair goes to `identical` (when given) for the reader to merge.
void check_coincident_slices(const SliceSet& set, const SliceNaming& naming, SlicePairs* identical,
                             Problems& problems) {
  if (set.slices.size() < 2) return;
  const double scale = std::max(1.0, set.effective_bounds().diagonal());
  const double offset_tol = kCoincidentTol * scale;
  std::vector<Vec3> normals;
  for (const LabeledSlice& s : set.slices) normals.push_back(s.normal().normalized());
  // A slice identical to an earlier one is compared with nothing else: what it would find, the
  // earlier one finds. 100 copies of a slice cost 99 comparisons, not 4950.
  std::vector<bool> copy(set.slices.size(), false);
  for (std::size_t i = 0; i < set.slices.size(); ++i) {
    if (copy[i]) continue;
    for (std::size_t j = i + 1; j < set.slices.size(); ++j) {
      if (copy[j] || std::abs(normals[i].dot(normals[j])) < 1.0 - kCoincidentTol) continue;
      if (std::abs(normals[i].dot(set.slices[j].origin_mm - set.slices[i].origin_mm)) > offset_tol)
        continue;
      const std::string difference = content_difference(set.slices[i], set.slices[j], offset_tol);
      if (difference.empty()) {
        copy[j] = true;
        if (identical) identical->emplace_back(i, j);
      } else {
        problems.add(naming.slice(i) + " and " + naming.slice(j),
                     "they lie in the same plane but their contents disagree (" + difference +
                         "); remove one of them or put all regions of that plane into one slice");
      }
    }
  }
}

}  // namespace

Status validate_slice_set_named(const SliceSet& set, const std::string& source_name,
                                const SliceNaming& naming, SlicePairs* identical,
                                RegionPairs* thin_overlaps) {
  Problems problems(source_name);
  const std::set<int> declared = check_declared_labels(set, problems);
  const bool bounds_ok = check_bounds_box(set, problems);
  for (std::size_t i = 0; i < set.slices.size(); ++i)
    check_slice(set, i, declared, bounds_ok, naming, thin_overlaps, problems);
  // Coincident slices: only once every slice is sound, since the test needs finite planes.
  if (problems.empty()) check_coincident_slices(set, naming, identical, problems);
  return problems.status();
}

void merge_identical_slices(SliceSet& set, const SlicePairs& identical, const SliceNaming& naming,
                            RepairLog& repairs) {
  if (identical.empty()) return;
  std::set<std::size_t> dropped;
  for (const auto& [kept, later] : identical) {
    if (dropped.count(kept) || !dropped.insert(later).second) continue;
    repairs.add(naming.slice(later),
                {"duplicate_slice", naming.slice(later),
                 "lies in the same plane as " + naming.slice(kept) +
                     " with identical contents; merged (dropped " + naming.slice(later) + ")",
                 0.0});
  }
  std::vector<LabeledSlice> slices;
  for (std::size_t i = 0; i < set.slices.size(); ++i)
    if (!dropped.count(i)) slices.push_back(std::move(set.slices[i]));
  set.slices = std::move(slices);
}

namespace {

// The octree has at most 2^11 cells a side: bounds more than 1000 times larger than the regions
// they hold leave every region inside a cell or two, and the surface comes out empty. Such
// bounds (1e308, or a box in metres around contours in mm) are an error, not an empty mesh.
constexpr double kMaxBoundsToRegionsRatio = 1000.0;

Status check_bounds_resolvable(const SliceSet& set, const std::string& source_name) {
  if (!set.bounds) return Status::ok();
  Box3 seen{Vec3::Constant(std::numeric_limits<double>::infinity()),
            Vec3::Constant(-std::numeric_limits<double>::infinity())};
  for (const LabeledSlice& s : set.slices)
    for (const Region& r : s.regions)
      for (const Vec2& p : r.outer) {
        const Vec3 w = s.to_world(p);
        seen.min = seen.min.cwiseMin(w);
        seen.max = seen.max.cwiseMax(w);
      }
  if (!seen.min.allFinite()) return Status::ok();  // no regions: nothing to resolve
  const double regions_side = (seen.max - seen.min).maxCoeff();
  const double bounds_side = (set.bounds->max - set.bounds->min).maxCoeff();
  if (std::isfinite(bounds_side) && bounds_side <= kMaxBoundsToRegionsRatio * regions_side)
    return Status::ok();
  return Status::error(
      source_name + ": bounds: the box (largest side " + format_double(bounds_side) +
      ") is more than " + format_double(kMaxBoundsToRegionsRatio) +
      " times the extent of the regions (" + format_double(regions_side) +
      "), finer than the octree can resolve, so the surface would be empty; give bounds "
      "that fit the regions (check the units), or leave bounds out");
}

}  // namespace

Result<SliceSet> finish_parsed_set(SliceSet set, const std::string& source_name,
                                   const SliceNaming& naming, RepairLog& repairs) {
  // Rounding slivers are snapped once the set is otherwise valid (the snap needs valid
  // polygons), then the set is validated again: a snap moves vertices that a third region may
  // share, so a few rounds may be needed. What remains is an error.
  constexpr int kSnapRounds = 3;
  SlicePairs identical;
  RegionPairs thin;
  Status status = validate_slice_set_named(set, source_name, naming, &identical, &thin);
  for (int round = 0; status && !thin.empty(); ++round) {
    try {
      snap_rounding_overlaps(set, thin, naming, repairs);
    } catch (const InputError& refused) {  // a repair refused under strict: names its file
      return Status::error(refused.what());
    }
    identical.clear();
    thin.clear();
    status = validate_slice_set_named(set, source_name, naming, &identical,
                                      round + 1 < kSnapRounds ? &thin : nullptr);
  }
  if (!status) return status;
  if (Status resolvable = check_bounds_resolvable(set, source_name); !resolvable) return resolvable;
  try {
    merge_identical_slices(set, identical, naming, repairs);
  } catch (const InputError& refused) {
    return Status::error(refused.what());
  }
  set.repairs = repairs.finish();
  return set;
}

}  // namespace sonoshape::detail

namespace sonoshape {

Status validate_slice_set(const SliceSet& set, const std::string& source_name) {
  return detail::validate_slice_set_named(set, source_name, detail::SliceNaming(), nullptr);
}

}  // namespace sonoshape
