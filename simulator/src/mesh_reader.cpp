#include "sonoshape/simulator/mesh_reader.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "sonoshape/core/input_file.hpp"

namespace sonoshape::sim {
namespace {

// Parse failures carry the element (line, vertex, face) they concern; read_mesh adds the file.
struct ParseError {
  std::string message;
};

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const std::size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

bool parse_double(std::string_view word, double& value) {
  // from_chars for double rejects a leading '+', which some exporters write.
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), value);
  return ec == std::errc() && end == word.data() + word.size() && std::isfinite(value);
}

bool parse_long(std::string_view word, long long& value) {
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), value);
  return ec == std::errc() && end == word.data() + word.size();
}

// Splits text into lines, keeping 1-based line numbers for messages.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : text_(text) {}
  bool next(std::string_view& line) {
    if (pos_ >= text_.size()) return false;
    std::size_t end = text_.find('\n', pos_);
    if (end == std::string_view::npos) end = text_.size();
    line = text_.substr(pos_, end - pos_);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos_ = end < text_.size() ? end + 1 : end;  // a last line without '\n' ends at the end
    ++number_;
    return true;
  }
  int number() const { return number_; }
  std::size_t position() const { return pos_; }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  int number_ = 0;
};

// Appends a polygon as a triangle fan after checking its indices.
void add_polygon(TriangleMesh& mesh, const std::vector<long long>& polygon,
                 std::size_t vertex_count, const std::string& where) {
  if (polygon.size() < 3)
    throw ParseError{where + ": a face needs at least 3 vertices, got " +
                     std::to_string(polygon.size())};
  for (long long index : polygon)
    if (index < 0 || static_cast<std::size_t>(index) >= vertex_count)
      throw ParseError{where + ": vertex index " + std::to_string(index) +
                       " out of range (the file has " + std::to_string(vertex_count) +
                       " vertices so far)"};
  for (std::size_t k = 1; k + 1 < polygon.size(); ++k)
    mesh.triangles.push_back({static_cast<std::uint32_t>(polygon[0]),
                              static_cast<std::uint32_t>(polygon[k]),
                              static_cast<std::uint32_t>(polygon[k + 1])});
}

TriangleMesh parse_obj(std::string_view text) {
  TriangleMesh mesh;
  LineReader lines(text);
  std::string_view line;
  std::vector<long long> polygon;
  while (lines.next(line)) {
    const auto words = split_words(line);
    if (words.empty() || words[0].front() == '#') continue;
    const std::string where = "line " + std::to_string(lines.number());
    if (words[0] == "v") {
      Vec3 p;
      if (words.size() < 4) throw ParseError{where + ": a vertex needs x y z"};
      for (int k = 0; k < 3; ++k)
        if (!parse_double(words[k + 1], p[k]))
          throw ParseError{where + ": bad vertex coordinate '" + std::string(words[k + 1]) + "'"};
      mesh.vertices.push_back(p);
    } else if (words[0] == "f") {
      polygon.clear();
      for (std::size_t k = 1; k < words.size(); ++k) {
        // "a", "a/b", "a//c", "a/b/c": only the position index matters.
        const std::string_view word = words[k].substr(0, words[k].find('/'));
        long long index = 0;
        if (!parse_long(word, index) || index == 0)
          throw ParseError{where + ": bad face index '" + std::string(words[k]) + "'"};
        // OBJ indices are 1-based; negative ones count back from the last vertex read.
        polygon.push_back(index > 0 ? index - 1
                                    : static_cast<long long>(mesh.vertices.size()) + index);
      }
      add_polygon(mesh, polygon, mesh.vertices.size(), where);
    }
    // Texture coordinates, normals, groups, materials and lines are not geometry we need.
  }
  return mesh;
}

TriangleMesh parse_off(std::string_view text) {
  TriangleMesh mesh;
  LineReader lines(text);
  std::string_view line;
  // The OFF header may share its line with the counts ("OFF 8 6 0"); comments start with '#'.
  std::vector<std::string_view> tokens;
  std::vector<int> token_lines;
  while (lines.next(line)) {
    const std::size_t hash = line.find('#');
    for (std::string_view w : split_words(line.substr(0, hash))) {
      tokens.push_back(w);
      token_lines.push_back(lines.number());
    }
  }
  std::size_t t = 0;
  if (tokens.empty() || (tokens[0] != "OFF" && tokens[0] != "COFF" && tokens[0] != "NOFF"))
    throw ParseError{"line 1: expected the OFF header"};
  ++t;
  auto where = [&](std::size_t k) {
    return "line " + std::to_string(token_lines[std::min(k, token_lines.size() - 1)]);
  };
  auto next_long = [&](const char* what) {
    long long value = 0;
    if (t >= tokens.size()) throw ParseError{where(t) + ": file ends before " + what};
    if (!parse_long(tokens[t], value))
      throw ParseError{where(t) + ": bad " + what + " '" + std::string(tokens[t]) + "'"};
    ++t;
    return value;
  };
  const long long vertex_count = next_long("vertex count");
  const long long face_count = next_long("face count");
  next_long("edge count");
  if (vertex_count < 0 || face_count < 0) throw ParseError{where(t) + ": negative element count"};
  const bool colored = tokens[0] == "COFF";
  const bool with_normals = tokens[0] == "NOFF";
  // A corrupt count must not reserve more than the file can hold.
  mesh.vertices.reserve(
      std::min<std::size_t>(static_cast<std::size_t>(vertex_count), text.size() / 3));
  for (long long i = 0; i < vertex_count; ++i) {
    Vec3 p;
    for (int k = 0; k < 3; ++k) {
      if (t >= tokens.size()) throw ParseError{"vertex " + std::to_string(i) + ": file ends early"};
      if (!parse_double(tokens[t], p[k]))
        throw ParseError{where(t) + ": vertex " + std::to_string(i) + ": bad coordinate '" +
                         std::string(tokens[t]) + "'"};
      ++t;
    }
    t += colored ? 4 : with_normals ? 3 : 0;
    mesh.vertices.push_back(p);
  }
  std::vector<long long> polygon;
  for (long long f = 0; f < face_count; ++f) {
    const std::size_t line_token = t;
    const long long n = next_long("face size");
    const int line_number = token_lines[std::min(line_token, token_lines.size() - 1)];
    polygon.clear();
    for (long long k = 0; k < n; ++k) polygon.push_back(next_long("face index"));
    // Optional per-face colour values follow on the same line: skip them.
    while (t < tokens.size() && token_lines[t] == line_number) ++t;
    add_polygon(mesh, polygon, mesh.vertices.size(),
                "line " + std::to_string(line_number) + ", face " + std::to_string(f));
  }
  return mesh;
}

// ---- PLY ----------------------------------------------------------------------------------

enum class PlyType { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

PlyType parse_ply_type(std::string_view name, const std::string& where) {
  if (name == "char" || name == "int8") return PlyType::kInt8;
  if (name == "uchar" || name == "uint8") return PlyType::kUInt8;
  if (name == "short" || name == "int16") return PlyType::kInt16;
  if (name == "ushort" || name == "uint16") return PlyType::kUInt16;
  if (name == "int" || name == "int32") return PlyType::kInt32;
  if (name == "uint" || name == "uint32") return PlyType::kUInt32;
  if (name == "float" || name == "float32") return PlyType::kFloat32;
  if (name == "double" || name == "float64") return PlyType::kFloat64;
  throw ParseError{where + ": unknown PLY type '" + std::string(name) + "'"};
}

std::size_t ply_type_size(PlyType type) {
  switch (type) {
    case PlyType::kInt8:
    case PlyType::kUInt8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUInt16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUInt32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;
  bool is_list = false;
  PlyType count_type = PlyType::kUInt8;
};

struct PlyElement {
  std::string name;
  std::size_t count = 0;
  std::vector<PlyProperty> properties;
};

// Reads scalars from the body of a PLY file, ascii or binary little-endian.
class PlyBody {
 public:
  PlyBody(std::string_view body, bool ascii) : body_(body), ascii_(ascii) {}

  double read(PlyType type, const std::string& where) {
    if (ascii_) return read_ascii(where);
    const std::size_t size = ply_type_size(type);
    if (pos_ + size > body_.size()) throw ParseError{where + ": file ends early"};
    const char* p = body_.data() + pos_;
    pos_ += size;
    static_assert(std::endian::native == std::endian::little,
                  "the binary PLY reader assumes a little-endian host");
    switch (type) {
      case PlyType::kInt8:
        return load<std::int8_t>(p);
      case PlyType::kUInt8:
        return load<std::uint8_t>(p);
      case PlyType::kInt16:
        return load<std::int16_t>(p);
      case PlyType::kUInt16:
        return load<std::uint16_t>(p);
      case PlyType::kInt32:
        return load<std::int32_t>(p);
      case PlyType::kUInt32:
        return load<std::uint32_t>(p);
      case PlyType::kFloat32:
        return load<float>(p);
      case PlyType::kFloat64:
        return load<double>(p);
    }
    return 0.0;
  }

 private:
  template <typename T>
  static double load(const char* p) {
    T value;
    std::memcpy(&value, p, sizeof(T));
    return static_cast<double>(value);
  }

  double read_ascii(const std::string& where) {
    while (pos_ < body_.size() && std::isspace(static_cast<unsigned char>(body_[pos_]))) ++pos_;
    const std::size_t start = pos_;
    while (pos_ < body_.size() && !std::isspace(static_cast<unsigned char>(body_[pos_]))) ++pos_;
    if (start == pos_) throw ParseError{where + ": file ends early"};
    double value = 0.0;
    if (!parse_double(body_.substr(start, pos_ - start), value))
      throw ParseError{where + ": bad number '" + std::string(body_.substr(start, pos_ - start)) +
                       "'"};
    return value;
  }

  std::string_view body_;
  bool ascii_;
  std::size_t pos_ = 0;
};

TriangleMesh parse_ply(std::string_view text) {
  LineReader lines(text);
  std::string_view line;
  if (!lines.next(line) || line != "ply") throw ParseError{"line 1: expected 'ply'"};
  bool ascii = false;
  bool have_format = false;
  std::vector<PlyElement> elements;
  bool header_done = false;
  while (lines.next(line)) {
    const auto words = split_words(line);
    const std::string where = "header line " + std::to_string(lines.number());
    if (words.empty() || words[0] == "comment" || words[0] == "obj_info") continue;
    if (words[0] == "end_header") {
      header_done = true;
      break;
    }
    if (words[0] == "format") {
      if (words.size() < 2) throw ParseError{where + ": incomplete format line"};
      if (words[1] == "ascii")
        ascii = true;
      else if (words[1] == "binary_little_endian")
        ascii = false;
      else
        throw ParseError{where + ": PLY format '" + std::string(words[1]) +
                         "' is not supported (use ascii or binary_little_endian)"};
      have_format = true;
    } else if (words[0] == "element") {
      long long count = 0;
      if (words.size() < 3 || !parse_long(words[2], count) || count < 0)
        throw ParseError{where + ": bad element line"};
      elements.push_back({std::string(words[1]), static_cast<std::size_t>(count), {}});
    } else if (words[0] == "property") {
      if (elements.empty()) throw ParseError{where + ": property before any element"};
      PlyProperty property;
      if (words.size() >= 5 && words[1] == "list") {
        property.is_list = true;
        property.count_type = parse_ply_type(words[2], where);
        property.type = parse_ply_type(words[3], where);
        property.name = words[4];
      } else if (words.size() >= 3) {
        property.type = parse_ply_type(words[1], where);
        property.name = words[2];
      } else {
        throw ParseError{where + ": bad property line"};
      }
      elements.back().properties.push_back(property);
    } else {
      throw ParseError{where + ": unexpected '" + std::string(words[0]) + "'"};
    }
  }
  if (!header_done) throw ParseError{"header: no end_header"};
  if (!have_format) throw ParseError{"header: no format line"};

  TriangleMesh mesh;
  PlyBody body(text.substr(lines.position()), ascii);
  bool have_vertices = false;
  std::vector<long long> polygon;
  for (const PlyElement& element : elements) {
    const bool is_vertex = element.name == "vertex";
    const bool is_face = element.name == "face";
    int xyz[3] = {-1, -1, -1};
    int index_list = -1;
    for (std::size_t k = 0; k < element.properties.size(); ++k) {
      const PlyProperty& p = element.properties[k];
      if (is_vertex && !p.is_list && p.name.size() == 1 && p.name[0] >= 'x' && p.name[0] <= 'z')
        xyz[p.name[0] - 'x'] = static_cast<int>(k);
      if (is_face && p.is_list && (p.name == "vertex_indices" || p.name == "vertex_index"))
        index_list = static_cast<int>(k);
    }
    if (is_vertex) {
      if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0)
        throw ParseError{"header: element vertex lacks an x, y or z property"};
      have_vertices = true;
      // A corrupt count must not reserve more than the file can hold.
      mesh.vertices.reserve(std::min<std::size_t>(element.count, text.size() / 3));
    }
    if (is_face && index_list < 0)
      throw ParseError{"header: element face lacks a vertex_indices list"};
    // An element without properties occupies no bytes, so its count cannot be checked against
    // the file and there is nothing to read: `element edge 9223372036854775807` alone would
    // otherwise be a loop of 2^63 empty steps.
    if (element.properties.empty()) continue;
    for (std::size_t i = 0; i < element.count; ++i) {
      const std::string where = element.name + " " + std::to_string(i);
      Vec3 p = Vec3::Zero();
      for (std::size_t k = 0; k < element.properties.size(); ++k) {
        const PlyProperty& property = element.properties[k];
        if (!property.is_list) {
          const double value = body.read(property.type, where);
          if (is_vertex)
            for (int axis = 0; axis < 3; ++axis)
              if (xyz[axis] == static_cast<int>(k)) p[axis] = value;
          continue;
        }
        const double n = body.read(property.count_type, where);
        if (n < 0 || n != std::floor(n)) throw ParseError{where + ": bad list length"};
        const bool wanted = is_face && static_cast<int>(k) == index_list;
        if (wanted) polygon.clear();
        for (long long j = 0; j < static_cast<long long>(n); ++j) {
          const double value = body.read(property.type, where);
          if (wanted) polygon.push_back(static_cast<long long>(value));
        }
        if (wanted) {
          if (!have_vertices)
            throw ParseError{"header: faces come before vertices, which this reader needs first"};
          add_polygon(mesh, polygon, mesh.vertices.size(), where);
        }
      }
      if (is_vertex) {
        if (!p.allFinite()) throw ParseError{where + ": coordinate is not finite"};
        mesh.vertices.push_back(p);
      }
    }
  }
  if (!have_vertices) throw ParseError{"header: no vertex element"};
  return mesh;
}

// ---- STL ----------------------------------------------------------------------------------

// STL stores every facet with its own three corners and no indices. Corners with identical
// coordinates (exact equality of the numbers as read, float for binary, double for ASCII; -0 and
// +0 are one value) become one vertex, so a mesh that is closed in the source is closed here.
// No tolerance: welding near-equal corners would join surfaces the source keeps apart. Facet
// normals are ignored (the corner order gives the orientation) and so are binary attribute bytes.
class StlWelder {
 public:
  // Adds a facet; one whose corners weld into fewer than three vertices has no area and is
  // dropped (it would only make edges look non-manifold).
  void add_facet(const std::array<Vec3, 3>& corners) {
    std::array<std::uint32_t, 3> triangle{};
    for (int k = 0; k < 3; ++k) triangle[k] = vertex(corners[k]);
    if (triangle[0] == triangle[1] || triangle[1] == triangle[2] || triangle[0] == triangle[2])
      return;
    mesh_.triangles.push_back(triangle);
  }
  TriangleMesh take() { return std::move(mesh_); }

 private:
  std::uint32_t vertex(const Vec3& p) {
    const auto [it, added] = index_.try_emplace(std::array<double, 3>{p.x(), p.y(), p.z()},
                                                static_cast<std::uint32_t>(mesh_.vertices.size()));
    if (added) mesh_.vertices.push_back(p);
    return it->second;
  }
  TriangleMesh mesh_;
  std::map<std::array<double, 3>, std::uint32_t> index_;
};

constexpr std::size_t kStlHeaderBytes = 84;  // 80-byte header + uint32 facet count
constexpr std::size_t kStlFacetBytes = 50;   // normal, 3 corners (12 floats) + 2 attribute bytes

// The facet count a binary STL declares (the file must be at least 84 bytes).
std::uint32_t stl_declared_facets(std::string_view data) {
  std::uint32_t count = 0;
  std::memcpy(&count, data.data() + 80, sizeof count);
  return count;
}

// Binary when the size is exactly 84 + 50 n for the n declared in bytes 80-83 (for ASCII text
// those four characters would have to encode its own size). The "solid" prefix is no test: many
// binary exporters start their 80-byte header with it.
bool is_binary_stl(std::string_view data) {
  if (data.size() < kStlHeaderBytes) return false;
  return kStlHeaderBytes + kStlFacetBytes * std::uint64_t{stl_declared_facets(data)} == data.size();
}

std::string_view trim_left(std::string_view text) {
  std::size_t i = 0;
  while (i < text.size() && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  return text.substr(i);
}

TriangleMesh parse_binary_stl(std::string_view data) {
  static_assert(std::endian::native == std::endian::little,
                "the binary STL reader assumes a little-endian host");
  const std::uint32_t count = stl_declared_facets(data);
  StlWelder welder;
  for (std::uint32_t f = 0; f < count; ++f) {
    const char* facet = data.data() + kStlHeaderBytes + kStlFacetBytes * std::size_t{f};
    std::array<float, 12> values{};
    std::memcpy(values.data(), facet, sizeof values);
    std::array<Vec3, 3> corners;
    for (int k = 0; k < 3; ++k) {
      corners[k] = Vec3(values[3 + 3 * k], values[4 + 3 * k], values[5 + 3 * k]);
      if (!corners[k].allFinite())
        throw ParseError{"facet " + std::to_string(f) + ", corner " + std::to_string(k) +
                         ": coordinate is not finite (NaN or infinity); repair or re-export "
                         "the mesh"};
    }
    welder.add_facet(corners);
  }
  return welder.take();
}

// ASCII: solid NAME { facet normal n n n / outer loop / vertex x y z (3x) / endloop / endfacet }
// endsolid NAME; several solids in one file are read as one mesh.
TriangleMesh parse_ascii_stl(std::string_view text) {
  LineReader lines(text);
  std::string_view line;
  StlWelder welder;
  std::size_t facet = 0;
  std::array<Vec3, 3> corners;
  int corner = 0;
  // What the next line must start with (kFacet also accepts "endsolid").
  enum class Expect { kSolid, kFacet, kOuter, kVertex, kEndloop, kEndfacet };
  Expect expect = Expect::kSolid;
  auto fail = [&](const std::string& what) {
    throw ParseError{"line " + std::to_string(lines.number()) +
                     (expect == Expect::kSolid ? "" : ", facet " + std::to_string(facet)) + ": " +
                     what};
  };
  while (lines.next(line)) {
    const auto words = split_words(line);
    if (words.empty()) continue;
    const std::string keyword = lower(std::string(words[0]));
    auto expected = [&](const char* wanted) {
      fail("expected '" + std::string(wanted) + "', found '" + std::string(words[0]) +
           "'; the file is not valid ASCII STL (re-export it, or export binary STL)");
    };
    switch (expect) {
      case Expect::kSolid:
        if (keyword != "solid") expected("solid");
        expect = Expect::kFacet;
        break;
      case Expect::kFacet:
        if (keyword == "endsolid") {
          expect = Expect::kSolid;
        } else if (keyword == "facet") {
          expect = Expect::kOuter;
        } else {
          expected("facet");
        }
        break;
      case Expect::kOuter:
        if (keyword != "outer") expected("outer loop");
        expect = Expect::kVertex;
        corner = 0;
        break;
      case Expect::kVertex:
        if (keyword != "vertex") expected("vertex");
        if (words.size() != 4) fail("a vertex needs x y z");
        for (int k = 0; k < 3; ++k) {
          double value = 0.0;
          if (!parse_double(words[k + 1], value))
            fail("bad vertex coordinate '" + std::string(words[k + 1]) +
                 "' (NaN and infinity are not coordinates); repair or re-export the mesh");
          corners[corner][k] = value;
        }
        if (++corner == 3) expect = Expect::kEndloop;
        break;
      case Expect::kEndloop:
        if (keyword != "endloop")
          fail(keyword == "vertex" ? "a facet has more than 3 vertices; triangulate the mesh"
                                   : "expected 'endloop', found '" + std::string(words[0]) + "'");
        expect = Expect::kEndfacet;
        break;
      case Expect::kEndfacet:
        if (keyword != "endfacet") expected("endfacet");
        welder.add_facet(corners);
        ++facet;
        expect = Expect::kFacet;
        break;
    }
  }
  if (expect != Expect::kSolid && expect != Expect::kFacet)
    fail("the file ends inside a facet; it is truncated, re-export it");
  if (expect == Expect::kFacet)
    throw ParseError{"the file ends without 'endsolid' after facet " + std::to_string(facet) +
                     "; it is truncated, re-export it"};
  return welder.take();
}

TriangleMesh parse_stl(std::string_view data) {
  if (is_binary_stl(data)) return parse_binary_stl(data);
  // Text has no NUL or other control bytes; a truncated binary file (even one whose header
  // starts with "solid") has them among its floats.
  const bool text = std::none_of(data.begin(), data.end(), [](char c) {
    const auto byte = static_cast<unsigned char>(c);
    return byte < 0x20 && !std::isspace(byte);
  });
  if (text && trim_left(data).substr(0, 5) == "solid") return parse_ascii_stl(data);
  if (data.empty()) throw ParseError{"the file is empty; re-export the mesh"};
  if (data.size() < kStlHeaderBytes)
    throw ParseError{"binary STL needs an 84-byte header, the file has " +
                     std::to_string(data.size()) + " bytes; it is truncated, re-export it"};
  const std::uint64_t count = stl_declared_facets(data);
  const std::uint64_t whole = (data.size() - kStlHeaderBytes) / kStlFacetBytes;
  throw ParseError{"binary STL declares " + std::to_string(count) + " facets (" +
                   std::to_string(kStlHeaderBytes + kStlFacetBytes * count) +
                   " bytes) but the file has " + std::to_string(data.size()) + " bytes" +
                   (whole < count ? "; facet " + std::to_string(whole) + " is cut off" : "") +
                   ": the file is truncated or not STL, re-export it"};
}

}  // namespace

Result<TriangleMesh> read_mesh(const std::filesystem::path& path, bool allow_empty) {
  Result<std::string> bytes = read_input_file(path, "mesh file");
  if (!bytes) return bytes.status();
  const std::string text = std::move(*bytes);
  const std::string extension = lower(path.extension().string());
  TriangleMesh mesh;
  try {
    if (extension == ".obj")
      mesh = parse_obj(text);
    else if (extension == ".ply")
      mesh = parse_ply(text);
    else if (extension == ".off")
      mesh = parse_off(text);
    else if (extension == ".stl")
      mesh = parse_stl(text);
    else
      return Status::error("mesh file " + path.string() + ": unsupported extension '" + extension +
                           "' (use .obj, .ply, .off or .stl)");
  } catch (const ParseError& e) {
    return Status::error("mesh file " + path.string() + ": " + e.message);
  }
  if (mesh.triangles.empty() && !allow_empty)
    return Status::error("mesh file " + path.string() +
                         ": no faces (a closed mesh is needed; export the surface with its "
                         "triangles, not only its points)");
  return mesh;
}

void orient_outward(TriangleMesh& mesh) {
  if (signed_volume(mesh) >= 0.0) return;
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
}

}  // namespace sonoshape::sim
