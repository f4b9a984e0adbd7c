// Slice-set JSON (docs/formats/slices.md): the parser, which repairs what the format allows and
// hands the set to the validation rules (slice_rules.hpp), and the writer.
#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "repair_log.hpp"
#include "ring_checks.hpp"
#include "ring_repair.hpp"
#include "slice_rules.hpp"
#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/log.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "text_io.hpp"

namespace sonoshape {

// ---------------------------------------------------------------------------------------------
// JSON

namespace {

using nlohmann::json;

// Problems are thrown as InputError inside the parser only; parse_slice_set_json and
// parse_slice_json turn them into a Status.
[[noreturn]] void fail_at(const std::string& where, const std::string& what) {
  throw InputError(where, what);
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

double read_coordinate(const json& j, const std::string& where) {
  const double value = read_number(j, where);
  if (std::abs(value) > detail::kMaxCoordinateMm)
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
  // Appended piece by piece: GCC 12 at -O3 flags `"[" + std::string` with a false -Wrestrict.
  std::string text = "[";
  text += detail::format_short(p.x());
  text += ", ";
  text += detail::format_short(p.y());
  text += "]";
  return text;
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
  warn_unknown_keys(js, {"origin", "u", "v", "timestamp", "outline_sd_mm", "fov", "regions"},
                    source_name, where, also_known);
  for (const char* key : {"origin", "u", "v"})
    if (!js.contains(key)) fail_at(where, std::string("\"") + key + "\" is missing");
  LabeledSlice s;
  s.origin_mm = read_vec3(js["origin"], where + ", origin");
  if (s.origin_mm.cwiseAbs().maxCoeff() > detail::kMaxCoordinateMm)
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
  if (const auto sd = js.find("outline_sd_mm"); sd != js.end() && !sd->is_null()) {
    s.outline_sd_mm = read_number(*sd, where + ", outline_sd_mm");
    if (s.outline_sd_mm < 0.0)
      fail_at(where + ", outline_sd_mm",
              "a negative standard deviation; write 0 for exact outlines or the outlines' error "
              "in mm");
  }
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
      if (const auto shadow = entry.find("casts_shadow"); shadow != entry.end()) {
        if (!shadow->is_boolean())
          fail_at(where, "\"casts_shadow\" is " + short_dump(*shadow) +
                             ", not true or false; write true for a material that shadows what "
                             "lies beyond it (bone), or leave the key out");
        info.casts_shadow = shadow->get<bool>();
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
  std::string text = "[";  // piece by piece, as plane_point_text
  text += detail::format_double(v.x());
  text += ", ";
  text += detail::format_double(v.y());
  text += ", ";
  text += detail::format_double(v.z());
  text += "]";
  return text;
}

// One slice object. The file form breaks lines before fov, regions and each region; one_line
// keeps it on a single line (messages, JSON lines).
void append_slice_object(std::string& out, const LabeledSlice& s, bool one_line) {
  const char* field_break = one_line ? ", " : ",\n     ";
  out += "{\"origin\": " + vec3_json(s.origin_mm) + ", \"u\": " + vec3_json(s.u) +
         ", \"v\": " + vec3_json(s.v);
  if (s.timestamp_s) out += ", \"timestamp\": " + detail::format_double(*s.timestamp_s);
  if (s.outline_sd_mm > 0.0)
    out += ", \"outline_sd_mm\": " + detail::format_double(s.outline_sd_mm);
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
    if (!std::isfinite(s.outline_sd_mm)) return false;
    if (s.fov && !ring_ok(*s.fov)) return false;
    for (const Region& r : s.regions) {
      if (!ring_ok(r.outer)) return false;
      if (!std::all_of(r.holes.begin(), r.holes.end(), ring_ok)) return false;
    }
  }
  return true;
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
  } catch (const InputError& p) {  // a parse problem, or a repair refused under strict
    return Status::error(p.message_in(source_name));
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
             ", \"name\": " + json(set.labels[k].name).dump() +
             (set.labels[k].casts_shadow ? ", \"casts_shadow\": true}" : "}");
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
  } catch (const InputError& p) {
    return Status::error(p.message_in(source_name));
  } catch (const json::exception& e) {
    return Status::error(source_name + ": malformed slice (" + std::string(e.what()) + ")");
  }
  if (Status status = detail::validate_slice_set_named(set, source_name, naming, nullptr); !status)
    return status;
  repairs.finish();
  return std::move(set.slices.front());
}

}  // namespace sonoshape
