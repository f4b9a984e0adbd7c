#include "arrangement.hpp"

#include <CGAL/FPU.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

#include "grow.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/heap.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::recon {
namespace {

using Point3 = ExactKernel::Point_3;
using Plane3 = ExactKernel::Plane_3;

constexpr std::int8_t kUnknownSign = 2;

std::uint64_t pair_key(int a, int b) {
  if (a > b) std::swap(a, b);
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) |
         static_cast<std::uint32_t>(b);
}

using IntervalPoint3 = IntervalKernel::Point_3;

// The key of a vertex on demand: its three planes, sorted, 21 bits each (the same key is the
// same exact point).
std::uint64_t point_key(std::array<int, 3> planes) {
  std::sort(planes.begin(), planes.end());
  return (static_cast<std::uint64_t>(planes[0]) << 42) |
         (static_cast<std::uint64_t>(planes[1]) << 21) | static_cast<std::uint64_t>(planes[2]);
}

Point3 exact_intersection(const Plane3& a, const Plane3& b, const Plane3& c) {
  const auto result = CGAL::intersection(a, b, c);
  const Point3* point = result ? boost::get<Point3>(&*result) : nullptr;
  if (point == nullptr) throw GeometryError("arrangement: three planes do not meet in one point");
  return *point;
}

// A coordinate's double as ExactKernel's to_double gives it: the middle of its interval when
// that is narrow (relative width 1e-5, ExactKernel's default), of the exact value's otherwise.
template <typename ExactPoint>
double coordinate_double(const CGAL::Interval_nt<false>& approximation, const ExactPoint& exact,
                         int axis) {
  if (CGAL::has_smaller_relative_precision(approximation, 1e-5))
    return CGAL::to_double(approximation);
  return CGAL::to_double(CGAL::Interval_nt<false>(CGAL::to_interval(exact().exact()[axis])));
}

int to_side(CGAL::Oriented_side s) {
  return s == CGAL::ON_POSITIVE_SIDE ? 1 : (s == CGAL::ON_NEGATIVE_SIDE ? -1 : 0);
}

}  // namespace

Arrangement::Arrangement(const Box3& box) : box_(box) {
  if (!((box.max.array() > box.min.array()).all()))
    throw GeometryError(
        "reconstruction box is empty or inverted: min must be below max on every axis");
  // Six box planes, normals pointing inwards: plane 2k bounds axis k from below, 2k+1 from above.
  for (int axis = 0; axis < 3; ++axis) {
    for (int upper = 0; upper < 2; ++upper) {
      Vec3 n = Vec3::Zero();
      n[axis] = upper ? -1.0 : 1.0;
      const double d = upper ? box.max[axis] : -box.min[axis];
      planes_.push_back({n, d, -1, Plane3(n.x(), n.y(), n.z(), d),
                         IntervalKernel::Plane_3(n.x(), n.y(), n.z(), d)});
    }
  }
  // Corner c has coordinate bit k set when it sits at the box maximum along axis k.
  for (int c = 0; c < 8; ++c) {
    const Vec3 corner((c & 1) ? box.max.x() : box.min.x(), (c & 2) ? box.max.y() : box.min.y(),
                      (c & 4) ? box.max.z() : box.min.z());
    add_vertex(IntervalPoint3(corner.x(), corner.y(), corner.z()),
               {(c & 1) ? 1 : 0, (c & 2) ? 3 : 2, (c & 4) ? 5 : 4}, corner);
  }
  cells_.push_back({});
  for (int axis = 0; axis < 3; ++axis) {
    for (int upper = 0; upper < 2; ++upper) {
      const int i = (axis + 1) % 3, j = (axis + 2) % 3;
      // (0,0), (1,0), (1,1), (0,1) in axes (i, j) turns counter-clockwise about +e_axis.
      const std::array<std::array<int, 2>, 4> square{{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
      ArrangementFace face;
      face.plane = 2 * axis + upper;
      for (const auto& ij : square)
        face.vertices.push_back((upper << axis) | (ij[0] << i) | (ij[1] << j));
      if (upper) std::reverse(face.vertices.begin(), face.vertices.end());  // normal is -e_axis
      for (std::size_t e = 0; e < 4; ++e) {
        const int a = face.vertices[e], b = face.vertices[(e + 1) % 4];
        // The other box plane through both corners: the axis along which they agree (not `axis`).
        int other = -1;
        for (int k = 0; k < 3; ++k)
          if (k != axis && ((a >> k) & 1) == ((b >> k) & 1)) other = 2 * k + ((a >> k) & 1);
        face.edge_planes.push_back(other);
      }
      face.cell_positive = 0;
      cells_[0].faces.push_back(static_cast<int>(faces_.size()));
      faces_.push_back(std::move(face));
    }
  }
  cell_bounds_.push_back(box);
  bsp_.push_back({-1, -1, -1, 0, -1});
  leaf_of_cell_.push_back(0);
}

Arrangement::Arrangement(const Box3& box, bool on_demand) : Arrangement(box) {
  if (!on_demand) return;
  on_demand_ = true;
  // The box cell becomes the root region: the faces keep their polygons, the cell goes.
  Region root;
  for (const int f : cells_[0].faces) {
    const ArrangementFace& face = faces_[static_cast<std::size_t>(f)];
    root.faces.insert(root.faces.end(), {face.plane, 1, static_cast<int>(face.vertices.size())});
    for (std::size_t i = 0; i < face.vertices.size(); ++i)
      root.faces.insert(root.faces.end(), {face.vertices[i], face.edge_planes[i]});
  }
  root.bounds = box;
  root.next = planes_.size();
  regions_.push_back(std::move(root));
  cells_.clear();
  faces_.clear();
  cell_bounds_.clear();
  leaf_of_cell_.clear();
  bsp_.assign(1, BspNode{-1, -1, -1, -1, 0});
}

int Arrangement::add_vertex(const IntervalPoint3& approximation, const std::array<int, 3>& planes,
                            const Vec3& approx) {
  vertex_intervals_.push_back(approximation);
  vertex_planes_.push_back(planes);
  vertex_approx_.push_back(approx);
  sign_cache_.push_back(kUnknownSign);
  if (on_demand_) {
    // Box corners, made before, are keyed by themselves.
    vertex_keys_.push_back(point_key(planes));
  } else {
    vertex_keys_.push_back(std::uint64_t{1} << 63 | vertex_planes_.size());
  }
  return static_cast<int>(vertex_planes_.size()) - 1;
}

Point3 Arrangement::exact_vertex(int id) const {
  const std::array<int, 3>& t = vertex_planes_[static_cast<std::size_t>(id)];
  return exact_intersection(planes_[static_cast<std::size_t>(t[0])].exact,
                            planes_[static_cast<std::size_t>(t[1])].exact,
                            planes_[static_cast<std::size_t>(t[2])].exact);
}

int Arrangement::side(int plane_id, int vertex_id) const {
  return point_side(plane_id, vertex_intervals_[static_cast<std::size_t>(vertex_id)],
                    vertex_planes_[static_cast<std::size_t>(vertex_id)]);
}

int Arrangement::point_side(int plane_id, const IntervalPoint3& interval,
                            const std::array<int, 3>& planes) const {
  // ExactKernel's filtered predicate, by hand: the interval test decides unless the point's
  // interval box touches the plane; then CGAL's exact predicate on the exact point does.
  const ArrangementPlane& plane = planes_[static_cast<std::size_t>(plane_id)];
  try {
    const CGAL::Protect_FPU_rounding<true> upward;
    const CGAL::Uncertain<CGAL::Oriented_side> s =
        IntervalKernel().oriented_side_3_object()(plane.interval, interval);
    if (CGAL::is_certain(s)) return to_side(CGAL::get_certain(s));
  } catch (const CGAL::Uncertain_conversion_exception&) {
    // Undecided by the intervals.
  }
  return to_side(plane.exact.oriented_side(
      exact_intersection(planes_[static_cast<std::size_t>(planes[0])].exact,
                         planes_[static_cast<std::size_t>(planes[1])].exact,
                         planes_[static_cast<std::size_t>(planes[2])].exact)));
}

bool Arrangement::same_point(int a, int b) const {
  if (a == b ||
      vertex_planes_[static_cast<std::size_t>(a)] == vertex_planes_[static_cast<std::size_t>(b)])
    return true;
  try {
    const CGAL::Protect_FPU_rounding<true> upward;
    bool all_equal = true;
    for (int axis = 0; axis < 3; ++axis) {
      const CGAL::Uncertain<bool> equal =
          vertex_intervals_[static_cast<std::size_t>(a)].cartesian(axis) ==
          vertex_intervals_[static_cast<std::size_t>(b)].cartesian(axis);
      if (CGAL::is_certain(equal) && !CGAL::get_certain(equal)) return false;
      all_equal = all_equal && CGAL::is_certain(equal);
    }
    if (all_equal) return true;
  } catch (const CGAL::Uncertain_conversion_exception&) {
    // Undecided by the intervals.
  }
  return exact_vertex(a) == exact_vertex(b);
}

int Arrangement::plane_side(int plane_id, int vertex_id) {
  std::int8_t& cached = sign_cache_[static_cast<std::size_t>(vertex_id)];
  if (cached == kUnknownSign) {
    cached = static_cast<std::int8_t>(side(plane_id, vertex_id));
    touched_vertices_.push_back(vertex_id);
  }
  return cached;
}

int Arrangement::edge_vertex(int a, int b, int face_plane, int edge_plane, int new_plane) {
  const auto [it, inserted] = edge_vertex_cache_.try_emplace(pair_key(a, b), -1);
  if (!inserted) return it->second;
  it->second = plane_vertex(face_plane, edge_plane, new_plane);
  return it->second;
}

std::pair<IntervalPoint3, Vec3> Arrangement::intersection_point(int plane_a, int plane_b,
                                                                int plane_c) const {
  // The crossing point of an edge is the exact intersection of three input planes (the edge's
  // two and the new one): a construction of depth one, kept as its interval approximation (as
  // ExactKernel computes it) and the three planes.
  const ArrangementPlane& a = planes_[static_cast<std::size_t>(plane_a)];
  const ArrangementPlane& b = planes_[static_cast<std::size_t>(plane_b)];
  const ArrangementPlane& c = planes_[static_cast<std::size_t>(plane_c)];
  IntervalPoint3 approximation;
  bool approximated = false;
  try {
    const CGAL::Protect_FPU_rounding<true> upward;
    const auto result = CGAL::intersection(a.interval, b.interval, c.interval);
    if (const IntervalPoint3* point = result ? boost::get<IntervalPoint3>(&*result) : nullptr) {
      approximation = *point;
      approximated = true;
    }
  } catch (const CGAL::Uncertain_conversion_exception&) {
    // Intervals too wide to tell whether the planes meet in a point: the exact point decides.
  }
  std::optional<Point3> exact;
  if (!approximated) {
    const auto result = CGAL::intersection(a.exact, b.exact, c.exact);
    const Point3* point = result ? boost::get<Point3>(&*result) : nullptr;
    if (point == nullptr)
      throw GeometryError("arrangement: planes " + std::to_string(plane_a) + ", " +
                          std::to_string(plane_b) + ", " + std::to_string(plane_c) +
                          " do not meet in one point where an edge crosses the new plane");
    exact = *point;
    const auto& e = point->exact();
    approximation = IntervalPoint3(CGAL::to_interval(e.x()), CGAL::to_interval(e.y()),
                                   CGAL::to_interval(e.z()));
  }
  // The double point: the intervals' middles, or the exact point's where an interval is wide.
  auto exact_point = [&] {
    if (!exact) exact = exact_intersection(a.exact, b.exact, c.exact);
    return *exact;
  };
  Vec3 approx;
  for (int axis = 0; axis < 3; ++axis)
    approx[axis] = coordinate_double(approximation.cartesian(axis), exact_point, axis);
  return {approximation, approx};
}

int Arrangement::plane_vertex(int face_plane, int edge_plane, int new_plane) {
  const auto [interval, approx] = intersection_point(face_plane, edge_plane, new_plane);
  const int id = add_vertex(interval, {face_plane, edge_plane, new_plane}, approx);
  sign_cache_[static_cast<std::size_t>(id)] = 0;
  touched_vertices_.push_back(id);
  return id;
}

Arrangement::FaceSplit Arrangement::split_face(int face_id, int new_plane) {
  const auto cached = face_split_cache_.find(face_id);
  if (cached != face_split_cache_.end()) return cached->second;

  const ArrangementFace old = faces_[static_cast<std::size_t>(face_id)];
  const int q = new_plane;
  const std::size_t n = old.vertices.size();
  ArrangementFace pos, neg;
  pos.plane = neg.plane = old.plane;
  pos.cell_positive = neg.cell_positive = old.cell_positive;
  pos.cell_negative = neg.cell_negative = old.cell_negative;
  FaceSplit split;
  // Each kept vertex is pushed with the plane of the edge leaving it in the new polygon. The part
  // on a side leaves that side at a crossing point and re-enters at another: the edge between
  // them is the chord on the new plane.
  for (std::size_t i = 0; i < n; ++i) {
    const int vi = old.vertices[i], vj = old.vertices[(i + 1) % n];
    const int si = plane_side(q, vi), sj = plane_side(q, vj);
    const int edge_plane = old.edge_planes[i];
    int crossing = -1;
    if ((si > 0 && sj < 0) || (si < 0 && sj > 0))
      crossing = edge_vertex(vi, vj, old.plane, edge_plane, new_plane);
    // Positive part.
    if (si >= 0) {
      pos.vertices.push_back(vi);
      pos.edge_planes.push_back(si == 0 && sj < 0 ? new_plane : edge_plane);
      if (si > 0 && sj < 0) {
        pos.vertices.push_back(crossing);
        pos.edge_planes.push_back(new_plane);
      }
    } else if (sj > 0) {
      pos.vertices.push_back(crossing);
      pos.edge_planes.push_back(edge_plane);
    }
    // Negative part: the same with the sides swapped.
    if (si <= 0) {
      neg.vertices.push_back(vi);
      neg.edge_planes.push_back(si == 0 && sj > 0 ? new_plane : edge_plane);
      if (si < 0 && sj > 0) {
        neg.vertices.push_back(crossing);
        neg.edge_planes.push_back(new_plane);
      }
    } else if (sj < 0) {
      neg.vertices.push_back(crossing);
      neg.edge_planes.push_back(edge_plane);
    }
  }
  for (std::size_t k = 0; k < pos.vertices.size(); ++k) {
    if (pos.edge_planes[k] == new_plane) {
      split.chord_from = pos.vertices[k];
      split.chord_to = pos.vertices[(k + 1) % pos.vertices.size()];
    }
  }
  if (split.chord_from < 0 || pos.vertices.size() < 3 || neg.vertices.size() < 3)
    throw GeometryError("arrangement: inconsistent split of face " + std::to_string(face_id));
  split.negative = face_id;
  split.positive = static_cast<int>(faces_.size());
  faces_[static_cast<std::size_t>(face_id)] = std::move(neg);
  faces_.push_back(std::move(pos));
  face_split_cache_.emplace(face_id, split);
  return split;
}

void Arrangement::split_cell(int cell_id, int new_plane, std::vector<int>& changed) {
  const int cell_pos = static_cast<int>(cells_.size());
  const int cell_neg = cell_id;
  const int new_face = static_cast<int>(faces_.size());
  faces_.push_back({});
  faces_.back().plane = new_plane;
  faces_.back().cell_positive = cell_pos;
  faces_.back().cell_negative = cell_neg;
  const std::vector<int> old_faces = cells_[static_cast<std::size_t>(cell_id)].faces;
  cells_.push_back({});
  const int q = new_plane;

  std::vector<int> pos_faces, neg_faces;
  std::vector<DirectedEdge> section;  // boundary of the new face, counter-clockwise about q
  auto move_face = [&](int f, int to_cell) {
    ArrangementFace& face = faces_[static_cast<std::size_t>(f)];
    if (face.cell_positive == cell_id)
      face.cell_positive = to_cell;
    else if (face.cell_negative == cell_id)
      face.cell_negative = to_cell;
  };
  for (const int f : old_faces) {
    // sigma: +1 when this cell lies on the positive side of face f's plane. The face's stored
    // order is then clockwise seen from outside the cell, which flips the chord's direction.
    const int sigma = faces_[static_cast<std::size_t>(f)].cell_positive == cell_id ? 1 : -1;
    // A face already split for the neighbouring cell now holds only its negative part.
    const bool already_split = face_split_cache_.count(f) > 0;
    bool has_pos = already_split, has_neg = already_split;
    for (const int v : faces_[static_cast<std::size_t>(f)].vertices) {
      if (already_split) break;
      const int s = plane_side(q, v);
      has_pos |= s > 0;
      has_neg |= s < 0;
    }
    const int face_plane = faces_[static_cast<std::size_t>(f)].plane;
    if (has_pos && has_neg) {
      const FaceSplit split = split_face(f, new_plane);
      move_face(split.positive, cell_pos);
      pos_faces.push_back(split.positive);
      neg_faces.push_back(split.negative);
      if (sigma < 0)
        section.push_back({split.chord_from, split.chord_to, face_plane});
      else
        section.push_back({split.chord_to, split.chord_from, face_plane});
    } else if (has_pos || has_neg) {
      move_face(f, has_pos ? cell_pos : cell_neg);
      (has_pos ? pos_faces : neg_faces).push_back(f);
      // An edge of this face lying on the new plane bounds the new face too.
      const std::vector<int>& vs = faces_[static_cast<std::size_t>(f)].vertices;
      for (std::size_t i = 0; i < vs.size(); ++i) {
        const int a = vs[i], b = vs[(i + 1) % vs.size()];
        if (plane_side(q, a) != 0 || plane_side(q, b) != 0) continue;
        const bool forward = has_pos ? sigma < 0 : sigma > 0;
        section.push_back(forward ? DirectedEdge{a, b, face_plane}
                                  : DirectedEdge{b, a, face_plane});
      }
    } else {
      throw GeometryError("arrangement: a face of a crossed cell lies on the new plane");
    }
  }
  chain_section(section, cell_id, new_face);
  pos_faces.push_back(new_face);
  neg_faces.push_back(new_face);
  cells_[static_cast<std::size_t>(cell_pos)].faces = std::move(pos_faces);
  cells_[static_cast<std::size_t>(cell_neg)].faces = std::move(neg_faces);
  locate_split_cells(cell_neg, cell_pos, new_plane);
  changed.push_back(cell_neg);
  changed.push_back(cell_pos);
}

// Chains the section's edges (each boundary edge may come from two faces) into one cycle: the
// new face's vertices and edge planes.
void Arrangement::chain_section(const std::vector<DirectedEdge>& section, int cell_id,
                                int new_face) {
  std::unordered_map<int, std::pair<int, int>> next;  // from -> (to, plane)
  for (const DirectedEdge& e : section) {
    const auto [it, inserted] = next.try_emplace(e.from, e.to, e.plane);
    if (!inserted && it->second.first != e.to)
      throw GeometryError("arrangement: cross-section of cell " + std::to_string(cell_id) +
                          " is not a simple cycle");
  }
  ArrangementFace& section_face = faces_[static_cast<std::size_t>(new_face)];
  int v = next.begin()->first;
  for (std::size_t k = 0; k < next.size(); ++k) {
    const auto it = next.find(v);
    if (it == next.end())
      throw GeometryError("arrangement: open cross-section of cell " + std::to_string(cell_id));
    section_face.vertices.push_back(v);
    section_face.edge_planes.push_back(it->second.second);
    v = it->second.first;
  }
  if (v != section_face.vertices.front() || section_face.vertices.size() < 3)
    throw GeometryError("arrangement: cross-section of cell " + std::to_string(cell_id) +
                        " does not close");
}

// The boxes of the two halves of a split cell, and their leaves under the split cell's leaf of
// the point-location tree (the negative half keeps the old cell's id).
void Arrangement::locate_split_cells(int cell_neg, int cell_pos, int new_plane) {
  cell_bounds_.push_back({});
  for (const int c : {cell_neg, cell_pos}) {
    Box3 b{Vec3::Constant(std::numeric_limits<double>::infinity()),
           Vec3::Constant(-std::numeric_limits<double>::infinity())};
    for (const int f : cells_[static_cast<std::size_t>(c)].faces)
      for (const int vid : faces_[static_cast<std::size_t>(f)].vertices) {
        b.min = b.min.cwiseMin(vertex(vid));
        b.max = b.max.cwiseMax(vertex(vid));
      }
    cell_bounds_[static_cast<std::size_t>(c)] = b;
  }
  const int leaf = leaf_of_cell_[static_cast<std::size_t>(cell_neg)];
  const int neg_leaf = static_cast<int>(bsp_.size());
  bsp_.push_back({-1, -1, -1, cell_neg, -1});
  bsp_.push_back({-1, -1, -1, cell_pos, -1});
  bsp_[static_cast<std::size_t>(leaf)] = {new_plane, neg_leaf, neg_leaf + 1, -1, -1};
  leaf_of_cell_[static_cast<std::size_t>(cell_neg)] = neg_leaf;
  leaf_of_cell_.push_back(neg_leaf + 1);
}

std::vector<int> Arrangement::insert_plane(const Vec3& normal, double offset, int slice) {
  if (!(normal.allFinite() && std::isfinite(offset)) || normal.norm() == 0.0)
    throw GeometryError("arrangement: plane of slice " + std::to_string(slice) +
                        " has no valid normal");
  const Plane3 exact(normal.x(), normal.y(), normal.z(), offset);
  const IntervalKernel::Plane_3 interval(normal.x(), normal.y(), normal.z(), offset);
  for (std::size_t p = 0; p < planes_.size(); ++p) {
    if (exact == planes_[p].exact || exact == planes_[p].exact.opposite()) {
      throw GeometryError(
          "arrangement: the plane of slice " + std::to_string(slice) + " coincides with " +
          (planes_[p].slice >= 0 ? "the plane of slice " + std::to_string(planes_[p].slice)
                                 : std::string("a face of the reconstruction box")));
    }
  }
  const int plane_id = static_cast<int>(planes_.size());
  planes_.push_back({normal, offset, slice, exact, interval});
  // On demand, regions meet the plane when construct_cell reaches them; built cells it crosses
  // are reopened now.
  if (on_demand_) return reopen_crossed_cells(plane_id);

  edge_vertex_cache_.clear();
  face_split_cache_.clear();
  std::vector<int> changed;
  // Quick rejection with the double bounds of each cell; the tolerance covers the rounding of
  // the vertex approximations, everything closer is decided by the exact predicate.
  const double scale =
      normal.cwiseAbs().dot(box_.max.cwiseAbs().cwiseMax(box_.min.cwiseAbs())) + std::abs(offset);
  const double tolerance = 1e-9 * scale;
  const std::size_t cells_before = cells_.size();
  for (std::size_t c = 0; c < cells_before; ++c) {
    const Box3& b = cell_bounds_[c];
    const Vec3 center = 0.5 * (b.min + b.max);
    const double reach = 0.5 * normal.cwiseAbs().dot(b.max - b.min);
    const double center_value = normal.dot(center) + offset;
    if (center_value - reach > tolerance || center_value + reach < -tolerance) continue;
    bool has_pos = false, has_neg = false;
    for (const int f : cells_[c].faces) {
      // A face split for an earlier neighbour keeps only its negative part under its old id.
      if (face_split_cache_.count(f) > 0) {
        has_pos = has_neg = true;
        break;
      }
      for (const int v : faces_[static_cast<std::size_t>(f)].vertices) {
        const int s = plane_side(plane_id, v);
        has_pos |= s > 0;
        has_neg |= s < 0;
      }
    }
    if (has_pos && has_neg) split_cell(static_cast<int>(c), plane_id, changed);
  }
  reset_signs();
  return changed;
}

void Arrangement::reset_signs() {
  for (const int v : touched_vertices_) sign_cache_[static_cast<std::size_t>(v)] = kUnknownSign;
  touched_vertices_.clear();
}

bool Arrangement::region_crossed(const Region& region, int plane_id, RefineJob& job,
                                 RefineScratch& scratch) const {
  // Quick rejection with the region's double bounds, as insert_plane does for cells.
  const ArrangementPlane& plane = planes_[static_cast<std::size_t>(plane_id)];
  const Box3& b = region.bounds;
  const double scale = value_scale(plane);
  const double center_value = plane.normal.dot(0.5 * (b.min + b.max)) + plane.offset;
  const double reach = 0.5 * plane.normal.cwiseAbs().dot(b.max - b.min);
  if (center_value - reach > 1e-9 * scale || center_value + reach < -1e-9 * scale) return false;
  bool has_pos = false, has_neg = false;
  for (std::size_t at = 0; at < region.faces.size() && !(has_pos && has_neg);) {
    const RegionFace face = region_face(region.faces, at);
    for (int i = 0; i < face.count; ++i) {
      const int s = job_side(plane_id, face.vertex(i), job, scratch);
      has_pos |= s > 0;
      has_neg |= s < 0;
    }
    at += face.size();
  }
  reset_signs(job, scratch);
  return has_pos && has_neg;
}

int Arrangement::job_side(int plane_id, int vertex_id, RefineJob& job,
                          RefineScratch& scratch) const {
  std::int8_t* cached;
  if (vertex_id >= kJobVertex) {
    cached = &job.vertex_signs[static_cast<std::size_t>(vertex_id - kJobVertex)];
  } else {
    if (static_cast<std::size_t>(vertex_id) >= scratch.signs.size())
      scratch.signs.resize(vertex_planes_.size(), kUnknownSign);
    cached = &scratch.signs[static_cast<std::size_t>(vertex_id)];
  }
  if (*cached == kUnknownSign) {
    if (vertex_id >= kJobVertex) {
      const JobVertex& v = job.vertices[static_cast<std::size_t>(vertex_id - kJobVertex)];
      *cached = static_cast<std::int8_t>(point_side(plane_id, v.interval, v.planes));
    } else {
      *cached = static_cast<std::int8_t>(side(plane_id, vertex_id));
    }
    scratch.touched.push_back(vertex_id);
  }
  return *cached;
}

void Arrangement::reset_signs(RefineJob& job, RefineScratch& scratch) {
  for (const int v : scratch.touched) {
    if (v >= kJobVertex)
      job.vertex_signs[static_cast<std::size_t>(v - kJobVertex)] = kUnknownSign;
    else
      scratch.signs[static_cast<std::size_t>(v)] = kUnknownSign;
  }
  scratch.touched.clear();
}

int Arrangement::split_vertex(int a, int b, int face_plane, int edge_plane, int new_plane,
                              RefineJob& job, RefineScratch& scratch) const {
  // One vertex per edge within a split (the two faces on an edge must agree: a few entries,
  // searched in order). Regions do not share vertices: a vertex met again in another region is
  // constructed again (the same exact point), which costs less than finding it in a table of
  // a million; faces are matched by their vertices' planes instead (place(), link()).
  const std::uint64_t edge = pair_key(a, b);
  for (const auto& [key, id] : scratch.split_vertices)
    if (key == edge) return id;
  const auto [interval, approx] = intersection_point(face_plane, edge_plane, new_plane);
  const int id = kJobVertex + static_cast<int>(job.vertices.size());
  job.vertices.push_back({interval, {face_plane, edge_plane, new_plane}, approx});
  job.vertex_signs.push_back(kUnknownSign);
  scratch.split_vertices.emplace_back(edge, id);
  return id;
}

Arrangement::DirectedEdge Arrangement::split_region_face(const RegionFace& face, int new_plane,
                                                         std::vector<int>& pos,
                                                         std::vector<int>& neg, RefineJob& job,
                                                         RefineScratch& scratch) const {
  // The polygon's two parts, as split_face: each kept vertex is pushed with the plane of the
  // edge leaving it in the new polygon; the part on a side leaves it at one crossing point and
  // re-enters at another, and the edge between them is the chord on the new plane.
  const int q = new_plane;
  const int n = face.count;
  const std::size_t pos_at = pos.size(), neg_at = neg.size();
  pos.insert(pos.end(), {face.plane, face.sigma, 0});
  neg.insert(neg.end(), {face.plane, face.sigma, 0});
  for (int i = 0; i < n; ++i) {
    const int vi = face.vertex(i), vj = face.vertex((i + 1) % n);
    const int si = job_side(q, vi, job, scratch), sj = job_side(q, vj, job, scratch);
    const int edge_plane = face.edge_plane(i);
    int crossing = -1;
    if ((si > 0 && sj < 0) || (si < 0 && sj > 0))
      crossing = split_vertex(vi, vj, face.plane, edge_plane, new_plane, job, scratch);
    for (const int side : {1, -1}) {
      std::vector<int>& part = side > 0 ? pos : neg;
      if (si * side >= 0) {
        part.insert(part.end(), {vi, si == 0 && sj * side < 0 ? new_plane : edge_plane});
        if (si * side > 0 && sj * side < 0) part.insert(part.end(), {crossing, new_plane});
      } else if (sj * side > 0) {
        part.insert(part.end(), {crossing, edge_plane});
      }
    }
  }
  pos[pos_at + 2] = static_cast<int>((pos.size() - pos_at - 3) / 2);
  neg[neg_at + 2] = static_cast<int>((neg.size() - neg_at - 3) / 2);
  const RegionFace p = region_face(pos, pos_at);
  int chord_from = -1, chord_to = -1;
  for (int k = 0; k < p.count; ++k)
    if (p.edge_plane(k) == new_plane) {
      chord_from = p.vertex(k);
      chord_to = p.vertex((k + 1) % p.count);
    }
  if (chord_from < 0 || p.count < 3 || neg[neg_at + 2] < 3)
    throw GeometryError("arrangement: inconsistent split of a face on plane " +
                        std::to_string(face.plane));
  // The region lies on side sigma of the face's plane: its stored order is then clockwise seen
  // from outside the region when sigma > 0, which flips the chord's direction.
  return face.sigma < 0 ? DirectedEdge{chord_from, chord_to, face.plane}
                        : DirectedEdge{chord_to, chord_from, face.plane};
}

void Arrangement::close_section(const std::vector<DirectedEdge>& section, int new_plane, int sigma,
                                std::vector<int>& out) const {
  // Chains the section's edges (an edge on the plane may come from two faces) into one cycle,
  // counter-clockwise about the new plane, starting at the first face's edge (so the polygon
  // does not depend on vertex ids, which depend on the order cells were built in).
  auto fail = [&](const char* what) {
    return GeometryError(std::string("arrangement: the cross-section of a region by plane ") +
                         std::to_string(new_plane) + " " + what);
  };
  for (std::size_t i = 0; i < section.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (section[i].from == section[j].from && section[i].to != section[j].to)
        throw fail("is not a simple cycle");
  const std::size_t at = out.size();
  out.insert(out.end(), {new_plane, sigma, 0});
  int v = section.front().from, count = 0;
  do {
    const auto next = std::find_if(section.begin(), section.end(),
                                   [&](const DirectedEdge& e) { return e.from == v; });
    if (next == section.end()) throw fail("is open");
    out.insert(out.end(), {v, next->plane});
    ++count;
    v = next->to;
  } while (v != section.front().from && static_cast<std::size_t>(count) <= section.size());
  if (v != section.front().from || count < 3) throw fail("does not close");
  out[at + 2] = count;
}

std::pair<Arrangement::Region, Arrangement::Region> Arrangement::split_region(
    const Region& old, int new_plane, RefineJob& job, RefineScratch& scratch) const {
  const int q = new_plane;
  scratch.split_vertices.clear();
  Region pos, neg;
  pos.next = neg.next = old.next;
  pos.faces.reserve(old.faces.size() + 32);
  neg.faces.reserve(old.faces.size() + 32);
  std::vector<DirectedEdge>& section = scratch.section;  // boundary of the new face
  section.clear();
  for (std::size_t at = 0; at < old.faces.size();) {
    const RegionFace face = region_face(old.faces, at);
    at += face.size();
    bool has_pos = false, has_neg = false;
    for (int i = 0; i < face.count; ++i) {
      const int s = job_side(q, face.vertex(i), job, scratch);
      has_pos |= s > 0;
      has_neg |= s < 0;
    }
    if (has_pos && has_neg) {
      section.push_back(split_region_face(face, new_plane, pos.faces, neg.faces, job, scratch));
    } else if (has_pos || has_neg) {
      // An edge of this face lying on the new plane bounds the new face too.
      for (int i = 0; i < face.count; ++i) {
        const int a = face.vertex(i), b = face.vertex((i + 1) % face.count);
        if (job_side(q, a, job, scratch) != 0 || job_side(q, b, job, scratch) != 0) continue;
        const bool forward = has_pos ? face.sigma < 0 : face.sigma > 0;
        section.push_back(forward ? DirectedEdge{a, b, face.plane}
                                  : DirectedEdge{b, a, face.plane});
      }
      std::vector<int>& side = has_pos ? pos.faces : neg.faces;
      side.insert(side.end(), face.corners - 3, face.corners + 2 * face.count);
    } else {
      throw GeometryError("arrangement: a face of a crossed region lies on the new plane");
    }
  }
  reset_signs(job, scratch);
  if (section.empty()) throw GeometryError("arrangement: a crossed region has no cross-section");
  close_section(section, new_plane, -1, neg.faces);
  close_section(section, new_plane, 1, pos.faces);
  for (Region* r : {&neg, &pos}) {
    r->bounds = {Vec3::Constant(std::numeric_limits<double>::infinity()),
                 Vec3::Constant(-std::numeric_limits<double>::infinity())};
    for (std::size_t at = 0; at < r->faces.size();) {
      const RegionFace face = region_face(r->faces, at);
      for (int i = 0; i < face.count; ++i) {
        r->bounds.min = r->bounds.min.cwiseMin(job_vertex(face.vertex(i), job));
        r->bounds.max = r->bounds.max.cwiseMax(job_vertex(face.vertex(i), job));
      }
      at += face.size();
    }
  }
  return {std::move(neg), std::move(pos)};
}

int Arrangement::allocate_region(Region region) {
  if (!free_regions_.empty()) {
    const int id = free_regions_.back();
    free_regions_.pop_back();
    regions_[static_cast<std::size_t>(id)] = std::move(region);
    return id;
  }
  regions_.push_back(std::move(region));
  return static_cast<int>(regions_.size()) - 1;
}

void Arrangement::FaceTable::reserve(std::size_t more) {
  // Twice as many slots (at least 1024) until they are enough, the erased ones dropped.
  std::size_t size = std::max<std::size_t>(1024, slots_.size());
  while (2 * (used_ + more) > size) size *= 2;
  if (size == slots_.size()) return;
  std::vector<Slot> old = std::move(slots_);
  slots_.assign(size, Slot{});
  shift_ = 64 - std::countr_zero(slots_.size());
  used_ = 0;
  for (const Slot& slot : old)
    if (slot.face >= 0) insert(slot.key, slot.face);
}

void Arrangement::FaceTable::insert(std::uint64_t key, int face) {
  if (2 * (used_ + 1) > slots_.size()) reserve(1);
  std::size_t i = slot_of(key);
  while (slots_[i].face != kEmpty) i = (i + 1) & (slots_.size() - 1);
  slots_[i] = {key, face};
  ++used_;
}

bool Arrangement::FaceTable::erase(std::uint64_t key, int face) {
  if (slots_.empty()) return false;
  for (std::size_t i = slot_of(key); slots_[i].face != kEmpty; i = (i + 1) & (slots_.size() - 1)) {
    if (slots_[i].key == key && slots_[i].face == face) {
      slots_[i].face = kErased;  // still used: later faces of the probe sequence stay found
      return true;
    }
  }
  return false;
}

std::uint64_t Arrangement::face_key(int plane, std::vector<std::uint64_t>& keys) {
  std::sort(keys.begin(), keys.end());
  std::uint64_t key = static_cast<std::uint64_t>(plane) * 0x9E3779B97F4A7C15ull;
  for (const std::uint64_t v : keys) key = (key ^ v) * 0x100000001B3ull;
  return key;
}

std::vector<int> Arrangement::reopen_crossed_cells(int plane_id) {
  // Quick rejection with each cell's double bounds, as insert_plane does for whole arrangements;
  // the exact predicate decides the rest.
  const ArrangementPlane& plane = planes_[static_cast<std::size_t>(plane_id)];
  const double scale = value_scale(plane);
  std::vector<int> reopened;
  for (std::size_t c = 0; c < cells_.size(); ++c) {
    if (cells_[c].faces.empty()) continue;  // reopened before
    const Box3& b = cell_bounds_[c];
    const double center_value = plane.normal.dot(0.5 * (b.min + b.max)) + plane.offset;
    const double reach = 0.5 * plane.normal.cwiseAbs().dot(b.max - b.min);
    if (center_value - reach > 1e-9 * scale || center_value + reach < -1e-9 * scale) continue;
    bool has_pos = false, has_neg = false;
    for (const int f : cells_[c].faces)
      for (const int v : faces_[static_cast<std::size_t>(f)].vertices) {
        const int s = plane_side(plane_id, v);
        has_pos |= s > 0;
        has_neg |= s < 0;
      }
    if (!(has_pos && has_neg)) continue;
    reopen_cell(static_cast<int>(c), plane_id);
    reopened.push_back(static_cast<int>(c));
  }
  reset_signs();
  return reopened;
}

void Arrangement::reopen_cell(int cell, int plane_id) {
  // The faces a cell shares with its built neighbours name their points by the neighbours'
  // vertex ids, so one point may have two ids in the cell; a region's faces must agree on ids
  // (split_region chains the cross-section by them). The same key is the same exact point;
  // otherwise (four planes through a point) the exact points decide, for close doubles only.
  const int q = plane_id;
  std::vector<int> ids;
  const double tolerance =
      1e-5 * (box_.diagonal() + box_.max.cwiseAbs().maxCoeff() + box_.min.cwiseAbs().maxCoeff());
  auto canonical = [&](int v) {
    for (const int w : ids)
      if (w == v ||
          vertex_keys_[static_cast<std::size_t>(w)] == vertex_keys_[static_cast<std::size_t>(v)])
        return w;
    for (const int w : ids)
      if ((vertex(w) - vertex(v)).cwiseAbs().maxCoeff() <= tolerance && same_point(w, v)) return w;
    ids.push_back(v);
    return v;
  };
  Region region;
  region.bounds = cell_bounds_[static_cast<std::size_t>(cell)];
  region.next = static_cast<std::size_t>(plane_id);
  std::vector<std::uint64_t>& keys = sorted_scratch_;
  for (const int f : cells_[static_cast<std::size_t>(cell)].faces) {
    ArrangementFace& face = faces_[static_cast<std::size_t>(f)];
    const int sigma = face.cell_positive == cell ? 1 : -1;
    (sigma > 0 ? face.cell_positive : face.cell_negative) = -1;
    region.faces.insert(region.faces.end(),
                        {face.plane, sigma, static_cast<int>(face.vertices.size())});
    bool has_pos = false, has_neg = false;
    for (std::size_t i = 0; i < face.vertices.size(); ++i) {
      const int s = plane_side(q, face.vertices[i]);
      has_pos |= s > 0;
      has_neg |= s < 0;
      region.faces.insert(region.faces.end(), {canonical(face.vertices[i]), face.edge_planes[i]});
    }
    if (!(has_pos && has_neg)) continue;  // kept: the part of the region next to it reuses it
    // Crossed: no cell of the arrangement has this face any more.
    keys.clear();
    for (const int v : face.vertices) keys.push_back(vertex_keys_[static_cast<std::size_t>(v)]);
    if (faces_by_key_.erase(face_key(face.plane, keys), f)) retired_faces_.push_back(f);
    // Its polygon goes with the last cell on it (the other one, if built, is crossed too and
    // copies it when it is reopened).
    if (face.cell_positive < 0 && face.cell_negative < 0) {
      std::vector<int>().swap(face.vertices);
      std::vector<int>().swap(face.edge_planes);
    }
  }
  std::vector<int>().swap(cells_[static_cast<std::size_t>(cell)].faces);
  ++reopened_cells_;
  const int leaf = leaf_of_cell_[static_cast<std::size_t>(cell)];
  bsp_[static_cast<std::size_t>(leaf)] = {-1, -1, -1, -1, allocate_region(std::move(region))};
  leaf_of_cell_[static_cast<std::size_t>(cell)] = -1;
  reopened_leaves_.push_back(leaf);
}

int Arrangement::construct_cell(const Vec3& p) {
  if (!on_demand_) return locate(p);
  return construct_cells({p}, {1}).front();
}

template <typename Group>
void Arrangement::refine_in_passes(Group&& group, const std::vector<Vec3>& points,
                                   std::vector<int>& cells, std::size_t jobs_per_pass) {
  // Few regions reached (the first batch of a reconstruction reaches the root alone): each is
  // refined by a bounded number of splits, breadth first, and what is still in regions goes
  // round again, so that every thread has regions to refine. The bounds are constants: the
  // rounds, and so the ids, do not depend on the number of threads.
  // The jobs go in passes of at most jobs_per_pass, in order: the same ids as all at once, with
  // the storage of fewer jobs at a time (their regions, vertices and faces until linked).
  constexpr std::size_t kFewJobs = 32, kRoundSplits = 64, kTrimCells = 1024;
  jobs_per_pass = std::max<std::size_t>(1, jobs_per_pass);
  for (;;) {
    Stopwatch serial_clock;
    std::vector<RefineJob> all = group();
    serial_seconds_ += serial_clock.seconds();
    if (all.empty()) break;
    const bool bounded = all.size() < kFewJobs;
    for (std::size_t first = 0; first < all.size(); first += jobs_per_pass) {
      std::vector<RefineJob> jobs(
          std::make_move_iterator(all.begin() + static_cast<std::ptrdiff_t>(first)),
          std::make_move_iterator(all.begin() + static_cast<std::ptrdiff_t>(
                                                    std::min(all.size(), first + jobs_per_pass))));
      const std::size_t cells_before = cells_.size();
      // The jobs in parallel: each reads the arrangement and writes only itself.
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, jobs.size(), 1),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          RefineScratch& scratch = refine_scratch_.local();
                          for (std::size_t j = r.begin(); j < r.end(); ++j)
                            refine(
                                jobs[j], points, scratch,
                                bounded ? kRoundSplits : std::numeric_limits<std::size_t>::max());
                        });
      // Then into the tree: ids in job order, so they do not depend on which thread refined
      // what; the jobs' vertices, nodes and cells are written in parallel (each job its own
      // ids), their faces shared with the cells across in job order.
      serial_clock.reset();
      number(jobs);
      serial_seconds_ += serial_clock.seconds();
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, jobs.size(), 1),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          std::vector<std::uint64_t> sorted;
                          for (std::size_t j = r.begin(); j < r.end(); ++j)
                            place(jobs[j], cells, sorted);
                        });
      serial_clock.reset();
      link(jobs);
      serial_seconds_ += serial_clock.seconds();
      // The jobs' storage goes back to the system after a large pass: left in the allocator's
      // free lists it stayed resident, and the peak of `reconstruct` on 200 random slices was
      // 301-308 MB instead of 289-293 MB (one or two threads; /usr/bin/time). Passes of fewer
      // cells (online updates) skip the walk of the free lists: after each, it cost the last
      // updates 6 ms.
      const std::size_t built = cells_.size() - cells_before;
      jobs = {};
      if (built >= kTrimCells) release_free_heap();
    }
    if (!bounded) break;
  }
}

std::vector<int> Arrangement::construct_cells(const std::vector<Vec3>& points,
                                              const std::vector<char>& wanted,
                                              std::size_t jobs_per_pass) {
  std::vector<int> cells(points.size(), -1);
  std::vector<char> todo(points.size());
  refine_in_passes(
      [&] {
        // The points still in regions (after a bounded round) go round again.
        for (std::size_t n = 0; n < points.size(); ++n) todo[n] = wanted[n] && cells[n] < 0;
        return group_points(points, todo, cells);
      },
      points, cells, jobs_per_pass);
  return cells;
}

void Arrangement::construct_cells_meeting(const std::vector<std::vector<Vec3>>& polygons,
                                          std::size_t jobs_per_pass) {
  if (!on_demand_ || polygons.empty()) return;
  std::vector<int> no_cells;
  const std::vector<std::pair<int, PolygonParts>> root{{0, polygons}};
  refine_in_passes([&] { return group_polygons(root); }, {}, no_cells, jobs_per_pass);
}

void Arrangement::construct_reopened_cells_meeting(const std::vector<std::vector<Vec3>>& polygons,
                                                   std::size_t jobs_per_pass) {
  std::vector<int> leaves = std::exchange(reopened_leaves_, {});
  if (!on_demand_ || polygons.empty()) return;
  // Each reopened region (a leaf still: nothing refined it since) with the parts of the
  // polygons inside it: those whose bounds meet the region's, clipped by its faces' planes.
  std::vector<std::pair<int, PolygonParts>> starts;
  std::vector<Vec3> part, clipped;
  const double reach =
      1e-9 * (box_.max.cwiseAbs().cwiseMax(box_.min.cwiseAbs()).sum() + box_.diagonal());
  std::vector<Box3> polygon_bounds;
  for (const std::vector<Vec3>& polygon : polygons) {
    Box3& bounds = polygon_bounds.emplace_back(Box3{polygon.front(), polygon.front()});
    for (const Vec3& q : polygon) {
      bounds.min = bounds.min.cwiseMin(q);
      bounds.max = bounds.max.cwiseMax(q);
    }
  }
  for (const int leaf : leaves) {
    const BspNode& b = bsp_[static_cast<std::size_t>(leaf)];
    if (b.plane >= 0 || b.cell >= 0) continue;
    const Region& region = regions_[static_cast<std::size_t>(b.region)];
    PolygonParts parts;
    for (std::size_t i = 0; i < polygons.size(); ++i) {
      const std::vector<Vec3>& polygon = polygons[i];
      const Box3& bounds = polygon_bounds[i];
      if ((bounds.min.array() > region.bounds.max.array() + reach).any() ||
          (bounds.max.array() < region.bounds.min.array() - reach).any())
        continue;
      part = polygon;
      for (std::size_t at = 0; at < region.faces.size() && !part.empty();) {
        const RegionFace face = region_face(region.faces, at);
        at += face.size();
        clip_to_side(part, face.plane, face.sigma, clipped);
        std::swap(part, clipped);
      }
      if (!part.empty()) parts.push_back(part);
    }
    if (!parts.empty()) starts.emplace_back(leaf, std::move(parts));
  }
  if (starts.empty()) return;
  std::vector<int> no_cells;
  refine_in_passes([&] { return group_polygons(starts); }, {}, no_cells, jobs_per_pass);
}

void Arrangement::clip_to_side(const std::vector<Vec3>& polygon, int plane_id, int sigma,
                               std::vector<Vec3>& out) const {
  // Sutherland-Hodgman against one half-space, widened by the margin: a part that rounding
  // might put on the wrong side goes to both.
  const ArrangementPlane& plane = planes_[static_cast<std::size_t>(plane_id)];
  const double margin = 1e-9 * value_scale(plane);
  const auto value = [&](const Vec3& p) {
    return sigma * (plane.normal.dot(p) + plane.offset) + margin;
  };
  out.clear();
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const Vec3& a = polygon[i];
    const Vec3& b = polygon[(i + 1) % polygon.size()];
    const double fa = value(a), fb = value(b);
    if (fa >= 0.0) out.push_back(a);
    if ((fa >= 0.0) != (fb >= 0.0)) out.push_back(a + (b - a) * (fa / (fa - fb)));
  }
}

void Arrangement::split_parts(const PolygonParts& parts, int plane_id, PolygonParts& negative,
                              PolygonParts& positive, std::vector<Vec3>& scratch) const {
  for (const std::vector<Vec3>& part : parts) {
    clip_to_side(part, plane_id, -1, scratch);
    if (!scratch.empty()) negative.push_back(scratch);
    clip_to_side(part, plane_id, 1, scratch);
    if (!scratch.empty()) positive.push_back(scratch);
  }
}

Arrangement::RefineJob& Arrangement::start_job(std::vector<RefineJob>& jobs, int leaf) {
  const int region = bsp_[static_cast<std::size_t>(leaf)].region;
  RefineJob& job = jobs.emplace_back();
  job.leaf = leaf;
  job.regions.push_back(std::move(regions_[static_cast<std::size_t>(region)]));
  regions_[static_cast<std::size_t>(region)] = Region{};
  free_regions_.push_back(region);
  job.nodes.push_back({-1, -1, -1, 0, false, 0, 0, -1});
  return job;
}

std::vector<Arrangement::RefineJob> Arrangement::group_polygons(
    const std::vector<std::pair<int, PolygonParts>>& starts) {
  // From each start in turn, depth first, negative side first: the jobs' order does not depend
  // on the threads.
  std::vector<RefineJob> jobs;
  struct Visit {
    int node;
    PolygonParts parts;
  };
  std::vector<Visit> stack;
  std::vector<Vec3> clipped;  // split_parts' scratch
  for (auto start = starts.rbegin(); start != starts.rend(); ++start)
    stack.push_back({start->first, start->second});
  while (!stack.empty()) {
    Visit visit = std::move(stack.back());
    stack.pop_back();
    const BspNode& b = bsp_[static_cast<std::size_t>(visit.node)];
    if (b.plane < 0) {
      if (b.cell >= 0) continue;  // built
      RefineJob& job = start_job(jobs, visit.node);
      job.nodes[0].targets = 0;
      job.targets.push_back(std::move(visit.parts));
      continue;
    }
    Visit negative{b.negative, {}}, positive{b.positive, {}};
    split_parts(visit.parts, b.plane, negative.parts, positive.parts, clipped);
    if (!positive.parts.empty()) stack.push_back(std::move(positive));
    if (!negative.parts.empty()) stack.push_back(std::move(negative));
  }
  return jobs;
}

std::vector<Arrangement::RefineJob> Arrangement::group_points(const std::vector<Vec3>& points,
                                                              const std::vector<char>& wanted,
                                                              std::vector<int>& cells) {
  // Each point's BSP leaf (in parallel; the walk only reads the tree): the points in built cells
  // are done, the others are grouped by the region they reach, one refinement job per region,
  // in the order of their first points.
  std::vector<int> leaves(points.size(), -1);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, points.size(), 256),
      [&](const tbb::blocked_range<std::size_t>& r) {
        int guess = -1;  // the points come in runs of neighbours
        for (std::size_t n = r.begin(); n < r.end(); ++n) {
          if (!wanted[n]) continue;
          const Vec3& p = points[n];
          if (clear_inside(p, guess)) {
            cells[n] = guess;
            continue;
          }
          int node = 0;
          while (bsp_[static_cast<std::size_t>(node)].plane >= 0) {
            const BspNode& b = bsp_[static_cast<std::size_t>(node)];
            const ArrangementPlane& plane = planes_[static_cast<std::size_t>(b.plane)];
            node = plane.normal.dot(p) + plane.offset >= 0.0 ? b.positive : b.negative;
          }
          const BspNode& leaf = bsp_[static_cast<std::size_t>(node)];
          if (!on_demand_ || leaf.cell >= 0)
            cells[n] = guess = leaf.cell;
          else
            leaves[n] = node;
        }
      });
  std::vector<RefineJob> jobs;
  std::vector<int> job_of_leaf(bsp_.size(), -1);  // a table: a hash map cost more
  for (std::size_t n = 0; n < points.size(); ++n) {
    const int node = leaves[n];
    if (node < 0) continue;
    int& job_id = job_of_leaf[static_cast<std::size_t>(node)];
    if (job_id < 0) {
      job_id = static_cast<int>(jobs.size());
      start_job(jobs, node);
    }
    jobs[static_cast<std::size_t>(job_id)].points.push_back(static_cast<int>(n));
  }
  return jobs;
}

void Arrangement::refine(RefineJob& job, const std::vector<Vec3>& points, RefineScratch& scratch,
                         std::size_t max_splits) const {
  job.nodes[0].points_end = job.points.size();
  std::vector<int> pending{0};  // nodes with points and a region to refine, breadth first
  std::size_t splits = 0;
  for (std::size_t next = 0; next < pending.size() && splits < max_splits; ++next) {
    const auto k = static_cast<std::size_t>(pending[next]);
    // The first plane still crossing the region splits it; with none left it is a cell of the
    // full arrangement.
    Region& region = job.regions[static_cast<std::size_t>(job.nodes[k].region)];
    int crossing = -1;
    for (; region.next < planes_.size(); ++region.next) {
      if (region_crossed(region, static_cast<int>(region.next), job, scratch)) {
        crossing = static_cast<int>(region.next++);
        break;
      }
    }
    if (crossing < 0) {
      job.nodes[k].cell = true;
      continue;
    }
    auto [neg, pos] = split_region(region, crossing, job, scratch);
    ++splits;
    // The negative part takes the parent's slot; each point takes the side the walk down the
    // tree takes (construct_cell, locate).
    const int neg_region = job.nodes[k].region;
    const int pos_region = static_cast<int>(job.regions.size());
    job.regions[static_cast<std::size_t>(neg_region)] = std::move(neg);
    job.regions.push_back(std::move(pos));
    const ArrangementPlane& plane = planes_[static_cast<std::size_t>(crossing)];
    const auto begin = job.points.begin() + static_cast<std::ptrdiff_t>(job.nodes[k].points_begin);
    const auto end = job.points.begin() + static_cast<std::ptrdiff_t>(job.nodes[k].points_end);
    const auto middle = std::partition(begin, end, [&](int n) {
      const Vec3& p = points[static_cast<std::size_t>(n)];
      return !(plane.normal.dot(p) + plane.offset >= 0.0);
    });
    const std::size_t mid = static_cast<std::size_t>(middle - job.points.begin());
    // The target polygons' parts, clipped to each side (the negative side takes the slot).
    int neg_targets = -1, pos_targets = -1;
    if (job.nodes[k].targets >= 0) {
      const PolygonParts parts =
          std::move(job.targets[static_cast<std::size_t>(job.nodes[k].targets)]);
      PolygonParts neg_parts, pos_parts;
      split_parts(parts, crossing, neg_parts, pos_parts, scratch.clipped);
      if (!neg_parts.empty()) {
        neg_targets = job.nodes[k].targets;
        job.targets[static_cast<std::size_t>(neg_targets)] = std::move(neg_parts);
      }
      if (!pos_parts.empty()) {
        pos_targets = static_cast<int>(job.targets.size());
        job.targets.push_back(std::move(pos_parts));
      }
    }
    const int negative = static_cast<int>(job.nodes.size());
    job.nodes.push_back(
        {-1, -1, -1, neg_region, false, job.nodes[k].points_begin, mid, neg_targets});
    job.nodes.push_back({-1, -1, -1, pos_region, false, mid, job.nodes[k].points_end, pos_targets});
    RefineJob::Node& node = job.nodes[k];
    node.plane = crossing;
    node.negative = negative;
    node.positive = negative + 1;
    node.region = -1;
    node.targets = -1;
    // A part no point or polygon reached stays a region.
    if (mid > node.points_begin || neg_targets >= 0) pending.push_back(negative);
    if (job.nodes[static_cast<std::size_t>(negative) + 1].points_end > mid || pos_targets >= 0)
      pending.push_back(negative + 1);
  }
}

void Arrangement::number(std::vector<RefineJob>& jobs) {
  // In job order, after the arrangement's: vertices, BSP nodes (node 0 of a job is the leaf it
  // refined) and cells.
  std::size_t vertices = vertex_planes_.size(), nodes = bsp_.size(), cells = cells_.size();
  for (RefineJob& job : jobs) {
    job.vertex_base = static_cast<int>(vertices);
    job.node_base = static_cast<int>(nodes) - 1;
    job.cell_base = static_cast<int>(cells);
    vertices += job.vertices.size();
    nodes += job.nodes.size() - 1;
    cells += static_cast<std::size_t>(std::count_if(
        job.nodes.begin(), job.nodes.end(), [](const RefineJob::Node& n) { return n.cell; }));
  }
  grow(vertex_intervals_, vertices);
  grow(vertex_planes_, vertices);
  grow(vertex_approx_, vertices);
  grow(sign_cache_, vertices, kUnknownSign);
  grow(vertex_keys_, vertices);
  grow(bsp_, nodes);
  grow(cells_, cells);
  grow(cell_bounds_, cells);
  grow(leaf_of_cell_, cells);
}

void Arrangement::place(RefineJob& job, std::vector<int>& cells,
                        std::vector<std::uint64_t>& sorted) {
  for (std::size_t i = 0; i < job.vertices.size(); ++i) {
    const JobVertex& v = job.vertices[i];
    const std::size_t id = static_cast<std::size_t>(job.vertex_base) + i;
    vertex_intervals_[id] = v.interval;
    vertex_planes_[id] = v.planes;
    vertex_approx_[id] = v.approx;
    vertex_keys_[id] = point_key(v.planes);
  }
  // The job's copies go now: freeing them here took the peak of `reconstruct` on 200 random
  // slices from 342 to 317 MB (/usr/bin/time, before the passes of construct_cells).
  std::vector<JobVertex>().swap(job.vertices);
  std::vector<std::int8_t>().swap(job.vertex_signs);
  auto bsp_id = [&](int k) { return k == 0 ? job.leaf : job.node_base + k; };
  int cell = job.cell_base;
  for (std::size_t k = 0; k < job.nodes.size(); ++k) {
    const RefineJob::Node& node = job.nodes[k];
    BspNode& b = bsp_[static_cast<std::size_t>(bsp_id(static_cast<int>(k)))];
    if (node.plane >= 0) {
      b = {node.plane, bsp_id(node.negative), bsp_id(node.positive), -1, -1};
      continue;
    }
    Region& region = job.regions[static_cast<std::size_t>(node.region)];
    for (std::size_t at = 0; at < region.faces.size();) {
      const RegionFace face = region_face(region.faces, at);
      for (int i = 0; i < face.count; ++i) {
        int& v = region.faces[at + 3 + 2 * static_cast<std::size_t>(i)];
        if (v >= kJobVertex) v = job.vertex_base + (v - kJobVertex);
      }
      at += face.size();
    }
    if (!node.cell) continue;  // stays a region: link() gives it a slot
    // A cell: its faces with their keys, ready for link() to share with the cells across.
    b = {-1, -1, -1, cell, -1};
    leaf_of_cell_[static_cast<std::size_t>(cell)] = bsp_id(static_cast<int>(k));
    cell_bounds_[static_cast<std::size_t>(cell)] = region.bounds;
    for (std::size_t n = node.points_begin; n < node.points_end; ++n)
      cells[static_cast<std::size_t>(job.points[n])] = cell;
    for (std::size_t at = 0; at < region.faces.size();) {
      const RegionFace face = region_face(region.faces, at);
      at += face.size();
      // The face's identity: its plane and its vertices' planes (the same exact points).
      sorted.clear();
      for (int i = 0; i < face.count; ++i)
        sorted.push_back(vertex_keys_[static_cast<std::size_t>(face.vertex(i))]);
      RefineJob::CellFace& out = job.cell_faces.emplace_back();
      out.key = face_key(face.plane, sorted);
      out.sigma = face.sigma;
      out.cell = cell;
      out.region = node.region;
      out.at = static_cast<int>(at - face.size());
      out.keys_at = job.sorted_keys.size();
      job.sorted_keys.insert(job.sorted_keys.end(), sorted.begin(), sorted.end());
      // Starting at the vertex of smallest coordinates: the face's polygon, and so its image,
      // are the same whichever of its two cells was built first.
      for (int i = 1; i < face.count; ++i) {
        const Vec3& p = vertex(face.vertex(i));
        const Vec3& q = vertex(face.vertex(out.start));
        if (std::lexicographical_compare(p.data(), p.data() + 3, q.data(), q.data() + 3))
          out.start = i;
      }
    }
    job.cell_faces_end.push_back(job.cell_faces.size());
    ++cell;
  }
}

// The leaves no point reached become regions again, in slots that allocate_region would give
// them one after the other (the free ones last freed first, then new ones), moved in parallel.
void Arrangement::relink_regions(std::vector<RefineJob>& jobs) {
  auto is_region = [](const RefineJob::Node& node) { return node.plane < 0 && !node.cell; };
  std::vector<std::size_t> region_base(jobs.size() + 1, 0);
  for (std::size_t j = 0; j < jobs.size(); ++j)
    region_base[j + 1] =
        region_base[j] + static_cast<std::size_t>(
                             std::count_if(jobs[j].nodes.begin(), jobs[j].nodes.end(), is_region));
  std::vector<int> slots(region_base.back());
  std::size_t fresh = regions_.size();
  for (int& slot : slots) {
    if (free_regions_.empty()) {
      slot = static_cast<int>(fresh++);
      continue;
    }
    slot = free_regions_.back();
    free_regions_.pop_back();
  }
  regions_.resize(fresh);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, jobs.size(), 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t j = r.begin(); j < r.end(); ++j) {
                        RefineJob& job = jobs[j];
                        std::size_t slot = region_base[j];
                        for (std::size_t k = 0; k < job.nodes.size(); ++k) {
                          const RefineJob::Node& node = job.nodes[k];
                          if (!is_region(node)) continue;
                          const int id = slots[slot++];
                          regions_[static_cast<std::size_t>(id)] =
                              std::move(job.regions[static_cast<std::size_t>(node.region)]);
                          bsp_[static_cast<std::size_t>(
                              k == 0 ? job.leaf : job.node_base + static_cast<int>(k))] = {
                              -1, -1, -1, -1, id};
                        }
                      }
                    });
}

// The cells' faces, numbered g in job order. What adding them one after the other would do
// (find a face under the key whose side towards the cell is free and whose vertices have the
// same keys, and share it; else add the face and its key), in four steps.
class Arrangement::FaceLinker {
 public:
  FaceLinker(Arrangement& arrangement, std::vector<RefineJob>& jobs)
      : a_(arrangement), jobs_(jobs), face_base_(jobs.size() + 1, 0) {
    for (std::size_t j = 0; j < jobs.size(); ++j)
      face_base_[j + 1] = face_base_[j] + jobs[j].cell_faces.size();
    const std::size_t count = face_base_.back();
    shares_old_.assign(count, -1);
    shares_new_.assign(count, -1);
    face_id_.assign(count, -1);
  }

  void run() {
    find_shared_old_faces();
    const std::size_t keyed = share_new_faces();
    const int faces = number_added_faces(keyed);
    place_faces(faces);
  }

 private:
  RefineJob::CellFace& job_face(std::size_t g, std::size_t j) {
    return jobs_[j].cell_faces[g - face_base_[j]];
  }
  static RegionFace polygon(const RefineJob& job, const RefineJob::CellFace& face) {
    return region_face(job.regions[static_cast<std::size_t>(face.region)].faces,
                       static_cast<std::size_t>(face.at));
  }
  static std::pair<std::vector<std::uint64_t>::const_iterator,
                   std::vector<std::uint64_t>::const_iterator>
  keys_of(const RefineJob& job, const RefineJob::CellFace& face) {
    const auto begin = job.sorted_keys.cbegin() + static_cast<std::ptrdiff_t>(face.keys_at);
    return {begin, begin + polygon(job, face).count};
  }

  // 1. (in parallel; only reads) the faces built before that each face shares: one cell per
  //    side of a face, so no two new faces take the same side.
  void find_shared_old_faces() {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, jobs_.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t j = r.begin(); j < r.end(); ++j)
                          for (std::size_t i = 0; i < jobs_[j].cell_faces.size(); ++i)
                            shares_old_[face_base_[j] + i] =
                                old_face_shared(jobs_[j], jobs_[j].cell_faces[i]);
                      });
  }
  int old_face_shared(const RefineJob& job, const RefineJob::CellFace& face) const {
    const RegionFace p = polygon(job, face);
    const auto [keys_begin, keys_end] = keys_of(job, face);
    int shared = -1;
    a_.faces_by_key_.find(face.key, [&](int candidate) {
      const ArrangementFace& f = a_.faces_[static_cast<std::size_t>(candidate)];
      const int side = face.sigma > 0 ? f.cell_positive : f.cell_negative;
      if (f.plane != p.plane || side >= 0 || f.vertices.size() != static_cast<std::size_t>(p.count))
        return false;
      if (!std::all_of(f.vertices.begin(), f.vertices.end(), [&](int v) {
            return std::binary_search(keys_begin, keys_end,
                                      a_.vertex_keys_[static_cast<std::size_t>(v)]);
          }))
        return false;
      shared = candidate;
      return true;
    });
    return shared;
  }

  struct Keyed {
    std::uint64_t key;
    std::uint32_t job;
    std::uint32_t g;
    bool operator<(const Keyed& o) const { return key != o.key ? key < o.key : g < o.g; }
  };
  // 2. The others by key (a parallel sort): within a key, in order, a face shares the first
  //    earlier one that it would have found (added, its side free: the other side of its cell,
  //    not taken yet; the same plane and vertex keys), which gets the cell on that side.
  //    Returns how many faces were keyed.
  std::size_t share_new_faces() {
    std::vector<Keyed> keyed;
    for (std::size_t j = 0; j < jobs_.size(); ++j)
      for (std::size_t i = 0; i < jobs_[j].cell_faces.size(); ++i)
        if (shares_old_[face_base_[j] + i] < 0)
          keyed.push_back({jobs_[j].cell_faces[i].key, static_cast<std::uint32_t>(j),
                           static_cast<std::uint32_t>(face_base_[j] + i)});
    tbb::parallel_sort(keyed.begin(), keyed.end());
    for (std::size_t a = 0; a < keyed.size();) {
      std::size_t b = a + 1;
      while (b < keyed.size() && keyed[b].key == keyed[a].key) ++b;
      for (std::size_t later = a + 1; later < b; ++later) share_earlier(keyed, a, later);
      a = b;
    }
    return keyed.size();
  }
  void share_earlier(const std::vector<Keyed>& keyed, std::size_t first, std::size_t later) {
    const RefineJob::CellFace& face = job_face(keyed[later].g, keyed[later].job);
    const RegionFace p = polygon(jobs_[keyed[later].job], face);
    const auto [keys_begin, keys_end] = keys_of(jobs_[keyed[later].job], face);
    for (std::size_t earlier = first; earlier < later; ++earlier) {
      if (shares_new_[keyed[earlier].g] >= 0) continue;  // not added: not found
      RefineJob::CellFace& other = job_face(keyed[earlier].g, keyed[earlier].job);
      const RegionFace q = polygon(jobs_[keyed[earlier].job], other);
      if (q.plane != p.plane || other.sigma == face.sigma || other.other_cell >= 0 ||
          q.count != p.count)
        continue;
      const auto [other_begin, other_end] = keys_of(jobs_[keyed[earlier].job], other);
      if (!std::all_of(other_begin, other_end, [&](std::uint64_t k) {
            return std::binary_search(keys_begin, keys_end, k);
          }))
        continue;
      other.other_cell = face.cell;
      shares_new_[keyed[later].g] = keyed[earlier].g;
      return;
    }
  }

  // 3. Ids of the added faces in order, and their keys in the table; returns the face count.
  int number_added_faces(std::size_t keyed) {
    a_.faces_by_key_.reserve(
        keyed - static_cast<std::size_t>(std::count_if(shares_new_.begin(), shares_new_.end(),
                                                       [](std::int64_t g) { return g >= 0; })));
    int next = static_cast<int>(a_.faces_.size());
    for (std::size_t j = 0; j < jobs_.size(); ++j)
      for (std::size_t i = 0; i < jobs_[j].cell_faces.size(); ++i) {
        const std::size_t g = face_base_[j] + i;
        if (shares_old_[g] >= 0 || shares_new_[g] >= 0) continue;
        face_id_[g] = next++;
        a_.faces_by_key_.insert(jobs_[j].cell_faces[i].key, face_id_[g]);
      }
    return next;
  }

  // 4. (in parallel, a job's cells and added faces each) the faces into place and into their
  //    cells; a face built before gets the cell on its free side (one new face per side).
  void place_faces(int face_count) {
    grow(a_.faces_, static_cast<std::size_t>(face_count));
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, jobs_.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t j = r.begin(); j < r.end(); ++j) place_job_faces(j);
                      });
  }
  void place_job_faces(std::size_t j) {
    RefineJob& job = jobs_[j];
    for (std::size_t i = 0; i < job.cell_faces.size(); ++i) {
      RefineJob::CellFace& face = job.cell_faces[i];
      const std::size_t g = face_base_[j] + i;
      int id = face_id_[g];
      if (shares_old_[g] >= 0) {
        id = shares_old_[g];
        ArrangementFace& f = a_.faces_[static_cast<std::size_t>(id)];
        (face.sigma > 0 ? f.cell_positive : f.cell_negative) = face.cell;
      } else if (shares_new_[g] >= 0) {
        id = face_id_[static_cast<std::size_t>(shares_new_[g])];
      } else {
        const RegionFace p = polygon(job, face);
        ArrangementFace& f = a_.faces_[static_cast<std::size_t>(id)];
        f.plane = p.plane;
        f.vertices.resize(static_cast<std::size_t>(p.count));
        f.edge_planes.resize(static_cast<std::size_t>(p.count));
        for (int k = 0; k < p.count; ++k) {
          f.vertices[static_cast<std::size_t>(k)] = p.vertex((face.start + k) % p.count);
          f.edge_planes[static_cast<std::size_t>(k)] = p.edge_plane((face.start + k) % p.count);
        }
        (face.sigma > 0 ? f.cell_positive : f.cell_negative) = face.cell;
        (face.sigma > 0 ? f.cell_negative : f.cell_positive) = face.other_cell;
      }
      a_.cells_[static_cast<std::size_t>(face.cell)].faces.push_back(id);
    }
    // The job's cells are built: its copies go.
    std::vector<Region>().swap(job.regions);
    std::vector<RefineJob::CellFace>().swap(job.cell_faces);
    std::vector<std::uint64_t>().swap(job.sorted_keys);
  }

  Arrangement& a_;
  std::vector<RefineJob>& jobs_;
  std::vector<std::size_t> face_base_;    // per job, its first g
  std::vector<int> shares_old_;           // per g, the face built before that it shares, or -1
  std::vector<std::int64_t> shares_new_;  // per g, the g of the new face it shares, or -1
  std::vector<int> face_id_;              // per g, the id of the face it adds, or -1
};

void Arrangement::link(std::vector<RefineJob>& jobs) {
  relink_regions(jobs);
  FaceLinker(*this, jobs).run();
}

std::vector<int> Arrangement::faces_split_by_last_plane() const {
  std::vector<int> faces;
  faces.reserve(face_split_cache_.size());
  for (const auto& entry : face_split_cache_) faces.push_back(entry.first);
  return faces;
}

int Arrangement::locate(const Vec3& p) const {
  int node = 0;
  while (bsp_[static_cast<std::size_t>(node)].plane >= 0) {
    const BspNode& n = bsp_[static_cast<std::size_t>(node)];
    const ArrangementPlane& plane = planes_[static_cast<std::size_t>(n.plane)];
    node = plane.normal.dot(p) + plane.offset >= 0.0 ? n.positive : n.negative;
  }
  return bsp_[static_cast<std::size_t>(node)].cell;
}

bool Arrangement::clear_inside(const Vec3& p, int cell) const {
  if (cell < 0 || static_cast<std::size_t>(cell) >= cells_.size() || reopened(cell)) return false;
  // Inside the convex cell, farther from each of its faces' planes than rounding can move a
  // side-of-plane test (1e-9 of the box diagonal, against errors of about 1e-16 of it). Every
  // plane on the tree's path to the cell has the whole cell on one side, so it is at least as far
  // from p as the cell's boundary: the walk would take the same side at every node.
  const double margin = 1e-9 * box_.diagonal();
  for (const int f : cells_[static_cast<std::size_t>(cell)].faces) {
    const ArrangementFace& face = faces_[static_cast<std::size_t>(f)];
    const double side = planes_[static_cast<std::size_t>(face.plane)].signed_distance(p);
    if (face.cell_positive == cell ? !(side > margin) : !(side < -margin)) return false;
  }
  return true;
}

int Arrangement::locate(const Vec3& p, int guess) const {
  return clear_inside(p, guess) ? guess : locate(p);
}

}  // namespace sonoshape::recon
