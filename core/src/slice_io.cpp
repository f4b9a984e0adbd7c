// Slice-set JSON (docs/formats/slices.md), the validation shared by every reader, and the
// exact-predicate polygon checks behind it.
#include "sonoshape/core/slice_io.hpp"

#include <CGAL/Boolean_set_operations_2.h>
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_2.h>
#include <CGAL/Polygon_2_algorithms.h>
#include <CGAL/Polygon_with_holes_2.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <tuple>

#include "polygon_validity.hpp"
#include "slice_io_internal.hpp"
#include "sonoshape/core/input_file.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_compare.hpp"

namespace sonoshape {
namespace detail {

// ---------------------------------------------------------------------------------------------
// Small shared helpers

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

std::string label_text(int label) {
  return label == kUnknownLabel ? std::string("unknown") : std::to_string(label);
}

double ring_size(const Ring2& ring) {
  if (ring.size() < 2) return 0.0;
  Vec2 lo = ring.front();
  Vec2 hi = ring.front();
  for (const Vec2& p : ring) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).norm();
}

std::size_t drop_repeated_points(Ring2& ring) {
  // Non-finite rings are left for the validation to report, point by point.
  if (ring.size() < 2 ||
      !std::all_of(ring.begin(), ring.end(), [](const Vec2& p) { return p.allFinite(); }))
    return 0;
  const double tol = kRepeatedPointRelTol * ring_size(ring);
  Ring2 kept;
  kept.reserve(ring.size());
  for (const Vec2& p : ring)
    if (kept.empty() || (p - kept.back()).norm() > tol) kept.push_back(p);
  while (kept.size() > 1 && (kept.back() - kept.front()).norm() <= tol) kept.pop_back();
  const std::size_t dropped = ring.size() - kept.size();
  ring = std::move(kept);
  return dropped;
}

std::string format_double(double value) {
  std::array<char, 64> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  if (ec != std::errc()) return "0";
  return std::string(buffer.data(), end);
}

std::string format_short(double value) {
  std::array<char, 64> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value,
                                       std::chars_format::general, 7);
  if (ec != std::errc()) return "0";
  return std::string(buffer.data(), end);
}

Result<std::string> read_text_file(const std::filesystem::path& path) {
  return read_input_file(path, "slice set");
}

Status write_text_file(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out)
    return Status::error("cannot write " + path.string() + ": " + std::strerror(errno) +
                         "; check that the folder exists and is writable");
  out << text;
  out.flush();
  // errno says which limit it was: ENOSPC (a full disk) or EFBIG (ulimit -f).
  if (!out)
    return Status::error("cannot write " + path.string() + ": " + std::strerror(errno) +
                         "; free disk space or raise the file-size limit, then run again");
  return Status::ok();
}

// ---------------------------------------------------------------------------------------------
// Polygon checks (exact predicates)

namespace {

using IK = CGAL::Exact_predicates_inexact_constructions_kernel;
using EK = CGAL::Exact_predicates_exact_constructions_kernel;
using ExactPolygon = CGAL::Polygon_2<EK>;
using ExactPolygonWithHoles = CGAL::Polygon_with_holes_2<EK>;

std::vector<IK::Point_2> to_points(const Ring2& ring) {
  std::vector<IK::Point_2> points;
  points.reserve(ring.size());
  for (const Vec2& p : ring) points.emplace_back(p.x(), p.y());
  return points;
}

// Closed 2D box of one ring, for cheap rejection before the exact tests.
struct Box2 {
  Vec2 lo;
  Vec2 hi;
  // Interiors overlap: boxes that merely touch cannot hold overlapping polygons.
  bool interiors_overlap(const Box2& other) const {
    return lo.x() < other.hi.x() && other.lo.x() < hi.x() && lo.y() < other.hi.y() &&
           other.lo.y() < hi.y();
  }
  // Closed boxes meet: boxes that touch can hold polygons that touch.
  bool meets(const Box2& other) const {
    return lo.x() <= other.hi.x() && other.lo.x() <= hi.x() && lo.y() <= other.hi.y() &&
           other.lo.y() <= hi.y();
  }
};

Box2 box_of(const Ring2& ring) {
  Box2 box{ring.front(), ring.front()};
  for (const Vec2& p : ring) {
    box.lo = box.lo.cwiseMin(p);
    box.hi = box.hi.cwiseMax(p);
  }
  return box;
}

// Finds two edges of a non-simple ring that intersect other than at their shared corner.
// Edge k runs from point k to point k+1. A sweep over x keeps it near-linear for real contours.
std::optional<std::pair<std::size_t, std::size_t>> find_crossing_edges(
    const std::vector<IK::Point_2>& pts) {
  const std::size_t n = pts.size();
  std::vector<IK::Segment_2> edges;
  edges.reserve(n);
  for (std::size_t k = 0; k < n; ++k) edges.emplace_back(pts[k], pts[(k + 1) % n]);
  std::vector<std::size_t> order(n);
  for (std::size_t k = 0; k < n; ++k) order[k] = k;
  auto min_x = [&](std::size_t k) {
    return std::min(edges[k].source().x(), edges[k].target().x());
  };
  auto max_x = [&](std::size_t k) {
    return std::max(edges[k].source().x(), edges[k].target().x());
  };
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return min_x(a) < min_x(b); });
  for (std::size_t oi = 0; oi < n; ++oi) {
    const std::size_t i = order[oi];
    for (std::size_t oj = oi + 1; oj < n && min_x(order[oj]) <= max_x(i); ++oj) {
      const std::size_t j = order[oj];
      const bool i_then_j = j == (i + 1) % n;
      const bool j_then_i = i == (j + 1) % n;
      bool bad = false;
      if (i_then_j || j_then_i) {
        // Adjacent edges a->b->c overlap only when they fold back along one line.
        const std::size_t first = i_then_j ? i : j;
        const IK::Point_2& a = pts[first];
        const IK::Point_2& b = pts[(first + 1) % n];
        const IK::Point_2& c = pts[(first + 2) % n];
        bad = CGAL::collinear(a, b, c) && !CGAL::collinear_are_ordered_along_line(a, b, c);
      } else {
        bad = CGAL::do_intersect(edges[i], edges[j]);
      }
      if (bad) return std::make_pair(std::min(i, j), std::max(i, j));
    }
  }
  return std::nullopt;
}

// A point shared by edges i and j (i < j) that find_crossing_edges reported.
Vec2 crossing_point(const std::vector<IK::Point_2>& pts, std::size_t i, std::size_t j) {
  const std::size_t n = pts.size();
  if (j == i + 1) return Vec2(pts[j].x(), pts[j].y());  // folding back at their shared corner
  if (i == 0 && j == n - 1) return Vec2(pts[0].x(), pts[0].y());
  const IK::Segment_2 a(pts[i], pts[(i + 1) % n]);
  const IK::Segment_2 b(pts[j], pts[(j + 1) % n]);
  const auto hit = CGAL::intersection(a, b);
  if (hit) {
    if (const IK::Point_2* p = boost::get<IK::Point_2>(&*hit)) return Vec2(p->x(), p->y());
    if (const IK::Segment_2* s = boost::get<IK::Segment_2>(&*hit))
      return Vec2(s->source().x(), s->source().y());
  }
  return Vec2(pts[j].x(), pts[j].y());
}

}  // namespace

RingCheck check_ring(const Ring2& ring) {
  RingCheck check;
  for (std::size_t k = 0; k < ring.size(); ++k)
    if (!ring[k].allFinite()) {
      check.problem =
          "point " + std::to_string(k) + " is not a finite number; write finite coordinates";
      return check;
    }
  std::set<std::pair<double, double>> distinct;
  for (const Vec2& p : ring) distinct.insert({p.x(), p.y()});
  if (distinct.size() < 3) {
    check.problem = "polygon has fewer than 3 distinct points (" + std::to_string(distinct.size()) +
                    "); a region needs at least 3 corners, remove it or complete it";
    return check;
  }
  const std::vector<IK::Point_2> pts = to_points(ring);
  std::size_t second = 1;
  while (second < pts.size() && pts[second] == pts[0]) ++second;
  bool all_collinear = true;
  for (std::size_t k = second + 1; k < pts.size() && all_collinear; ++k)
    all_collinear = CGAL::collinear(pts[0], pts[second], pts[k]);
  if (all_collinear) {
    check.problem =
        "polygon has zero area (all its points lie on one line); remove it or fix its points";
    return check;
  }
  if (!CGAL::is_simple_2(pts.begin(), pts.end(), IK())) {
    const auto edges = find_crossing_edges(pts);
    const std::string which = edges ? " (edges " + std::to_string(edges->first) + " and " +
                                          std::to_string(edges->second) + " cross)"
                                    : "";
    check.problem =
        "polygon self-intersects" + which + "; fix the contour or split it into separate regions";
    check.self_intersects = true;
    if (edges) check.crossing = crossing_point(pts, edges->first, edges->second);
    return check;
  }
  const double size = ring_size(ring);
  if (std::abs(signed_area(ring)) <= 1e-12 * size * size)
    check.problem = "polygon has zero area; remove it or fix its points";
  return check;
}

std::string ring_problem(const Ring2& ring) { return check_ring(ring).problem; }

namespace {

ExactPolygon to_exact(const Ring2& ring, CGAL::Orientation wanted) {
  ExactPolygon polygon;
  for (const Vec2& p : ring) polygon.push_back(EK::Point_2(p.x(), p.y()));
  if (polygon.orientation() != wanted) polygon.reverse_orientation();
  return polygon;
}

bool exact_inside(const ExactPolygon& inner_ccw, const ExactPolygon& outer_ccw) {
  std::vector<ExactPolygonWithHoles> rest;
  CGAL::difference(inner_ccw, outer_ccw, std::back_inserter(rest));
  return rest.empty();
}

// The boundary of a region as exact-predicate points and segments, for the cheap overlap tests.
using Segments = std::vector<IK::Segment_2>;
using Points = std::vector<IK::Point_2>;

struct RegionRings {
  Points outer;
  std::vector<Points> holes;
  Segments segments;  // outer and holes together
};

void add_segments(const Points& ring, Segments& out) {
  for (std::size_t k = 0; k < ring.size(); ++k)
    out.emplace_back(ring[k], ring[(k + 1) % ring.size()]);
}

Segments segments_of(const Points& ring) {
  Segments out;
  add_segments(ring, out);
  return out;
}

// Whether a segment of `a` meets a segment of `b` (exact predicates; a sweep over x).
bool boundaries_meet(const Segments& a, const Segments& b) {
  struct Item {
    double lo_x, hi_x, lo_y, hi_y;
    const IK::Segment_2* segment;
    bool from_a;
  };
  std::vector<Item> items;
  items.reserve(a.size() + b.size());
  auto add = [&](const Segments& segments, bool from_a) {
    for (const IK::Segment_2& s : segments) {
      const CGAL::Bbox_2 box = s.bbox();
      items.push_back({box.xmin(), box.xmax(), box.ymin(), box.ymax(), &s, from_a});
    }
  };
  add(a, true);
  add(b, false);
  std::sort(items.begin(), items.end(),
            [](const Item& p, const Item& q) { return p.lo_x < q.lo_x; });
  for (std::size_t i = 0; i < items.size(); ++i)
    for (std::size_t j = i + 1; j < items.size() && items[j].lo_x <= items[i].hi_x; ++j)
      if (items[i].from_a != items[j].from_a && items[j].lo_y <= items[i].hi_y &&
          items[i].lo_y <= items[j].hi_y &&
          CGAL::do_intersect(*items[i].segment, *items[j].segment))
        return true;
  return false;
}

bool strictly_inside(const IK::Point_2& p, const Points& ring) {
  return CGAL::bounded_side_2(ring.begin(), ring.end(), p, IK()) == CGAL::ON_BOUNDED_SIDE;
}

bool in_interior(const IK::Point_2& p, const RegionRings& region) {
  if (!strictly_inside(p, region.outer)) return false;
  return std::none_of(region.holes.begin(), region.holes.end(),
                      [&](const Points& hole) { return strictly_inside(p, hole); });
}

// Interiors of two regions whose boundaries do not meet overlap exactly when a boundary curve of
// one lies inside the other; each curve lies wholly inside or outside, so one vertex tells.
bool disjoint_boundaries_overlap(const RegionRings& a, const RegionRings& b) {
  auto any_ring_inside = [](const RegionRings& x, const RegionRings& y) {
    if (in_interior(x.outer.front(), y)) return true;
    return std::any_of(x.holes.begin(), x.holes.end(),
                       [&](const Points& hole) { return in_interior(hole.front(), y); });
  };
  return any_ring_inside(a, b) || any_ring_inside(b, a);
}

ExactPolygonWithHoles to_exact(const Ring2& outer, const std::vector<Ring2>& holes) {
  std::vector<ExactPolygon> holes_cw;
  for (const Ring2& hole : holes) holes_cw.push_back(to_exact(hole, CGAL::CLOCKWISE));
  return ExactPolygonWithHoles(to_exact(outer, CGAL::COUNTERCLOCKWISE), holes_cw.begin(),
                               holes_cw.end());
}

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

}  // namespace

bool ring_inside_ring(const Ring2& inner, const Ring2& outer) {
  const std::vector<IK::Point_2> outer_pts = to_points(outer);
  for (const Vec2& p : inner) {
    const CGAL::Bounded_side side =
        CGAL::bounded_side_2(outer_pts.begin(), outer_pts.end(), IK::Point_2(p.x(), p.y()), IK());
    if (side == CGAL::ON_BOUNDED_SIDE) return true;
    if (side == CGAL::ON_UNBOUNDED_SIDE) return false;
  }
  // Every vertex on the boundary: a ring in a pocket of `outer` whose corners it touches, or the
  // same ring. Only the exact difference tells.
  return exact_inside(to_exact(inner, CGAL::COUNTERCLOCKWISE),
                      to_exact(outer, CGAL::COUNTERCLOCKWISE));
}

// ---------------------------------------------------------------------------------------------
// Region overlaps: measured on the exact intersection; thin ones (rounding) snapped by readers

namespace {

// The overlap of two regions of one slice.
struct OverlapMeasure {
  double area = 0.0;   // all components together, in the file's units squared
  double width = 0.0;  // the widest component's 2·area/perimeter: the thickness of a sliver
  Vec2 location = Vec2::Zero();          // a point inside the largest component (slice coordinates)
  Box2 box{Vec2::Zero(), Vec2::Zero()};  // box of every component
};

double exact_ring_length(const ExactPolygon& ring) {
  double length = 0.0;
  for (auto e = ring.edges_begin(); e != ring.edges_end(); ++e)
    length += std::sqrt(CGAL::to_double(e->squared_length()));
  return length;
}

// A point strictly inside a polygon with holes (O'Rourke, Computational Geometry in C, 1.6): at
// the outer ring's leftmost vertex v (convex) with neighbours a and b, the centroid of triangle
// a-v-b is inside unless vertices lie in that triangle; then the midpoint of v and the one of
// them farthest from line ab is. A centroid would miss a thin curved sliver.
EK::Point_2 point_inside(const ExactPolygonWithHoles& polygon) {
  const ExactPolygon& outer = polygon.outer_boundary();
  const auto v_it = outer.left_vertex();
  const auto a_it =
      v_it == outer.vertices_begin() ? std::prev(outer.vertices_end()) : std::prev(v_it);
  const auto b_it =
      std::next(v_it) == outer.vertices_end() ? outer.vertices_begin() : std::next(v_it);
  const EK::Point_2 &v = *v_it, &a = *a_it, &b = *b_it;
  if (CGAL::collinear(a, v, b)) return v;  // not a simple polygon; the vertex still locates it
  const EK::Triangle_2 ear(a, v, b);
  const EK::Line_2 base(a, b);
  std::optional<EK::Point_2> deepest;
  auto consider = [&](const ExactPolygon& ring) {
    for (auto p = ring.vertices_begin(); p != ring.vertices_end(); ++p)
      if (ear.has_on_bounded_side(*p) &&
          (!deepest || CGAL::squared_distance(base, *p) > CGAL::squared_distance(base, *deepest)))
        deepest = *p;
  };
  consider(outer);
  for (auto h = polygon.holes_begin(); h != polygon.holes_end(); ++h) consider(*h);
  return deepest ? CGAL::midpoint(v, *deepest) : CGAL::centroid(ear);
}

// The exact intersection of two regions (valid rings); nullopt when their interiors are
// disjoint (shared edges and touching corners are not overlaps).
std::optional<OverlapMeasure> measure_overlap(const ExactPolygonWithHoles& a,
                                              const ExactPolygonWithHoles& b) {
  std::vector<ExactPolygonWithHoles> parts;
  // Tag_false: the segment traits, whose precondition valid_for_boolean_ops checks (the default
  // polyline traits reject, and crash on, holes that meet in corners).
  CGAL::intersection(a, b, std::back_inserter(parts), CGAL::Tag_false());
  if (parts.empty()) return std::nullopt;
  OverlapMeasure overlap;
  double largest = -1.0;
  bool first = true;
  for (const ExactPolygonWithHoles& part : parts) {
    double area = std::abs(CGAL::to_double(part.outer_boundary().area()));
    double perimeter = exact_ring_length(part.outer_boundary());
    for (auto h = part.holes_begin(); h != part.holes_end(); ++h) {
      area -= std::abs(CGAL::to_double(h->area()));
      perimeter += exact_ring_length(*h);
    }
    overlap.area += area;
    if (perimeter > 0.0) overlap.width = std::max(overlap.width, 2.0 * area / perimeter);
    if (area > largest) {
      largest = area;
      const EK::Point_2 inside = point_inside(part);
      overlap.location = Vec2(CGAL::to_double(inside.x()), CGAL::to_double(inside.y()));
    }
    const CGAL::Bbox_2 box = part.outer_boundary().bbox();
    const Box2 part_box{Vec2(box.xmin(), box.ymin()), Vec2(box.xmax(), box.ymax())};
    overlap.box =
        first ? part_box
              : Box2{overlap.box.lo.cwiseMin(part_box.lo), overlap.box.hi.cwiseMax(part_box.hi)};
    first = false;
  }
  return overlap;
}

// Bounding-box diagonal of a slice's regions: the scale of its rounding tolerance.
double slice_extent(const LabeledSlice& slice) {
  Vec2 lo = Vec2::Constant(std::numeric_limits<double>::infinity());
  Vec2 hi = -lo;
  for (const Region& r : slice.regions)
    for (const Vec2& p : r.outer) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  return slice.regions.empty() ? 0.0 : (hi - lo).norm();
}

std::string overlap_text(const LabeledSlice& slice, const OverlapMeasure& overlap,
                         const std::string& units) {
  // Seven digits find the spot; the shortest round-trip form of a sliver's point would be noise.
  std::ostringstream text;
  text.precision(3);
  text << overlap.area << " " << units << "² around (";
  text.precision(7);
  const Vec3 world = slice.to_world(overlap.location);
  text << overlap.location.x() << ", " << overlap.location.y() << "), world (" << world.x() << ", "
       << world.y() << ", " << world.z() << ")";
  return text.str();
}

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
std::size_t snap_to_vertices(Region& moving, Region& fixed, const Box2& zone, double tol) {
  std::vector<Vec2> targets;
  for (Ring2* ring : rings_of(fixed))
    for (const Vec2& p : *ring)
      if (in_box(p, zone)) targets.push_back(p);
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
  std::vector<Vec2> points;
  for (Ring2* ring : rings_of(source))
    for (const Vec2& q : *ring)
      if (in_box(q, zone)) points.push_back(q);
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

Status validate_slice_set_named(const SliceSet& set, const std::string& source_name,
                                const SliceNaming& naming, SlicePairs* identical,
                                RegionPairs* thin_overlaps) {
  std::vector<std::string> errors;
  auto fail = [&](const std::string& where, const std::string& what) {
    errors.push_back(source_name + ": " + where + ": " + what);
  };

  std::set<int> declared;
  for (const LabelInfo& label : set.labels) {
    if (label.id < 1)
      fail("labels", "id " + std::to_string(label.id) +
                         " is not a positive integer; material ids start at 1 (0 is the outside)");
    else if (!declared.insert(label.id).second)
      fail("labels",
           "id " + std::to_string(label.id) + " is declared twice; give each material one entry");
  }

  bool bounds_ok = false;
  if (set.bounds) {
    const Box3& b = *set.bounds;
    if (!b.min.allFinite() || !b.max.allFinite()) {
      fail("bounds", "min and max must be finite numbers");
    } else {
      bounds_ok = true;
      for (int k = 0; k < 3; ++k) {
        if (b.min[k] >= b.max[k]) {
          fail("bounds", "min[" + std::to_string(k) + "] = " + format_double(b.min[k]) +
                             " is not below max[" + std::to_string(k) + "] = " +
                             format_double(b.max[k]) + "; give a box with min < max on every axis");
          bounds_ok = false;
        }
      }
    }
  }

  std::vector<bool> basis_ok(set.slices.size(), false);
  for (std::size_t i = 0; i < set.slices.size(); ++i) {
    const LabeledSlice& s = set.slices[i];
    const std::string where = naming.slice(i);
    if (!s.origin_mm.allFinite() || !s.u.allFinite() || !s.v.allFinite()) {
      fail(where, "origin, u and v must be finite numbers");
    } else {
      const double u_len = s.u.norm();
      const double v_len = s.v.norm();
      const double u_dot_v = s.u.dot(s.v);
      const std::string hint =
          "; write unit orthogonal vectors, or add \"normalize\": true at the top level of the "
          "file to let the reader normalise them";
      if (std::abs(u_len - 1.0) > kBasisTol)
        fail(where, "u is not unit length (|u| = " + format_double(u_len) + ")" + hint);
      else if (std::abs(v_len - 1.0) > kBasisTol)
        fail(where, "v is not unit length (|v| = " + format_double(v_len) + ")" + hint);
      else if (std::abs(u_dot_v) > kBasisTol)
        fail(where, "u and v are not orthogonal (u.v = " + format_double(u_dot_v) + ")" + hint);
      else
        basis_ok[i] = true;
    }
    if (s.timestamp_s && !std::isfinite(*s.timestamp_s))
      fail(where, "timestamp is not a finite number");

    if (s.fov) {
      Ring2 fov = *s.fov;
      drop_repeated_points(fov);
      const std::string problem = ring_problem(fov);
      if (!problem.empty()) fail(where + ", fov", problem);
    }

    // Per region: label, rings, holes. Cleaned exact polygons feed the overlap test.
    bool regions_ok = true;
    struct CleanRegion {
      Ring2 outer;
      std::vector<Ring2> holes;
    };
    std::vector<CleanRegion> cleaned(s.regions.size());
    std::vector<RegionRings> region_rings(s.regions.size());
    std::vector<Box2> boxes(s.regions.size());
    for (std::size_t j = 0; j < s.regions.size(); ++j) {
      const Region& r = s.regions[j];
      const std::string region_where = where + ", " + naming.region(i, j, r.label);
      if (r.label == kOutsideLabel) {
        fail(region_where,
             "label 0 is the outside (the null material), which needs no region; remove the "
             "region or give it a material id");
      } else if (r.label < kOutsideLabel && r.label != kUnknownLabel) {
        fail(region_where, "label " + std::to_string(r.label) +
                               " is neither \"unknown\" nor a positive material id");
      } else if (r.label > 0 && !declared.empty() && !declared.count(r.label)) {
        fail(region_where, "label " + std::to_string(r.label) +
                               " is not declared in \"labels\" (declared: " + join_ids(declared) +
                               "); declare it or use a declared id");
      }

      Ring2 outer = r.outer;
      drop_repeated_points(outer);
      std::string problem = ring_problem(outer);
      if (!problem.empty()) {
        fail(naming.outer(i, j, r.label), problem);
        regions_ok = false;
        continue;
      }
      std::vector<Ring2> holes;
      bool holes_ok = true;
      for (std::size_t k = 0; k < r.holes.size(); ++k) {
        Ring2 hole = r.holes[k];
        drop_repeated_points(hole);
        problem = ring_problem(hole);
        if (!problem.empty()) {
          fail(naming.hole(i, j, r.label, k), problem);
          holes_ok = false;
        }
        holes.push_back(std::move(hole));
      }
      if (!holes_ok) {
        regions_ok = false;
        continue;
      }
      // Exact Boolean operations only where boundaries meet; disjoint ones need point tests.
      RegionRings& rings = region_rings[j];
      rings.outer = to_points(outer);
      add_segments(rings.outer, rings.segments);
      std::vector<Segments> hole_segments;
      for (const Ring2& hole : holes) {
        rings.holes.push_back(to_points(hole));
        hole_segments.push_back(segments_of(rings.holes.back()));
        add_segments(rings.holes.back(), rings.segments);
      }
      const Segments outer_segments = segments_of(rings.outer);
      bool boundaries_touch = false;  // a hole's boundary meets the outer ring's or another's
      for (std::size_t k = 0; k < holes.size(); ++k) {
        const bool meets_outer = boundaries_meet(hole_segments[k], outer_segments);
        boundaries_touch = boundaries_touch || meets_outer;
        const bool inside = meets_outer ? exact_inside(to_exact(holes[k], CGAL::COUNTERCLOCKWISE),
                                                       to_exact(outer, CGAL::COUNTERCLOCKWISE))
                                        : strictly_inside(rings.holes[k].front(), rings.outer);
        if (!inside) {
          fail(naming.hole(i, j, r.label, k),
               "hole is not inside the region's outer ring; a hole must lie within its polygon "
               "(touching the boundary is fine), fix it or make it a separate region");
          holes_ok = false;
        } else if (std::abs(signed_area(holes[k])) >= std::abs(signed_area(outer))) {
          // Inside and as large: the outer ring itself. Nothing is left of the region (and the
          // exact overlap test cannot take such a polygon).
          fail(naming.hole(i, j, r.label, k),
               "hole is the region's whole outer ring, so the region has no area; remove the "
               "region or the hole");
          holes_ok = false;
        }
      }
      std::vector<Box2> hole_boxes;
      for (const Ring2& hole : holes) hole_boxes.push_back(box_of(hole));
      for (std::size_t a = 0; a < holes.size(); ++a)
        for (std::size_t b = a + 1; b < holes.size(); ++b) {
          if (!hole_boxes[a].interiors_overlap(hole_boxes[b])) {
            // Boxes that touch: the holes may meet at a corner, which is no overlap.
            if (hole_boxes[a].meets(hole_boxes[b]))
              boundaries_touch =
                  boundaries_touch || boundaries_meet(hole_segments[a], hole_segments[b]);
            continue;
          }
          const bool overlap = boundaries_meet(hole_segments[a], hole_segments[b])
                                   ? CGAL::do_intersect(to_exact(holes[a], CGAL::COUNTERCLOCKWISE),
                                                        to_exact(holes[b], CGAL::COUNTERCLOCKWISE))
                                   : strictly_inside(rings.holes[a].front(), rings.holes[b]) ||
                                         strictly_inside(rings.holes[b].front(), rings.holes[a]);
          if (overlap) {
            fail(naming.hole(i, j, r.label, a),
                 "overlaps hole " + std::to_string(b) +
                     " of the same region; merge the two holes into one");
            holes_ok = false;
          }
        }
      if (!holes_ok) {
        regions_ok = false;
        continue;
      }
      // Holes inside and apart from each other make a valid polygon with holes; where their
      // boundaries touch, CGAL decides whether its overlap tests below (segment traits) can
      // take the region.
      if (boundaries_touch && !valid_for_boolean_ops(to_exact(outer, holes))) {
        fail(region_where,
             "its holes meet the outer ring or each other along an edge, or in corners that cut "
             "the region apart, so it is not a valid polygon with holes; a hole may touch the "
             "outer ring or another hole only at single corners: cut such a hole into the outer "
             "ring, or merge the holes");
        regions_ok = false;
        continue;
      }
      cleaned[j] = {std::move(outer), std::move(holes)};
      boxes[j] = box_of(cleaned[j].outer);
    }

    if (regions_ok) {
      for (std::size_t a = 0; a < s.regions.size(); ++a)
        for (std::size_t b = a + 1; b < s.regions.size(); ++b) {
          if (!boxes[a].interiors_overlap(boxes[b])) continue;
          const ExactPolygonWithHoles exact_a = to_exact(cleaned[a].outer, cleaned[a].holes);
          const ExactPolygonWithHoles exact_b = to_exact(cleaned[b].outer, cleaned[b].holes);
          const bool overlapping =
              boundaries_meet(region_rings[a].segments, region_rings[b].segments)
                  ? CGAL::do_intersect(exact_a, exact_b, CGAL::Tag_false())
                  : disjoint_boundaries_overlap(region_rings[a], region_rings[b]);
          // Measured only when there is something to report: the intersection costs more.
          const std::optional<OverlapMeasure> overlap =
              overlapping ? measure_overlap(exact_a, exact_b) : std::nullopt;
          if (!overlap) continue;
          const bool thin = overlap->width <= kRoundingOverlapRelTol * slice_extent(s);
          if (thin && thin_overlaps) {
            thin_overlaps->push_back({i, a, b});
            continue;
          }
          fail(where, naming.region(i, a, s.regions[a].label) + " and " +
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

    if (bounds_ok && basis_ok[i] && s.origin_mm.allFinite()) {
      const Box3& box = *set.bounds;
      const double tol = 1e-9 * box.diagonal();
      bool outside = !plane_meets_box(s, box, tol);
      if (!outside && !s.regions.empty()) {
        // Box of the region vertices in world coordinates: when it misses the bounds, so does
        // every region (a conservative test: it never rejects a slice that reaches the box).
        Box3 seen{Vec3::Constant(std::numeric_limits<double>::infinity()),
                  Vec3::Constant(-std::numeric_limits<double>::infinity())};
        for (const Region& r : s.regions)
          for (const Vec2& p : r.outer) {
            const Vec3 w = s.to_world(p);
            seen.min = seen.min.cwiseMin(w);
            seen.max = seen.max.cwiseMax(w);
          }
        outside = ((seen.max.array() < box.min.array() - tol).any() ||
                   (seen.min.array() > box.max.array() + tol).any());
      }
      if (outside)
        fail(where, "the slice lies entirely outside bounds (min " + vec_text(box.min) + ", max " +
                        vec_text(box.max) + "); check its origin and the units, or enlarge bounds");
    }
  }

  // Coincident slices: only once every slice is sound, since the test needs finite planes.
  if (errors.empty() && set.slices.size() > 1) {
    const double scale = std::max(1.0, set.effective_bounds().diagonal());
    const double offset_tol = kCoincidentTol * scale;
    std::vector<Vec3> normals;
    for (const LabeledSlice& s : set.slices) normals.push_back(s.normal().normalized());
    // A slice identical to an earlier one is compared with nothing else: what it would find, the
    // earlier one finds. 100 copies of a slice cost 99 comparisons, not 4950 (issue 40, C5).
    std::vector<bool> copy(set.slices.size(), false);
    for (std::size_t i = 0; i < set.slices.size(); ++i) {
      if (copy[i]) continue;
      for (std::size_t j = i + 1; j < set.slices.size(); ++j) {
        if (copy[j] || std::abs(normals[i].dot(normals[j])) < 1.0 - kCoincidentTol) continue;
        if (std::abs(normals[i].dot(set.slices[j].origin_mm - set.slices[i].origin_mm)) >
            offset_tol)
          continue;
        const std::string difference = content_difference(set.slices[i], set.slices[j], offset_tol);
        if (difference.empty()) {
          copy[j] = true;
          if (identical) identical->emplace_back(i, j);
        } else {
          fail(naming.slice(i) + " and " + naming.slice(j),
               "they lie in the same plane but their contents disagree (" + difference +
                   "); remove one of them or put all regions of that plane into one slice");
        }
      }
    }
  }

  if (errors.empty()) return Status::ok();
  std::string message;
  for (std::size_t k = 0; k < errors.size() && k < kMaxReportedErrors; ++k)
    message += (k ? "\n" : "") + errors[k];
  if (errors.size() > kMaxReportedErrors)
    message += "\n... and " + std::to_string(errors.size() - kMaxReportedErrors) + " more problems";
  return Status::error(message);
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
    } catch (const RepairRefused& refused) {
      return Status::error(refused.message);
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
  } catch (const RepairRefused& refused) {
    return Status::error(refused.message);
  }
  set.repairs = repairs.finish();
  return set;
}

void RepairLog::add(const std::string& slice_name, Repair repair) {
  if (strict_)
    throw RepairRefused{source_name_ + ": " + (repair.where.empty() ? "" : repair.where + ": ") +
                        repair.detail +
                        " (--strict refuses input that needs repairs; fix the file, or run "
                        "without --strict to accept the repair)"};
  repairs_.emplace_back(slice_name, std::move(repair));
}

std::vector<Repair> RepairLog::finish() {
  // One line per slice: a file with a pinched contour on every plane stays readable.
  std::vector<std::string> order;
  std::map<std::string, std::string> lines;
  for (const auto& [slice, repair] : repairs_) {
    auto [it, first] = lines.try_emplace(slice);
    if (first) order.push_back(slice);
    std::string item = repair.detail;
    if (!repair.where.empty() && repair.where != slice) {
      const std::string element = repair.where.rfind(slice + ", ", 0) == 0 && !slice.empty()
                                      ? repair.where.substr(slice.size() + 2)
                                      : repair.where;
      item = element + ": " + item;
    }
    it->second += (first ? "" : "; ") + item;
  }
  for (const std::string& slice : order)
    log_warning(source_name_ + ": " + (slice.empty() ? "" : slice + ": ") + lines[slice]);
  std::vector<Repair> records;
  records.reserve(repairs_.size());
  for (auto& entry : repairs_) records.push_back(std::move(entry.second));
  repairs_.clear();
  return records;
}

}  // namespace detail

Status validate_slice_set(const SliceSet& set, const std::string& source_name) {
  return detail::validate_slice_set_named(set, source_name, detail::SliceNaming(), nullptr);
}

// ---------------------------------------------------------------------------------------------
// JSON

namespace {

using nlohmann::json;

// Thrown inside the parser only; parse_slice_set_json turns it into a Status.
struct JsonProblem {
  std::string where;
  std::string what;
};

[[noreturn]] void fail_at(const std::string& where, const std::string& what) {
  throw JsonProblem{where, what};
}

std::string short_dump(const json& j) {
  std::string text = j.dump();
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  return text;
}

double read_number(const json& j, const std::string& where) {
  if (!j.is_number()) {
    const bool looks_special = j.is_string() || j.is_null();
    fail_at(where, "expected a number, got " + short_dump(j) +
                       (looks_special ? " (NaN and infinity are not allowed; write a finite number)"
                                      : ""));
  }
  const double value = j.get<double>();
  if (!std::isfinite(value)) fail_at(where, "number is not finite; write a finite number");
  return value;
}

// Lengths beyond 1e12 mm (1000 km) are no anatomy: their squares in the geometry overflow and
// the polygon then reads as "fewer than 3 distinct points", which blames the wrong thing.
constexpr double kMaxCoordinateMm = 1e12;

double read_coordinate(const json& j, const std::string& where) {
  const double value = read_number(j, where);
  if (std::abs(value) > kMaxCoordinateMm)
    fail_at(where, "coordinate " + short_dump(j) +
                       " is beyond 1e12 mm, where lengths lose their precision; check the units");
  return value;
}

Vec3 read_vec3(const json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3) fail_at(where, "expected [x, y, z], got " + short_dump(j));
  return Vec3(read_number(j[0], where), read_number(j[1], where), read_number(j[2], where));
}

Ring2 read_ring(const json& j, const std::string& where) {
  if (!j.is_array()) fail_at(where, "expected an array of [x, y] points, got " + short_dump(j));
  Ring2 ring;
  ring.reserve(j.size());
  for (std::size_t k = 0; k < j.size(); ++k) {
    const std::string point_where = where + ", point " + std::to_string(k);
    const json& p = j[k];
    if (!p.is_array() || p.size() != 2)
      fail_at(point_where, "expected [x, y], got " + short_dump(p));
    ring.emplace_back(read_coordinate(p[0], point_where), read_coordinate(p[1], point_where));
  }
  return ring;
}

void warn_unknown_keys(const json& object, std::initializer_list<const char*> known,
                       const std::string& source_name, const std::string& where,
                       const std::vector<std::string>& also_known = {}) {
  for (const auto& item : object.items()) {
    const bool is_known =
        std::any_of(known.begin(), known.end(), [&](const char* k) { return item.key() == k; }) ||
        std::find(also_known.begin(), also_known.end(), item.key()) != also_known.end();
    if (!is_known)
      log_warning(source_name + ": " + where + ": ignoring unknown key \"" + item.key() + "\"");
  }
}

// Drops repeated consecutive points, recording a repair of the ring `where` names.
void clean_ring(Ring2& ring, const std::string& slice_name, const std::string& where,
                detail::RepairLog& repairs) {
  const std::size_t dropped = detail::drop_repeated_points(ring);
  if (dropped)
    repairs.add(slice_name, {"repeated_points", where,
                             "dropped " + std::to_string(dropped) + " repeated consecutive point" +
                                 (dropped > 1 ? "s" : ""),
                             0.0});
}

std::string plane_point_text(const Vec2& p) {
  return "[" + detail::format_short(p.x()) + ", " + detail::format_short(p.y()) + "]";
}

// Whether a ring lies inside an outer ring: boxes first, then exact predicates.
bool inside_outer(const Ring2& ring, const Ring2& outer) {
  Vec2 olo = outer.front();
  Vec2 ohi = outer.front();
  for (const Vec2& p : outer) {
    olo = olo.cwiseMin(p);
    ohi = ohi.cwiseMax(p);
  }
  for (const Vec2& p : ring)
    if ((p.array() < olo.array()).any() || (p.array() > ohi.array()).any()) return false;
  return detail::ring_inside_ring(ring, outer);
}

// The regions a hole ring that crossed itself leaves: its outer boundaries are cut out of the
// region, and islands inside them (odd depth) are the region's material again.
void add_repaired_hole(const detail::ContourRepair& fixed, int label, std::vector<Ring2>& cut,
                       std::vector<Region>& islands) {
  std::vector<std::size_t> island_of(fixed.rings.size(), 0);
  for (std::size_t k = 0; k < fixed.rings.size(); ++k) {
    const detail::NestedRing& nested = fixed.rings[k];
    if (nested.depth == 0) {
      cut.push_back(nested.ring);
    } else if (nested.depth % 2 == 1) {
      island_of[k] = islands.size();
      islands.push_back(Region{label, nested.ring, {}});
    } else {
      islands[island_of[nested.parent]].holes.push_back(nested.ring);
    }
  }
}

// A region whose outer ring or holes cross themselves becomes the regions they enclose by the
// non-zero rule (detail::repair_contour): the first takes the region's place in the slice, the
// others follow the slice's regions. Rings that do not cross themselves are kept as written.
std::vector<Region> repair_region(Region r, std::size_t i, std::size_t j,
                                  const detail::SliceNaming& naming, detail::RepairLog& repairs) {
  const detail::RingCheck outer_check = detail::check_ring(r.outer);
  std::vector<detail::RingCheck> hole_checks;
  for (const Ring2& hole : r.holes) hole_checks.push_back(detail::check_ring(hole));
  if (!outer_check.self_intersects &&
      std::none_of(hole_checks.begin(), hole_checks.end(),
                   [](const detail::RingCheck& c) { return c.self_intersects; }))
    return {std::move(r)};

  const std::string slice_name = naming.slice(i);
  std::vector<Region> out;
  if (outer_check.self_intersects) {
    const detail::ContourRepair fixed = detail::repair_contour(r.outer);
    repairs.add(slice_name, detail::self_intersection_repair(naming.outer(i, j, r.label),
                                                             plane_point_text(outer_check.crossing),
                                                             fixed, false));
    std::vector<std::size_t> region_of(fixed.rings.size(), 0);
    for (std::size_t k = 0; k < fixed.rings.size(); ++k) {
      const detail::NestedRing& nested = fixed.rings[k];
      if (nested.depth % 2 == 0) {
        region_of[k] = out.size();
        out.push_back(Region{r.label, nested.ring, {}});
      } else {
        out[region_of[nested.parent]].holes.push_back(nested.ring);
      }
    }
    if (out.empty()) return out;  // the outer ring encloses nothing: so does the region
  } else {
    out.push_back(Region{r.label, r.outer, {}});
  }
  std::vector<Region> islands;
  for (std::size_t k = 0; k < r.holes.size(); ++k) {
    std::vector<Ring2> cut;
    if (hole_checks[k].self_intersects) {
      const detail::ContourRepair fixed = detail::repair_contour(r.holes[k]);
      repairs.add(slice_name, detail::self_intersection_repair(
                                  naming.hole(i, j, r.label, k),
                                  plane_point_text(hole_checks[k].crossing), fixed, true));
      add_repaired_hole(fixed, r.label, cut, islands);
    } else {
      cut.push_back(r.holes[k]);
    }
    // A hole belongs to the part of the repaired outer ring that holds it; when none does, the
    // first part keeps it and the validation reports a hole outside its region.
    for (Ring2& ring : cut) {
      std::size_t owner = 0;
      for (std::size_t m = 0; m < out.size() && out.size() > 1; ++m)
        if (inside_outer(ring, out[m].outer)) {
          owner = m;
          break;
        }
      out[owner].holes.push_back(std::move(ring));
    }
  }
  for (Region& island : islands) out.push_back(std::move(island));
  return out;
}

// A fov that crosses itself is repaired when what it encloses is one polygon; a fov cannot hold
// several polygons or holes.
void repair_fov(Ring2& ring, const std::string& where, detail::RepairLog& repairs) {
  const detail::RingCheck check = detail::check_ring(ring);
  if (!check.self_intersects) return;
  const detail::ContourRepair fixed = detail::repair_contour(ring);
  if (fixed.rings.size() != 1)
    fail_at(where + ", fov", check.problem + "; by the non-zero rule it encloses " +
                                 std::to_string(fixed.polygons()) + " polygons and " +
                                 std::to_string(fixed.rings.size() - fixed.polygons()) +
                                 " holes, but a fov must be one polygon");
  repairs.add(where, detail::self_intersection_repair(
                         where + ", fov", plane_point_text(check.crossing), fixed, false));
  ring = fixed.rings.front().ring;
}

int read_label(const json& j, const std::string& where) {
  if (j.is_string() && j.get<std::string>() == "unknown") return kUnknownLabel;
  if (j.is_number_integer()) {
    const auto value = j.get<long long>();
    if (value >= 1 && value <= INT_MAX) return static_cast<int>(value);
  }
  fail_at(where, "label " + short_dump(j) +
                     " is neither \"unknown\" nor a positive integer id (0 is the outside and "
                     "needs no region)");
}

// One element of "slices"; `i` names it in messages. Keys in `also_known` pass without a warning.
LabeledSlice parse_slice_object(const json& js, std::size_t i, bool normalize,
                                const std::string& source_name, const detail::SliceNaming& naming,
                                detail::RepairLog& repairs,
                                const std::vector<std::string>& also_known = {}) {
  const std::string where = naming.slice(i);
  if (!js.is_object()) fail_at(where, "expected a slice object");
  warn_unknown_keys(js, {"origin", "u", "v", "timestamp", "fov", "regions"}, source_name, where,
                    also_known);
  for (const char* key : {"origin", "u", "v"})
    if (!js.contains(key)) fail_at(where, std::string("\"") + key + "\" is missing");
  LabeledSlice s;
  s.origin_mm = read_vec3(js["origin"], where + ", origin");
  if (s.origin_mm.cwiseAbs().maxCoeff() > kMaxCoordinateMm)
    fail_at(where + ", origin",
            "a coordinate beyond 1e12 mm, where lengths lose their precision; check the units");
  s.u = read_vec3(js["u"], where + ", u");
  s.v = read_vec3(js["v"], where + ", v");
  if (normalize) {
    // Gram-Schmidt: keep u's direction, make v orthogonal to it.
    const double u_len = s.u.norm();
    const Vec3 v_ortho = u_len > 0.0 ? Vec3(s.v - s.v.dot(s.u / u_len) * (s.u / u_len)) : s.v;
    if (u_len <= 1e-12 || v_ortho.norm() <= 1e-6 * s.v.norm() || s.v.norm() <= 1e-12)
      fail_at(where,
              "u and v do not span a plane (one is zero or they are parallel); fix the "
              "direction vectors");
    s.u /= u_len;
    s.v = v_ortho.normalized();
  }
  if (const auto t = js.find("timestamp"); t != js.end() && !t->is_null())
    s.timestamp_s = read_number(*t, where + ", timestamp");
  if (const auto fov = js.find("fov"); fov != js.end() && !fov->is_null()) {
    Ring2 ring = read_ring(*fov, where + ", fov");
    clean_ring(ring, where, where + ", fov", repairs);
    repair_fov(ring, where, repairs);
    s.fov = std::move(ring);
  }
  if (const auto regions = js.find("regions"); regions != js.end()) {
    if (!regions->is_array()) fail_at(where, "\"regions\" must be an array of region objects");
    std::vector<Region> parts;  // more regions from repaired ones: they follow the others
    for (std::size_t j = 0; j < regions->size(); ++j) {
      const json& jr = (*regions)[j];
      const std::string region_where = where + ", region " + std::to_string(j);
      if (!jr.is_object()) fail_at(region_where, "expected a region object");
      if (!jr.contains("label")) fail_at(region_where, "\"label\" is missing");
      if (!jr.contains("polygon")) fail_at(region_where, "\"polygon\" is missing");
      Region r;
      r.label = read_label(jr["label"], region_where);
      warn_unknown_keys(jr, {"label", "polygon", "holes"}, source_name, region_where);
      r.outer = read_ring(jr["polygon"], naming.outer(i, j, r.label));
      clean_ring(r.outer, where, naming.outer(i, j, r.label), repairs);
      if (const auto holes = jr.find("holes"); holes != jr.end()) {
        if (!holes->is_array()) fail_at(region_where, "\"holes\" must be an array of polygons");
        for (std::size_t k = 0; k < holes->size(); ++k) {
          const std::string hole_where = naming.hole(i, j, r.label, k);
          Ring2 hole = read_ring((*holes)[k], hole_where);
          clean_ring(hole, where, hole_where, repairs);
          r.holes.push_back(std::move(hole));
        }
      }
      std::vector<Region> repaired = repair_region(std::move(r), i, j, naming, repairs);
      for (std::size_t k = 0; k < repaired.size(); ++k)
        (k == 0 ? s.regions : parts).push_back(std::move(repaired[k]));
    }
    for (Region& part : parts) s.regions.push_back(std::move(part));
  }
  return s;
}

SliceSet parse_document(const json& doc, const std::string& source_name,
                        detail::RepairLog& repairs) {
  if (!doc.is_object())
    fail_at("document",
            "not a slice set: expected a JSON object with \"format\": "
            "\"sonoshape-slices\"");
  const auto format = doc.find("format");
  if (format == doc.end() || !format->is_string() || *format != "sonoshape-slices")
    fail_at("format", std::string("\"format\" is ") +
                          (format == doc.end() ? "missing" : short_dump(*format)) +
                          ", not \"sonoshape-slices\"; this is not a sonoshape slice-set file "
                          "(contour files need the .csl extension)");
  const auto version = doc.find("version");
  if (version == doc.end()) fail_at("version", "\"version\" is missing; write \"version\": 1");
  if (!version->is_number_integer() || version->get<long long>() != 1)
    fail_at("version",
            "unknown version " + short_dump(*version) +
                "; this sonoshape reads version 1, a newer file needs a newer sonoshape");
  warn_unknown_keys(doc, {"format", "version", "units", "labels", "bounds", "slices", "normalize"},
                    source_name, "top level");

  SliceSet set;
  if (const auto units = doc.find("units"); units != doc.end()) {
    if (!units->is_string()) fail_at("units", "expected a string such as \"mm\"");
    // Every length in sonoshape is millimetres; a file in another unit read as mm would give a
    // surface 1000 times too small or large without a word, so it is refused instead.
    if (units->get<std::string>() != "mm")
      fail_at("units", short_dump(*units) +
                           " is not supported: sonoshape reads lengths in millimetres only; "
                           "convert the file's lengths to mm and write \"units\": \"mm\"");
    set.units = units->get<std::string>();
  }
  bool normalize = false;
  if (const auto n = doc.find("normalize"); n != doc.end()) {
    if (!n->is_boolean()) fail_at("normalize", "expected true or false");
    normalize = n->get<bool>();
  }

  if (const auto labels = doc.find("labels"); labels != doc.end()) {
    if (!labels->is_array()) fail_at("labels", "expected an array of {\"id\", \"name\"} objects");
    for (std::size_t k = 0; k < labels->size(); ++k) {
      const json& entry = (*labels)[k];
      const std::string where = "labels, entry " + std::to_string(k);
      if (!entry.is_object()) fail_at(where, "expected {\"id\": <int>, \"name\": <text>}");
      LabelInfo info;
      const auto id = entry.find("id");
      if (id == entry.end() || !id->is_number_integer() || id->get<long long>() < 1 ||
          id->get<long long>() > INT_MAX)
        fail_at(where, "\"id\" must be a positive integer (material ids start at 1)");
      info.id = static_cast<int>(id->get<long long>());
      if (const auto name = entry.find("name"); name != entry.end()) {
        if (!name->is_string()) fail_at(where, "\"name\" must be a string");
        info.name = name->get<std::string>();
      }
      set.labels.push_back(std::move(info));
    }
  }

  if (const auto bounds = doc.find("bounds"); bounds != doc.end()) {
    if (!bounds->is_object() || !bounds->contains("min") || !bounds->contains("max"))
      fail_at("bounds", "expected {\"min\": [x, y, z], \"max\": [x, y, z]}");
    set.bounds = Box3{read_vec3((*bounds)["min"], "bounds, min"),
                      read_vec3((*bounds)["max"], "bounds, max")};
  }

  const auto slices = doc.find("slices");
  if (slices == doc.end() || !slices->is_array())
    fail_at("slices", "\"slices\" must be an array of slice objects");
  const detail::SliceNaming naming;
  for (std::size_t i = 0; i < slices->size(); ++i)
    set.slices.push_back(
        parse_slice_object((*slices)[i], i, normalize, source_name, naming, repairs));
  return set;
}

// JSON text writer: slices one per block, points inline, numbers in shortest round-trip form.
void write_point_list(std::string& out, const Ring2& ring) {
  out += '[';
  for (std::size_t k = 0; k < ring.size(); ++k) {
    out += (k ? ", [" : "[") + detail::format_double(ring[k].x()) + ", " +
           detail::format_double(ring[k].y()) + "]";
  }
  out += ']';
}

std::string vec3_json(const Vec3& v) {
  return "[" + detail::format_double(v.x()) + ", " + detail::format_double(v.y()) + ", " +
         detail::format_double(v.z()) + "]";
}

// One slice object. The file form breaks lines before fov, regions and each region; one_line
// keeps it on a single line (messages, JSON lines).
void append_slice_object(std::string& out, const LabeledSlice& s, bool one_line) {
  const char* field_break = one_line ? ", " : ",\n     ";
  out += "{\"origin\": " + vec3_json(s.origin_mm) + ", \"u\": " + vec3_json(s.u) +
         ", \"v\": " + vec3_json(s.v);
  if (s.timestamp_s) out += ", \"timestamp\": " + detail::format_double(*s.timestamp_s);
  if (s.fov) {
    out += std::string(field_break) + "\"fov\": ";
    write_point_list(out, *s.fov);
  }
  out += std::string(field_break) + "\"regions\": [";
  for (std::size_t j = 0; j < s.regions.size(); ++j) {
    const Region& r = s.regions[j];
    if (j) out += ',';
    out += one_line ? (j ? " {" : "{") : "\n       {";
    out += "\"label\": " +
           (r.label == kUnknownLabel ? std::string("\"unknown\"") : std::to_string(r.label));
    out += ", \"polygon\": ";
    write_point_list(out, r.outer);
    if (!r.holes.empty()) {
      out += ", \"holes\": [";
      for (std::size_t k = 0; k < r.holes.size(); ++k) {
        if (k) out += ", ";
        write_point_list(out, r.holes[k]);
      }
      out += ']';
    }
    out += '}';
  }
  out += (s.regions.empty() || one_line) ? "]}" : "\n     ]}";
}

bool all_finite(const SliceSet& set) {
  auto ring_ok = [](const Ring2& ring) {
    return std::all_of(ring.begin(), ring.end(), [](const Vec2& p) { return p.allFinite(); });
  };
  if (set.bounds && (!set.bounds->min.allFinite() || !set.bounds->max.allFinite())) return false;
  for (const LabeledSlice& s : set.slices) {
    if (!s.origin_mm.allFinite() || !s.u.allFinite() || !s.v.allFinite()) return false;
    if (s.timestamp_s && !std::isfinite(*s.timestamp_s)) return false;
    if (s.fov && !ring_ok(*s.fov)) return false;
    for (const Region& r : s.regions) {
      if (!ring_ok(r.outer)) return false;
      if (!std::all_of(r.holes.begin(), r.holes.end(), ring_ok)) return false;
    }
  }
  return true;
}

std::string lower_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

}  // namespace

Result<SliceSet> parse_slice_set_json(const std::string& text, const std::string& source_name,
                                      const ReadOptions& options) {
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for a number overflow
    std::string what = e.what();
    if (const auto bracket = what.find("] ");
        what.rfind("[json.exception", 0) == 0 && bracket != std::string::npos)
      what = what.substr(bracket + 2);
    // The quoted token ("number overflow parsing '1111...'") cut to 40 characters.
    if (const auto open = what.find(" '"); open != std::string::npos) {
      const auto close = what.rfind('\'');
      if (close > open + 2 + 40)
        what = what.substr(0, open + 2 + 37) + "... (" + std::to_string(close - open - 2) +
               " characters)" + what.substr(close);
    }
    return Status::error(source_name + ": not valid JSON (" + what +
                         "); a slice set is a JSON document, see docs/formats/slices.md");
  }
  SliceSet set;
  detail::RepairLog repairs(source_name, options);
  try {
    set = parse_document(doc, source_name, repairs);
  } catch (const JsonProblem& p) {
    return Status::error(source_name + ": " + p.where + ": " + p.what);
  } catch (const detail::RepairRefused& refused) {
    return Status::error(refused.message);
  } catch (const json::exception& e) {
    return Status::error(source_name + ": malformed slice set (" + std::string(e.what()) + ")");
  }
  return detail::finish_parsed_set(std::move(set), source_name, detail::SliceNaming{}, repairs);
}

Status write_slice_set_json(const SliceSet& set, const std::filesystem::path& path) {
  if (!all_finite(set))
    return Status::error("cannot write " + path.string() +
                         ": the slice set holds NaN or infinite numbers, which JSON cannot hold");
  std::string out;
  out += "{\n  \"format\": \"sonoshape-slices\",\n  \"version\": 1,\n";
  out += "  \"units\": " + json(set.units).dump() + ",\n";
  if (!set.labels.empty()) {
    out += "  \"labels\": [";
    for (std::size_t k = 0; k < set.labels.size(); ++k)
      out += std::string(k ? ", " : "") + "{\"id\": " + std::to_string(set.labels[k].id) +
             ", \"name\": " + json(set.labels[k].name).dump() + "}";
    out += "],\n";
  }
  if (set.bounds)
    out += "  \"bounds\": {\"min\": " + vec3_json(set.bounds->min) +
           ", \"max\": " + vec3_json(set.bounds->max) + "},\n";
  out += "  \"slices\": [";
  for (std::size_t i = 0; i < set.slices.size(); ++i) {
    out += i ? ",\n    " : "\n    ";
    append_slice_object(out, set.slices[i], /*one_line=*/false);
  }
  out += set.slices.empty() ? "]\n}\n" : "\n  ]\n}\n";
  return detail::write_text_file(path, out);
}

Result<std::string> write_slice_json(const LabeledSlice& slice) {
  if (!all_finite(SliceSet{"mm", {}, std::nullopt, {slice}, {}}))
    return Status::error("cannot write the slice as JSON: it holds NaN or infinite numbers");
  std::string out;
  append_slice_object(out, slice, /*one_line=*/true);
  return out;
}

Result<LabeledSlice> parse_slice_json(const std::string& text, const std::string& source_name,
                                      const std::vector<std::string>& also_known) {
  // A lone slice has no index worth naming: "slice, region 1 (label 2)".
  struct LoneSliceNaming : detail::SliceNaming {
    std::string slice(std::size_t /*slice*/) const override { return "slice"; }
  };
  const LoneSliceNaming naming;
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {
    return Status::error(source_name + ": not valid JSON (" + std::string(e.what()) + ")");
  }
  SliceSet set;
  detail::RepairLog repairs(source_name, ReadOptions{});
  try {
    set.slices.push_back(
        parse_slice_object(doc, 0, false, source_name, naming, repairs, also_known));
  } catch (const JsonProblem& p) {
    return Status::error(source_name + ": " + p.where + ": " + p.what);
  } catch (const json::exception& e) {
    return Status::error(source_name + ": malformed slice (" + std::string(e.what()) + ")");
  }
  if (Status status = detail::validate_slice_set_named(set, source_name, naming, nullptr); !status)
    return status;
  repairs.finish();
  return std::move(set.slices.front());
}

Result<SliceSet> read_slice_set(const std::filesystem::path& path, const ReadOptions& options) {
  Result<std::string> text = detail::read_text_file(path);
  if (!text) return text.status();
  if (lower_extension(path) == ".csl") return parse_csl(*text, path.string(), options);
  return parse_slice_set_json(*text, path.string(), options);
}

Status write_slice_set(const SliceSet& set, const std::filesystem::path& path) {
  if (lower_extension(path) == ".csl") return write_csl(set, path);
  return write_slice_set_json(set, path);
}

}  // namespace sonoshape
