// `.csl` contour-slice files (docs/formats/csl.md): reading into a SliceSet and writing one.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <optional>
#include <string_view>

#include "slice_io_internal.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_io.hpp"

namespace sonoshape {
namespace {

// Thrown inside the parser only; parse_csl turns it into a Status.
struct CslProblem {
  std::string what;
};

[[noreturn]] void fail(std::size_t line, const std::string& what) {
  throw CslProblem{"line " + std::to_string(line) + ": " + what};
}

struct Token {
  std::string_view text;
  std::size_t line = 0;
};

// Whitespace-separated tokens with their line numbers; blank lines are simply skipped.
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
           std::string("expected ") + what + " (an integer), got \"" + std::string(t.text) + "\"");
    return value;
  }

  double take_double(const char* what) {
    const Token& t = take(what);
    double value = 0.0;
    const char* first = t.text.data();
    if (!t.text.empty() && t.text.front() == '+') ++first;  // from_chars refuses a leading '+'
    const auto [end, ec] = std::from_chars(first, t.text.data() + t.text.size(), value);
    if (ec != std::errc() || end != t.text.data() + t.text.size() || !std::isfinite(value))
      fail(t.line, std::string("expected ") + what + " (a finite number), got \"" +
                       std::string(t.text) + "\"");
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
  plane.vertices.reserve(static_cast<std::size_t>(n_vertices));
  for (long long k = 0; k < n_vertices; ++k) {
    Vec3 p;
    p.x() = tokens.take_double("a vertex x");
    p.y() = tokens.take_double("a vertex y");
    p.z() = tokens.take_double("a vertex z");
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
                               std::string(text) + "\"");
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
    const long long label = tokens.take_int("a component label");
    if (label == 0)
      fail(component.line, where +
                               ": label 0 is the outside in .csl; components carry material "
                               "labels 1.." +
                               std::to_string(n_labels - 1) +
                               ". If the file numbers materials from 0, add 1 to every "
                               "component label and to nLabels");
    if (label < 0 || label >= n_labels)
      fail(component.line, where + ": label " + std::to_string(label) + " is outside 1.." +
                               std::to_string(n_labels - 1) +
                               " (the header says nLabels = " + std::to_string(n_labels) +
                               ", which counts the outside); fix the label or the header");
    component.label = static_cast<int>(label);
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

struct Box2 {
  Vec2 lo, hi;
  bool contains(const Box2& other) const {
    return (lo.array() <= other.lo.array()).all() && (hi.array() >= other.hi.array()).all();
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

// Converts one plane into a slice; names the slice's regions and holes in `names`.
LabeledSlice convert_plane(const Plane& plane, CslNaming::SliceNames& names,
                           detail::RepairLog& repairs) {
  const std::string plane_name =
      "plane " + std::to_string(plane.index) + " (line " + std::to_string(plane.line) + ")";
  names.slice = plane_name;
  const double abc_norm = plane.abc.norm();
  if (!(abc_norm > 0.0))
    fail(plane.line, "plane " + std::to_string(plane.index) +
                         ": the normal (A, B, C) is zero, so this is not a plane");
  const Vec3 n = plane.abc / abc_norm;
  const double d = plane.d / abc_norm;

  LabeledSlice slice;
  plane_basis(n, slice.u, slice.v);
  if (plane.vertices.empty()) {
    slice.origin_mm = -d * n;
    return slice;
  }

  Vec3 centroid = Vec3::Zero();
  Vec3 lo = plane.vertices.front();
  Vec3 hi = lo;
  for (const Vec3& p : plane.vertices) {
    centroid += p;
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  centroid /= static_cast<double>(plane.vertices.size());
  slice.origin_mm = centroid - (n.dot(centroid) + d) * n;

  // Vertices slightly off the plane are projected (datasets round their coordinates); far off
  // means the plane equation and the vertices disagree, which we refuse to guess about.
  const double extent = (hi - lo).norm();
  double max_off = 0.0;
  std::size_t worst = 0;
  for (std::size_t k = 0; k < plane.vertices.size(); ++k) {
    const double off = std::abs(n.dot(plane.vertices[k]) + d);
    if (off > max_off) {
      max_off = off;
      worst = k;
    }
  }
  const double scale = std::max({extent, hi.cwiseAbs().maxCoeff(), lo.cwiseAbs().maxCoeff()});
  if (max_off > 1e-3 * extent && max_off > 1e-9 * scale)
    fail(plane.line, plane_name + ": vertex " + std::to_string(worst) + " lies " +
                         detail::format_double(max_off) +
                         " off the plane, more than 1e-3 of the plane's extent (" +
                         detail::format_double(extent) +
                         "); check the plane's A B C D or its vertices");
  if (max_off > 1e-9 * scale)
    repairs.add(plane_name, {"off_plane_vertices", plane_name,
                             "vertices lie up to " + detail::format_double(max_off) +
                                 " off the plane; projected onto it",
                             0.0});

  std::vector<Vec2> points;
  points.reserve(plane.vertices.size());
  for (const Vec3& p : plane.vertices) points.push_back(slice.to_plane(p));

  // Rings of every component, cleaned and checked before nesting is worked out.
  const std::size_t count = plane.components.size();
  std::vector<Ring2> rings(count);
  std::vector<std::string> component_names(count);
  std::size_t dropped = 0;
  for (std::size_t c = 0; c < count; ++c) {
    const Component& comp = plane.components[c];
    component_names[c] = "component " + std::to_string(c) + " (line " + std::to_string(comp.line) +
                         ", label " + std::to_string(comp.label) + ")";
    for (std::size_t index : comp.indices) rings[c].push_back(points[index]);
    dropped += detail::drop_repeated_points(rings[c]);
    const std::string problem = detail::ring_problem(rings[c]);
    if (!problem.empty()) fail(comp.line, plane_name + ", " + component_names[c] + ": " + problem);
  }
  if (dropped)
    repairs.add(plane_name, {"repeated_points", plane_name,
                             "dropped " + std::to_string(dropped) + " repeated consecutive point" +
                                 (dropped > 1 ? "s" : ""),
                             0.0});

  for (std::size_t c = 0; c < count; ++c) {
    const Component& comp = plane.components[c];
    if (comp.parent && plane.components[*comp.parent].parent)
      fail(comp.line, plane_name + ", " + component_names[c] + ": marked as a hole of component " +
                          std::to_string(*comp.parent) +
                          ", which is itself a hole; a hole's parent must be an outer contour");
  }

  // Nesting, not orientation, decides what an unmarked component is: its innermost container.
  std::vector<Box2> boxes(count);
  std::vector<double> areas(count);
  for (std::size_t c = 0; c < count; ++c) {
    boxes[c] = box_of(rings[c]);
    areas[c] = std::abs(signed_area(rings[c]));
  }
  auto contains = [&](std::size_t outer, std::size_t inner) {
    if (outer == inner || !boxes[outer].contains(boxes[inner])) return false;
    if (areas[inner] > areas[outer] || (areas[inner] == areas[outer] && inner < outer))
      return false;
    return detail::ring_inside_ring(rings[inner], rings[outer]);
  };
  std::vector<std::optional<std::size_t>> container(count);
  std::vector<std::size_t> depth(count, 0);
  for (std::size_t c = 0; c < count; ++c) {
    if (plane.components[c].parent) continue;
    for (std::size_t r = 0; r < count; ++r) {
      if (!contains(r, c)) continue;
      ++depth[c];
      if (!container[c] || areas[r] < areas[*container[c]]) container[c] = r;
    }
  }

  enum class Role { kRegion, kHole };
  std::vector<Role> role(count, Role::kRegion);
  std::vector<std::size_t> owner(count, 0);  // the region component a hole belongs to
  std::vector<std::size_t> order;
  for (std::size_t c = 0; c < count; ++c)
    if (!plane.components[c].parent) order.push_back(c);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return depth[a] < depth[b]; });
  std::vector<std::pair<std::size_t, std::size_t>> islands;  // (region component, island)
  for (std::size_t c : order) {
    if (!container[c]) continue;
    const std::size_t r = *container[c];
    if (plane.components[r].parent || role[r] == Role::kHole) continue;  // in a hole: a region
    if (plane.components[r].label == plane.components[c].label) {
      role[c] = Role::kHole;  // a hole without its "h" marker
      owner[c] = r;
    } else {
      islands.emplace_back(r, c);  // another material inside r: r needs a hole around it
    }
  }
  for (std::size_t c = 0; c < count; ++c) {
    if (!plane.components[c].parent) continue;
    const std::size_t p = *plane.components[c].parent;
    if (role[p] == Role::kHole)
      fail(plane.components[c].line,
           plane_name + ", " + component_names[c] + ": marked as a hole of component " +
               std::to_string(p) + ", which lies inside component " + std::to_string(owner[p]) +
               " of the same label and so is a hole itself; fix the h marker");
    role[c] = Role::kHole;
    owner[c] = p;
  }

  std::vector<std::size_t> region_of(count, 0);
  for (std::size_t c = 0; c < count; ++c) {
    if (role[c] != Role::kRegion) continue;
    region_of[c] = slice.regions.size();
    Region region;
    region.label = plane.components[c].label;
    region.outer = rings[c];
    slice.regions.push_back(std::move(region));
    names.regions.push_back(component_names[c]);
    names.holes.emplace_back();
  }
  for (std::size_t c = 0; c < count; ++c) {
    if (role[c] != Role::kHole) continue;
    const std::size_t j = region_of[owner[c]];
    slice.regions[j].holes.push_back(rings[c]);
    names.holes[j].push_back("component " + std::to_string(c) + " (line " +
                             std::to_string(plane.components[c].line) + ", hole of component " +
                             std::to_string(owner[c]) + ")");
  }
  for (const auto& [r, island] : islands) {
    const std::size_t j = region_of[r];
    slice.regions[j].holes.push_back(rings[island]);
    names.holes[j].push_back("component " + std::to_string(island) + " (line " +
                             std::to_string(plane.components[island].line) +
                             ") as a hole of component " + std::to_string(r));
  }
  return slice;
}

SliceSet parse_csl_text(const std::string& text, CslNaming& naming, detail::RepairLog& repairs) {
  Tokens tokens(text);
  const Token& magic = tokens.take("the header \"CSLC\"");
  if (magic.text != "CSLC")
    fail(magic.line, "expected the header \"CSLC\", got \"" + std::string(magic.text) +
                         "\"; this is not a .csl contour file");
  const std::size_t counts_line = tokens.line();
  const long long n_planes = tokens.take_int("the plane count");
  const long long n_labels = tokens.take_int("the label count");
  if (n_planes < 0) fail(counts_line, "negative plane count");
  if (n_labels < 2 || n_labels > std::numeric_limits<int>::max())
    fail(counts_line, "nLabels = " + std::to_string(n_labels) +
                          " but it counts the outside too, so it must be at least 2");

  SliceSet set;
  for (int id = 1; id < n_labels; ++id) set.labels.push_back({id, "label_" + std::to_string(id)});
  for (long long p = 0; p < n_planes; ++p) {
    const Plane plane = read_plane(tokens, static_cast<int>(n_labels));
    naming.names.emplace_back();
    set.slices.push_back(convert_plane(plane, naming.names.back(), repairs));
  }
  if (!tokens.done())
    fail(tokens.line(), "unexpected text after the last of the " + std::to_string(n_planes) +
                            " planes the header announces; fix the plane count");
  return set;
}

}  // namespace

Result<SliceSet> parse_csl(const std::string& text, const std::string& source_name,
                           const ReadOptions& options) {
  CslNaming naming;
  SliceSet set;
  detail::RepairLog repairs(source_name, options);
  try {
    set = parse_csl_text(text, naming, repairs);
  } catch (const CslProblem& problem) {
    return Status::error(source_name + ": " + problem.what);
  } catch (const detail::RepairRefused& refused) {
    return Status::error(refused.message);
  }
  return detail::finish_parsed_set(std::move(set), source_name, naming, repairs);
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
