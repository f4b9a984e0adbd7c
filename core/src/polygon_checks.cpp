// The exact-predicate polygon checks: one ring (ring_checks.hpp, for the readers) and regions
// against each other (exact_polygons.hpp, for the validation and the snapping).
#include <CGAL/Boolean_set_operations_2.h>
#include <CGAL/Polygon_2_algorithms.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <set>
#include <sstream>
#include <utility>

#include "exact_polygons.hpp"
#include "ring_checks.hpp"

namespace sonoshape::detail {

// ---------------------------------------------------------------------------------------------
// One ring

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

Points to_points(const Ring2& ring) {
  Points points;
  points.reserve(ring.size());
  for (const Vec2& p : ring) points.emplace_back(p.x(), p.y());
  return points;
}

Box2 box_of(const Ring2& ring) {
  Box2 box{ring.front(), ring.front()};
  for (const Vec2& p : ring) {
    box.lo = box.lo.cwiseMin(p);
    box.hi = box.hi.cwiseMax(p);
  }
  return box;
}

namespace {

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

// ---------------------------------------------------------------------------------------------
// Regions

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

namespace {

bool in_interior(const IK::Point_2& p, const RegionRings& region) {
  if (!strictly_inside(p, region.outer)) return false;
  return std::none_of(region.holes.begin(), region.holes.end(),
                      [&](const Points& hole) { return strictly_inside(p, hole); });
}

}  // namespace

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

namespace {

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

}  // namespace

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

}  // namespace sonoshape::detail
