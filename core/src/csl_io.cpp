// `.csl` contour-slice files (docs/formats/csl.md): reading into a SliceSet and writing one.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <optional>
#include <set>
#include <string_view>
#include <utility>

#include "repair_log.hpp"
#include "ring_checks.hpp"
#include "ring_repair.hpp"
#include "slice_rules.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "text_io.hpp"

namespace sonoshape {
namespace {

// Problems are thrown as InputError inside the parser only; parse_csl turns them into a Status.
[[noreturn]] void fail(std::size_t line, const std::string& what) {
  throw InputError("line " + std::to_string(line), what);
}

struct Token {
  std::string_view text;
  std::size_t line = 0;
};

// Whitespace-separated tokens with their line numbers; blank lines are simply skipped.
// A token as a message quotes it: a 100000-digit number is cut to its first 40 characters so
// that the message stays a line, not 100 KB.
std::string excerpt(std::string_view text) {
  if (text.size() <= 40) return std::string(text);
  return std::string(text.substr(0, 37)) + "... (" + std::to_string(text.size()) + " characters)";
}

class Tokens {
 public:
  explicit Tokens(const std::string& text) {
    std::size_t line = 1;
    std::size_t k = 0;
    while (k < text.size()) {
      const char c = text[k];
      if (c == '\n') {
        ++line;
        ++k;
      } else if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
        ++k;
      } else {
        const std::size_t start = k;
        while (k < text.size() && !std::isspace(static_cast<unsigned char>(text[k]))) ++k;
        tokens_.push_back({std::string_view(text).substr(start, k - start), line});
      }
    }
    end_line_ = line;
  }

  bool done() const { return next_ == tokens_.size(); }
  std::size_t line() const { return done() ? end_line_ : tokens_[next_].line; }

  const Token& take(const char* what) {
    if (done())
      fail(end_line_, std::string("the file ends early: expected ") + what +
                          "; check the counts in the plane headers");
    return tokens_[next_++];
  }

  long long take_int(const char* what) {
    const Token& t = take(what);
    long long value = 0;
    const auto [end, ec] = std::from_chars(t.text.data(), t.text.data() + t.text.size(), value);
    if (ec != std::errc() || end != t.text.data() + t.text.size())
      fail(t.line,
           std::string("expected ") + what + " (an integer), got \"" + excerpt(t.text) + "\"");
    return value;
  }

  double take_double(const char* what) {
    const Token& t = take(what);
    double value = 0.0;
    const char* first = t.text.data();
    if (!t.text.empty() && t.text.front() == '+') ++first;  // from_chars refuses a leading '+'
    const auto [end, ec] = std::from_chars(first, t.text.data() + t.text.size(), value);
    if (ec != std::errc() || end != t.text.data() + t.text.size() || !std::isfinite(value))
      fail(t.line,
           std::string("expected ") + what + " (a finite number), got \"" + excerpt(t.text) + "\"");
    return value;
  }

 private:
  std::vector<Token> tokens_;
  std::size_t next_ = 0;
  std::size_t end_line_ = 1;
};

struct Component {
  std::size_t line = 0;
  std::optional<std::size_t> parent;  // set for a hole written as "<n>h<parent>"
  int label = 1;
  std::vector<std::size_t> indices;
};

struct Plane {
  long long index = 0;
  std::size_t line = 0;
  Vec3 abc = Vec3::Zero();
  double d = 0.0;
  std::vector<Vec3> vertices;
  std::vector<Component> components;
};

// Messages name planes and components as the file writes them, so the user finds the line.
class CslNaming : public detail::SliceNaming {
 public:
  struct SliceNames {
    std::string slice;
    std::vector<std::string> regions;
    std::vector<std::vector<std::string>> holes;
  };
  std::vector<SliceNames> names;

  std::string slice(std::size_t i) const override { return names[i].slice; }
  std::string region(std::size_t i, std::size_t j, int /*label*/) const override {
    return names[i].regions[j];
  }
  std::string outer(std::size_t i, std::size_t j, int label) const override {
    return slice(i) + ", " + region(i, j, label);
  }
  std::string hole(std::size_t i, std::size_t j, int /*label*/, std::size_t k) const override {
    return slice(i) + ", " + names[i].holes[j][k];
  }
};

// A component's label as the file writes it, checked. An outer contour carries a material
// 1..nLabels-1. A hole's label says what fills it: its parent's own label, 0 or nLabels the
// outside, another material that material (files in the wild use all three).
int checked_label(long long label, bool hole, int n_labels, std::size_t line,
                  const std::string& where) {
  const std::string header = "the header says nLabels = " + std::to_string(n_labels);
  if (hole) {
    if (label < 0 || label > n_labels)
      fail(line, where + ": label " + std::to_string(label) + " is outside 0.." +
                     std::to_string(n_labels) + " (" + header +
                     "); a hole's label is its parent's, 0 or nLabels for the outside, or a "
                     "material 1.." +
                     std::to_string(n_labels - 1) +
                     " that fills the hole; fix the label or the header");
    return static_cast<int>(label);
  }
  if (label == 0)
    fail(line, where + ": label 0 is the outside in .csl; components carry material labels 1.." +
                   std::to_string(n_labels - 1) +
                   ". If the file numbers materials from 0, add 1 to every component label and "
                   "to nLabels");
  if (label < 0 || label >= n_labels)
    fail(line, where + ": label " + std::to_string(label) + " is outside 1.." +
                   std::to_string(n_labels - 1) + " (" + header +
                   ", which counts the outside); fix the label or the header");
  return static_cast<int>(label);
}

Plane read_plane(Tokens& tokens, int n_labels) {
  Plane plane;
  plane.line = tokens.line();
  plane.index = tokens.take_int("the plane index");
  const std::size_t header_line = plane.line;
  const long long n_vertices = tokens.take_int("the plane's vertex count");
  const long long n_components = tokens.take_int("the plane's component count");
  if (n_vertices < 0 || n_components < 0)
    fail(header_line, "plane " + std::to_string(plane.index) + ": negative counts");
  plane.abc.x() = tokens.take_double("the plane coefficient A");
  plane.abc.y() = tokens.take_double("the plane coefficient B");
  plane.abc.z() = tokens.take_double("the plane coefficient C");
  plane.d = tokens.take_double("the plane coefficient D");
  // A lying count (1e9) must not allocate before the vertices are read: the file ends early.
  plane.vertices.reserve(static_cast<std::size_t>(std::min<long long>(n_vertices, 1 << 16)));
  for (long long k = 0; k < n_vertices; ++k) {
    Vec3 p;
    p.x() = tokens.take_double("a vertex x");
    p.y() = tokens.take_double("a vertex y");
    p.z() = tokens.take_double("a vertex z");
    if (p.cwiseAbs().maxCoeff() > detail::kMaxCoordinateMm)
      fail(tokens.line(), "plane " + std::to_string(plane.index) + ", vertex " + std::to_string(k) +
                              ": a coordinate beyond 1e12 mm (" +
                              detail::format_double(p.cwiseAbs().maxCoeff()) +
                              "), where lengths lose their precision; check the units");
    plane.vertices.push_back(p);
  }
  const std::string plane_name = "plane " + std::to_string(plane.index);
  for (long long c = 0; c < n_components; ++c) {
    Component component;
    const Token& count_token = tokens.take("a component's point count");
    component.line = count_token.line;
    const std::string where = plane_name + ", component " + std::to_string(c);
    // "<n>" or "<n>h<parent>"
    const std::string_view text = count_token.text;
    const std::size_t h = text.find('h');
    long long count = 0;
    long long parent = -1;
    const std::string_view count_text = text.substr(0, h);
    auto [end, ec] =
        std::from_chars(count_text.data(), count_text.data() + count_text.size(), count);
    bool ok = ec == std::errc() && end == count_text.data() + count_text.size();
    if (ok && h != std::string_view::npos) {
      const std::string_view parent_text = text.substr(h + 1);
      auto [pend, pec] =
          std::from_chars(parent_text.data(), parent_text.data() + parent_text.size(), parent);
      ok = pec == std::errc() && pend == parent_text.data() + parent_text.size();
    }
    if (!ok)
      fail(component.line, where + ": expected a point count like \"25\" or \"25h3\", got \"" +
                               excerpt(text) + "\"");
    if (count < 0) fail(component.line, where + ": negative point count");
    if (h != std::string_view::npos) {
      if (parent < 0 || parent >= n_components || parent == c)
        fail(component.line, where + ": \"" + std::string(text) + "\" names component " +
                                 std::to_string(parent) +
                                 " as the parent of this hole, but the "
                                 "plane's components are 0.." +
                                 std::to_string(n_components - 1) +
                                 " (0-based) and a hole cannot be its own parent");
      component.parent = static_cast<std::size_t>(parent);
    }
    component.label = checked_label(tokens.take_int("a component label"),
                                    component.parent.has_value(), n_labels, component.line, where);
    for (long long k = 0; k < count; ++k) {
      const long long index = tokens.take_int("a vertex index");
      if (index < 0 || index >= n_vertices)
        fail(tokens.line(), where + ": vertex index " + std::to_string(index) + " is outside 0.." +
                                std::to_string(n_vertices - 1) +
                                " (indices are 0-based into the plane's vertex list)");
      component.indices.push_back(static_cast<std::size_t>(index));
    }
    plane.components.push_back(std::move(component));
  }
  return plane;
}

// A deterministic orthonormal basis (u, v) of the plane with u x v = n.
void plane_basis(const Vec3& n, Vec3& u, Vec3& v) {
  int axis = 0;  // the world axis least aligned with n
  for (int k = 1; k < 3; ++k)
    if (std::abs(n[k]) < std::abs(n[axis])) axis = k;
  const Vec3 e = Vec3::Unit(axis);
  u = (e - e.dot(n) * n).normalized();
  v = n.cross(u);
}

// The plane a plane's vertices lie on: unit normal n and offset d of n.p + d = 0.
struct PlaneFit {
  Vec3 n = Vec3::UnitZ();
  double d = 0.0;
  bool refitted = false;   // the written equation disagreed with the vertices
  bool flipped_d = false;  // the vertices satisfy the written equation with D negated
};

// The vertex farthest from the plane n.p + d = 0: (distance, index).
std::pair<double, std::size_t> farthest_vertex(const std::vector<Vec3>& vertices, const Vec3& n,
                                               double d) {
  std::pair<double, std::size_t> worst{0.0, 0};
  for (std::size_t k = 0; k < vertices.size(); ++k) {
    const double off = std::abs(n.dot(vertices[k]) + d);
    if (off > worst.first) worst = {off, k};
  }
  return worst;
}

// The least-squares plane of the vertices: through their centroid, normal along the covariance's
// smallest eigenvector, oriented like `written`. Nullopt when the vertices lie on one line.
std::optional<PlaneFit> least_squares_plane(const std::vector<Vec3>& vertices,
                                            const Vec3& written) {
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& p : vertices) centroid += p;
  centroid /= static_cast<double>(vertices.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const Vec3& p : vertices) covariance += (p - centroid) * (p - centroid).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  if (solver.info() != Eigen::Success ||
      !(solver.eigenvalues()(1) > 1e-12 * solver.eigenvalues()(2)))
    return std::nullopt;
  PlaneFit fit;
  fit.n = solver.eigenvectors().col(0).normalized();
  if (fit.n.dot(written) < 0.0) fit.n = -fit.n;
  fit.d = -fit.n.dot(centroid);
  fit.refitted = true;
  return fit;
}

// The plane of a plane's vertices. Vertices slightly off the written plane are projected
// (datasets round their coordinates). When they are far off it but coplanar, the vertices are
// the data: the plane is fitted to them (rose.csl writes +D where its vertices satisfy -D).
// Vertices that are not coplanar are refused.
PlaneFit fit_plane(const Plane& plane, const std::string& plane_name, detail::RepairLog& repairs) {
  const double abc_norm = plane.abc.norm();
  if (!(abc_norm > 0.0))
    fail(plane.line, "plane " + std::to_string(plane.index) +
                         ": the normal (A, B, C) is zero, so this is not a plane");
  PlaneFit fit;
  fit.n = plane.abc / abc_norm;
  fit.d = plane.d / abc_norm;
  if (plane.vertices.empty()) return fit;

  Vec3 lo = plane.vertices.front();
  Vec3 hi = lo;
  for (const Vec3& p : plane.vertices) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double extent = (hi - lo).norm();
  const double scale = std::max({extent, hi.cwiseAbs().maxCoeff(), lo.cwiseAbs().maxCoeff()});
  const double far = std::max(1e-3 * extent, 1e-9 * scale);
  auto [max_off, worst] = farthest_vertex(plane.vertices, fit.n, fit.d);
  if (max_off > far) {
    const std::string written_text = "vertex " + std::to_string(worst) + " lies " +
                                     detail::format_double(max_off) +
                                     " off the plane, more than 1e-3 of the plane's extent (" +
                                     detail::format_double(extent) + ")";
    const std::optional<PlaneFit> fitted = least_squares_plane(plane.vertices, fit.n);
    if (!fitted)
      fail(plane.line, plane_name + ": " + written_text +
                           ", and the vertices lie on one line, so no plane fits them; check the "
                           "plane's A B C D or its vertices");
    const auto [fit_off, fit_worst] = farthest_vertex(plane.vertices, fitted->n, fitted->d);
    if (fit_off > far)
      fail(plane.line, plane_name + ": " + written_text +
                           ", and the vertices are not coplanar either (vertex " +
                           std::to_string(fit_worst) + " lies " + detail::format_double(fit_off) +
                           " off the plane that fits them best); check the plane's vertices");
    fit = *fitted;
    max_off = fit_off;
  }
  fit.flipped_d =
      farthest_vertex(plane.vertices, plane.abc / abc_norm, -plane.d / abc_norm).first <= far;
  if (max_off > 1e-9 * scale)
    repairs.add(plane_name, {"off_plane_vertices", plane_name,
                             "vertices lie up to " + detail::format_double(max_off) +
                                 " off the plane; projected onto it",
                             0.0});
  return fit;
}

// A ring the nesting works on: a component as written, a part of one whose contour crossed
// itself (repaired by the non-zero rule), or the region of a material that fills a hole.
struct Piece {
  std::size_t component = 0;           // the component of the file it comes from
  std::optional<std::size_t> hole_of;  // a hole cut out of this component of the file
  std::optional<std::size_t> parent;   // hole_of resolved to a piece
  int label = 1;
  std::size_t depth = 0;  // in its component's repair; 0 when not repaired
  Ring2 ring;
  std::string name;
};

std::string world_text(const Vec3& p) {
  // Appended piece by piece: GCC 12 warns falsely (-Wrestrict) on the chained form once inlined.
  std::string text = "(";
  text += detail::format_short(p.x());
  text += ", ";
  text += detail::format_short(p.y());
  text += ", ";
  text += detail::format_short(p.z());
  text += ")";
  return text;
}

// The same points, in any order.
bool same_points(Ring2 a, Ring2 b) {
  if (a.size() != b.size()) return false;
  auto less = [](const Vec2& p, const Vec2& q) {
    return p.x() < q.x() || (p.x() == q.x() && p.y() < q.y());
  };
  std::sort(a.begin(), a.end(), less);
  std::sort(b.begin(), b.end(), less);
  return a == b;
}

// How a component enters the nesting. An outer contour is a region of its label. A hole of the
// outside (labelled with its parent's label, 0 or nLabels) is a marked hole of its parent, with
// the parent's label. A hole filled by another material is a region of that material, which the
// nesting cuts out of its parent.
struct ComponentRole {
  std::string name;
  int label = 1;
  bool cut = false;     // a hole of the outside
  int other_label = 0;  // a filled hole: the parent's label
};

ComponentRole component_role(const Plane& plane, std::size_t c, int n_labels,
                             const std::string& plane_name) {
  const Component& comp = plane.components[c];
  const std::string head = "component " + std::to_string(c) + " (line " + std::to_string(comp.line);
  ComponentRole role{head + ", label " + std::to_string(comp.label) + ")", comp.label};
  if (!comp.parent) return role;
  const Component& parent = plane.components[*comp.parent];
  const std::string of = ", hole of component " + std::to_string(*comp.parent);
  if (parent.parent)
    fail(comp.line, plane_name + ", " + role.name + ": marked as a hole of component " +
                        std::to_string(*comp.parent) +
                        ", which is itself a hole; a hole's parent must be an outer contour");
  if (comp.label == parent.label || comp.label == 0 || comp.label == n_labels) {
    role.cut = true;
    role.label = parent.label;
    role.name = head + of + ")";
  } else {
    role.other_label = parent.label;
    role.name = head + of + ", filled by label " + std::to_string(comp.label) + ")";
  }
  return role;
}

// The rings a self-intersecting component encloses, as pieces. Nesting sorts them out: inside a
// part of the same label a part is its hole, inside a hole a region. Only the outer parts of a
// hole of the outside keep the hole marker; the rings inside a filled hole alternate between the
// filling and the parent's material.
void add_repaired_parts(const Plane& plane, std::size_t c, const ComponentRole& role,
                        const detail::ContourRepair& fixed, const std::string& plane_name,
                        std::vector<Piece>& pieces) {
  for (std::size_t k = 0; k < fixed.rings.size(); ++k) {
    Piece part;
    part.component = c;
    part.depth = fixed.rings[k].depth;
    part.hole_of = role.cut && part.depth == 0 ? plane.components[c].parent : std::nullopt;
    part.label = role.other_label && part.depth % 2 == 1 ? role.other_label : role.label;
    part.ring = fixed.rings[k].ring;
    part.name = role.name + ", part " + std::to_string(k + 1) + " of " +
                std::to_string(fixed.rings.size()) + " after its repair";
    const std::string problem = detail::ring_problem(part.ring);
    if (!problem.empty())
      fail(plane.components[c].line, plane_name + ", " + part.name + ": " + problem);
    pieces.push_back(std::move(part));
  }
}

// A filled hole also written as a component of its material is that component.
std::vector<Piece> without_filled_duplicates(std::vector<Piece> pieces, const Plane& plane) {
  std::vector<bool> duplicate(pieces.size(), false);
  for (std::size_t k = 0; k < pieces.size(); ++k) {
    const Piece& piece = pieces[k];
    if (!plane.components[piece.component].parent || piece.hole_of || piece.depth != 0) continue;
    duplicate[k] = std::any_of(pieces.begin(), pieces.end(), [&](const Piece& other) {
      return !plane.components[other.component].parent && other.label == piece.label &&
             same_points(other.ring, piece.ring);
    });
  }
  std::vector<Piece> kept;
  for (std::size_t k = 0; k < pieces.size(); ++k)
    if (!duplicate[k]) kept.push_back(std::move(pieces[k]));
  return kept;
}

// What a plane's components become before nesting: their rings cleaned and checked, those that
// cross themselves repaired into the rings they enclose (recorded), holes classified by label.
std::vector<Piece> make_pieces(const Plane& plane, const std::vector<Vec2>& points,
                               const LabeledSlice& slice, int n_labels,
                               const std::string& plane_name, detail::RepairLog& repairs) {
  std::vector<Piece> pieces;
  std::size_t dropped = 0;
  for (std::size_t c = 0; c < plane.components.size(); ++c) {
    const Component& comp = plane.components[c];
    const ComponentRole role = component_role(plane, c, n_labels, plane_name);
    Piece piece;
    piece.component = c;
    piece.label = role.label;
    piece.hole_of = role.cut ? comp.parent : std::nullopt;
    piece.name = role.name;
    for (std::size_t index : comp.indices) piece.ring.push_back(points[index]);
    dropped += detail::drop_repeated_points(piece.ring);
    const detail::RingCheck check = detail::check_ring(piece.ring);
    if (!check.problem.empty() && !check.self_intersects)
      fail(comp.line, plane_name + ", " + role.name + ": " + check.problem);
    if (!check.self_intersects) {
      pieces.push_back(std::move(piece));
      continue;
    }
    const detail::ContourRepair fixed = detail::repair_contour(piece.ring);
    repairs.add(plane_name, detail::self_intersection_repair(
                                plane_name + ", " + role.name,
                                world_text(slice.to_world(check.crossing)), fixed, role.cut));
    add_repaired_parts(plane, c, role, fixed, plane_name, pieces);
  }
  if (dropped)
    repairs.add(plane_name, {"repeated_points", plane_name,
                             "dropped " + std::to_string(dropped) + " repeated consecutive point" +
                                 (dropped > 1 ? "s" : ""),
                             0.0});
  return without_filled_duplicates(std::move(pieces), plane);
}

// Whether piece `region` has a hole with the points of `ring` (marked, or an unmarked piece of
// its label that it contains): files such as Abdomen write an organ twice, as a hole of the body
// (with the body's label) and as the organ's own contour.
bool has_hole_like(const std::vector<Piece>& pieces,
                   const std::vector<std::optional<std::size_t>>& container, std::size_t region,
                   const Ring2& ring) {
  for (std::size_t h = 0; h < pieces.size(); ++h) {
    const bool hole = pieces[h].parent == region || (!pieces[h].parent && container[h] == region &&
                                                     pieces[h].label == pieces[region].label);
    if (hole && same_points(pieces[h].ring, ring)) return true;
  }
  return false;
}

// Whether container `r` of a piece lies inside its container `current`: the smaller one does.
// Two containers bounding the same area (up to rounding of the areas) are one contour given twice,
// typically an organ and the hole of the body around it (Abdomen): the unmarked one, the organ,
// is the inner.
bool inner_container(const std::vector<Piece>& pieces, const std::vector<double>& areas,
                     std::size_t r, std::size_t current) {
  if (std::abs(areas[r] - areas[current]) > 1e-12 * areas[current])
    return areas[r] < areas[current];
  return !pieces[r].parent && pieces[current].parent;
}

// Resolves each marked hole to the part of its parent component that holds it.
void resolve_parents(std::vector<Piece>& pieces, const Plane& plane,
                     const std::string& plane_name) {
  for (Piece& piece : pieces) {
    if (!piece.hole_of) continue;
    std::vector<std::size_t> candidates;
    for (std::size_t q = 0; q < pieces.size(); ++q)
      if (pieces[q].component == *piece.hole_of && pieces[q].depth == 0) candidates.push_back(q);
    if (candidates.empty())
      fail(plane.components[piece.component].line,
           plane_name + ", " + piece.name + ": its parent, component " +
               std::to_string(*piece.hole_of) +
               ", encloses no area; remove the hole or fix its parent");
    piece.parent = candidates.front();
    for (std::size_t q : candidates)
      if (detail::ring_inside_ring(piece.ring, pieces[q].ring)) {
        piece.parent = q;
        break;
      }
  }
}

// Each unmarked piece's innermost container, and how many pieces contain it. Nesting, not
// orientation, decides what an unmarked piece is.
struct Containers {
  std::vector<std::optional<std::size_t>> innermost;
  std::vector<std::size_t> depth;
};

Containers find_containers(const std::vector<Piece>& pieces) {
  const std::size_t count = pieces.size();
  std::vector<detail::Box2> boxes(count);
  std::vector<double> areas(count);
  for (std::size_t c = 0; c < count; ++c) {
    boxes[c] = detail::box_of(pieces[c].ring);
    areas[c] = std::abs(signed_area(pieces[c].ring));
  }
  auto contains = [&](std::size_t outer, std::size_t inner) {
    if (outer == inner || !boxes[outer].contains(boxes[inner])) return false;
    if (areas[inner] > areas[outer] || (areas[inner] == areas[outer] && inner < outer))
      return false;
    // The same contour twice (an organ's pinched-off loop that the file also gives as a
    // component) bounds the same area: neither holds the other.
    if (areas[inner] == areas[outer] && same_points(pieces[inner].ring, pieces[outer].ring))
      return false;
    return detail::ring_inside_ring(pieces[inner].ring, pieces[outer].ring);
  };
  Containers out{std::vector<std::optional<std::size_t>>(count),
                 std::vector<std::size_t>(count, 0)};
  for (std::size_t c = 0; c < count; ++c) {
    if (pieces[c].parent) continue;
    for (std::size_t r = 0; r < count; ++r) {
      if (!contains(r, c)) continue;
      ++out.depth[c];
      if (!out.innermost[c] || inner_container(pieces, areas, r, *out.innermost[c]))
        out.innermost[c] = r;
    }
  }
  return out;
}

// What the nesting makes of the pieces: each is a region or a hole of a region piece, and
// regions of another material inside a region need a hole around them (islands).
struct Nesting {
  std::vector<bool> hole;
  std::vector<std::size_t> owner;                            // of a hole: its region piece
  std::vector<std::pair<std::size_t, std::size_t>> islands;  // (region piece, island)
};

Nesting nest(const std::vector<Piece>& pieces, const Plane& plane, const std::string& plane_name) {
  const std::size_t count = pieces.size();
  const Containers containers = find_containers(pieces);
  const auto& container = containers.innermost;
  Nesting out{std::vector<bool>(count, false), std::vector<std::size_t>(count, 0), {}};
  std::vector<std::size_t> order;
  for (std::size_t c = 0; c < count; ++c)
    if (!pieces[c].parent) order.push_back(c);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return containers.depth[a] < containers.depth[b];
  });
  for (std::size_t c : order) {
    if (!container[c]) continue;
    const std::size_t r = *container[c];
    if (pieces[r].parent || out.hole[r]) continue;  // in a hole: a region
    if (pieces[r].label == pieces[c].label) {
      out.hole[c] = true;  // a hole without its "h" marker
      out.owner[c] = r;
    } else if (!has_hole_like(pieces, container, r, pieces[c].ring)) {
      out.islands.emplace_back(r, c);  // another material inside r: r needs a hole around it
    }
  }
  for (std::size_t c = 0; c < count; ++c) {
    if (!pieces[c].parent) continue;
    const std::size_t p = *pieces[c].parent;
    if (out.hole[p])
      fail(plane.components[pieces[c].component].line,
           plane_name + ", " + pieces[c].name + ": marked as a hole of component " +
               std::to_string(pieces[p].component) + ", which lies inside component " +
               std::to_string(pieces[out.owner[p]].component) +
               " of the same label and so is a hole itself; fix the h marker");
    out.hole[c] = true;
    out.owner[c] = p;
  }
  return out;
}

// The slice's regions and holes from the nested pieces, named for messages in `names`.
void add_regions(const std::vector<Piece>& pieces, const Nesting& nesting, LabeledSlice& slice,
                 CslNaming::SliceNames& names) {
  std::vector<std::size_t> region_of(pieces.size(), 0);
  for (std::size_t c = 0; c < pieces.size(); ++c) {
    if (nesting.hole[c]) continue;
    region_of[c] = slice.regions.size();
    slice.regions.push_back(Region{pieces[c].label, pieces[c].ring, {}});
    names.regions.push_back(pieces[c].name);
    names.holes.emplace_back();
  }
  auto add_hole = [&](std::size_t region_piece, std::size_t hole, const std::string& name) {
    const std::size_t j = region_of[region_piece];
    slice.regions[j].holes.push_back(pieces[hole].ring);
    names.holes[j].push_back(name);
  };
  for (std::size_t c = 0; c < pieces.size(); ++c) {
    if (!nesting.hole[c]) continue;
    const std::size_t r = nesting.owner[c];
    add_hole(r, c,
             pieces[c].parent ? pieces[c].name
                              : pieces[c].name + " as a hole of component " +
                                    std::to_string(pieces[r].component));
  }
  for (const auto& [r, island] : nesting.islands)
    add_hole(
        r, island,
        pieces[island].name + " as a hole of component " + std::to_string(pieces[r].component));
}

// How a plane's equation related to its vertices, for the one warning of the file.
struct PlaneNote {
  long long index = 0;
  bool empty = false;
  bool refitted = false;
  bool flipped_d = false;
};

// Converts one plane into a slice; names the slice's regions and holes in `names` and adds how
// its equation fitted its vertices to `notes`.
LabeledSlice convert_plane(const Plane& plane, int n_labels, CslNaming::SliceNames& names,
                           std::vector<PlaneNote>& notes, detail::RepairLog& repairs) {
  const std::string plane_name =
      "plane " + std::to_string(plane.index) + " (line " + std::to_string(plane.line) + ")";
  names.slice = plane_name;
  const PlaneFit fit = fit_plane(plane, plane_name, repairs);
  notes.push_back({plane.index, plane.vertices.empty(), fit.refitted, fit.flipped_d});
  const Vec3& n = fit.n;

  LabeledSlice slice;
  plane_basis(n, slice.u, slice.v);
  if (plane.vertices.empty()) {
    slice.origin_mm = -fit.d * n;
    return slice;
  }
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& p : plane.vertices) centroid += p;
  centroid /= static_cast<double>(plane.vertices.size());
  slice.origin_mm = centroid - (n.dot(centroid) + fit.d) * n;

  std::vector<Vec2> points;
  points.reserve(plane.vertices.size());
  for (const Vec3& p : plane.vertices) points.push_back(slice.to_plane(p));
  std::vector<Piece> pieces = make_pieces(plane, points, slice, n_labels, plane_name, repairs);
  resolve_parents(pieces, plane, plane_name);
  const Nesting nesting = nest(pieces, plane, plane_name);
  add_regions(pieces, nesting, slice, names);
  return slice;
}

// "1..44, 46" from sorted plane indices.
std::string index_ranges(const std::vector<long long>& indices) {
  std::string text;
  for (std::size_t k = 0; k < indices.size();) {
    std::size_t end = k;
    while (end + 1 < indices.size() && indices[end + 1] == indices[end] + 1) ++end;
    text += (text.empty() ? "" : ", ") + std::to_string(indices[k]);
    if (end > k) text += ".." + std::to_string(indices[end]);
    k = end + 1;
  }
  return text;
}

// One repair for the whole file: a writer that flips D does it on every plane. When every plane
// with vertices satisfies the flipped equation, the empty planes (which have no vertices to tell)
// are taken to flip it too, and move to the other side of the origin.
void record_refits(const std::vector<PlaneNote>& notes, SliceSet& set, detail::RepairLog& repairs) {
  std::vector<long long> indices;
  bool all_flipped = true;
  std::size_t empty = 0;
  for (const PlaneNote& note : notes) {
    if (note.refitted) indices.push_back(note.index);
    if (!note.empty) all_flipped = all_flipped && note.flipped_d;
    empty += note.empty;
  }
  if (indices.empty()) return;
  std::sort(indices.begin(), indices.end());
  std::string detail = (indices.size() == 1 ? "plane " : "planes ") + index_ranges(indices) + " (" +
                       std::to_string(indices.size()) + " of " + std::to_string(notes.size()) +
                       "): the plane equation disagrees with its vertices" +
                       (all_flipped ? " (they satisfy Ax+By+Cz-D=0)" : "") +
                       "; fitted the plane to the vertices";
  if (all_flipped && empty) {
    for (std::size_t i = 0; i < notes.size(); ++i)
      if (notes[i].empty) set.slices[i].origin_mm = -set.slices[i].origin_mm;
    detail += "; read the " + std::to_string(empty) + " empty plane" + (empty == 1 ? "" : "s") +
              " (no vertices to tell) as Ax+By+Cz-D=0 too";
  }
  repairs.add("", {"plane_refit", "", detail, 0.0});
}

SliceSet parse_csl_text(const std::string& text, CslNaming& naming, detail::RepairLog& repairs,
                        int& n_labels_out) {
  Tokens tokens(text);
  const Token& magic = tokens.take("the header \"CSLC\"");
  if (magic.text != "CSLC")
    fail(magic.line, "expected the header \"CSLC\", got \"" + excerpt(magic.text) +
                         "\"; this is not a .csl contour file");
  const std::size_t counts_line = tokens.line();
  const long long n_planes = tokens.take_int("the plane count");
  const long long n_labels = tokens.take_int("the label count");
  if (n_planes < 0) fail(counts_line, "negative plane count");
  if (n_labels < 2 || n_labels > std::numeric_limits<int>::max())
    fail(counts_line, "nLabels = " + std::to_string(n_labels) +
                          " but it counts the outside too, so it must be at least 2");
  n_labels_out = static_cast<int>(n_labels);

  SliceSet set;
  std::vector<PlaneNote> notes;
  for (long long p = 0; p < n_planes; ++p) {
    const Plane plane = read_plane(tokens, static_cast<int>(n_labels));
    naming.names.emplace_back();
    set.slices.push_back(
        convert_plane(plane, static_cast<int>(n_labels), naming.names.back(), notes, repairs));
  }
  if (!tokens.done())
    fail(tokens.line(), "unexpected text after the last of the " + std::to_string(n_planes) +
                            " planes the header announces; fix the plane count");
  record_refits(notes, set, repairs);

  // Only materials that occur become labels: a header may declare more (nLabels = 20 with one
  // material used), and each label is a mesh to make.
  std::set<int> used;
  for (const LabeledSlice& s : set.slices)
    for (const Region& r : s.regions) used.insert(r.label);
  for (int id : used) set.labels.push_back({id, "label_" + std::to_string(id)});
  return set;
}

// A note, not a repair: nothing in the data changes, and --strict has nothing to refuse.
void warn_unused_labels(const SliceSet& set, int n_labels, const std::string& source_name) {
  // The gaps between the used ids, as ranges: a header may declare nLabels = 1e9, so the unused
  // ids are never listed one by one.
  std::string ranges;
  long long unused = 0;
  long long next = 1;
  auto add_gap = [&](long long first, long long last) {
    if (first > last) return;
    unused += last - first + 1;
    ranges += (ranges.empty() ? "" : ", ") + std::to_string(first);
    if (last > first) ranges += ".." + std::to_string(last);
  };
  for (const LabelInfo& label : set.labels) {
    add_gap(next, static_cast<long long>(label.id) - 1);
    next = static_cast<long long>(label.id) + 1;
  }
  add_gap(next, static_cast<long long>(n_labels) - 1);
  if (unused == 0) return;
  log_warning(source_name + ": the header declares materials 1.." + std::to_string(n_labels - 1) +
              " (nLabels = " + std::to_string(n_labels) + ") but " +
              (unused == 1 ? "material " : "materials ") + ranges + " never occur" +
              (unused == 1 ? "s" : "") + "; meshes are made only for the materials that do");
}

}  // namespace

Result<SliceSet> parse_csl(const std::string& text, const std::string& source_name,
                           const ReadOptions& options) {
  CslNaming naming;
  SliceSet set;
  detail::RepairLog repairs(source_name, options);
  int n_labels = 0;
  try {
    set = parse_csl_text(text, naming, repairs, n_labels);
  } catch (const InputError& problem) {  // a parse problem, or a repair refused under strict
    return Status::error(problem.message_in(source_name));
  }
  Result<SliceSet> result = detail::finish_parsed_set(std::move(set), source_name, naming, repairs);
  if (result) warn_unused_labels(*result, n_labels, source_name);
  return result;
}

Status write_csl(const SliceSet& set, const std::filesystem::path& path) {
  const std::string refuse = "cannot write " + path.string() + " as .csl: ";
  int max_label = 1;
  for (const LabelInfo& l : set.labels) max_label = std::max(max_label, l.id);
  for (std::size_t i = 0; i < set.slices.size(); ++i) {
    const LabeledSlice& s = set.slices[i];
    if (s.fov)
      return Status::error(refuse + "slice " + std::to_string(i) +
                           " has a field of view (fov), which .csl cannot hold; write a "
                           ".slices.json file instead");
    for (std::size_t j = 0; j < s.regions.size(); ++j) {
      const Region& r = s.regions[j];
      if (r.label == kUnknownLabel)
        return Status::error(refuse + "slice " + std::to_string(i) + ", region " +
                             std::to_string(j) +
                             " is unknown, which .csl cannot hold; write a .slices.json file "
                             "instead");
      if (r.label < 1)
        return Status::error(refuse + "slice " + std::to_string(i) + ", region " +
                             std::to_string(j) + " has label " + std::to_string(r.label) +
                             "; .csl components need material labels >= 1");
      max_label = std::max(max_label, r.label);
    }
  }

  auto num = [](double x) { return detail::format_double(x); };
  std::string out =
      "CSLC\n" + std::to_string(set.slices.size()) + " " + std::to_string(max_label + 1) + "\n";
  for (std::size_t i = 0; i < set.slices.size(); ++i) {
    const LabeledSlice& s = set.slices[i];
    const Vec3 n = s.normal().normalized();
    if (!n.allFinite() || !s.origin_mm.allFinite())
      return Status::error(refuse + "slice " + std::to_string(i) +
                           " has no valid plane (u and v must be finite and span a plane)");
    std::size_t n_vertices = 0;
    std::size_t n_components = 0;
    for (const Region& r : s.regions) {
      n_vertices += r.outer.size();
      n_components += 1 + r.holes.size();
      for (const Ring2& h : r.holes) n_vertices += h.size();
    }
    out += "\n" + std::to_string(i + 1) + " " + std::to_string(n_vertices) + " " +
           std::to_string(n_components) + " " + num(n.x()) + " " + num(n.y()) + " " + num(n.z()) +
           " " + num(-n.dot(s.origin_mm)) + "\n";

    // Orientation seen from the normal u x v is orientation in (u, v): outer CCW, holes CW.
    std::vector<Ring2> rings;
    std::vector<std::string> heads;
    for (const Region& r : s.regions) {
      const std::size_t parent = rings.size();
      Ring2 outer = r.outer;
      if (signed_area(outer) < 0.0) std::reverse(outer.begin(), outer.end());
      heads.push_back(std::to_string(outer.size()) + " " + std::to_string(r.label));
      rings.push_back(std::move(outer));
      for (const Ring2& h : r.holes) {
        Ring2 hole = h;
        if (signed_area(hole) > 0.0) std::reverse(hole.begin(), hole.end());
        heads.push_back(std::to_string(hole.size()) + "h" + std::to_string(parent) + " " +
                        std::to_string(r.label));
        rings.push_back(std::move(hole));
      }
    }
    for (const Ring2& ring : rings)
      for (const Vec2& p : ring) {
        const Vec3 w = s.to_world(p);
        if (!w.allFinite())
          return Status::error(refuse + "slice " + std::to_string(i) +
                               " holds NaN or infinite coordinates");
        out += num(w.x()) + " " + num(w.y()) + " " + num(w.z()) + "\n";
      }
    std::size_t next_index = 0;
    for (std::size_t c = 0; c < rings.size(); ++c) {
      out += heads[c];
      for (std::size_t k = 0; k < rings[c].size(); ++k) out += " " + std::to_string(next_index++);
      out += "\n";
    }
  }
  return detail::write_text_file(path, out);
}

}  // namespace sonoshape
