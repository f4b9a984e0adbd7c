// Stanford PLY: a text header of elements and their properties, then the body in ascii or binary
// little-endian. The reader takes x, y, z of element vertex and the vertex_indices (or
// vertex_index) list of element face, and skips every other element and property; the writer
// writes binary little-endian float coordinates and int indices.
#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "formats.hpp"
#include "mesh_text.hpp"
#include "sonoshape/core/errors.hpp"

namespace sonoshape::mesh_io {
namespace {

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
  throw InputError(where, "unknown PLY type '" + std::string(name) + "'");
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

struct PlyHeader {
  bool ascii = false;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;  // first byte after the end_header line
};

// Reads scalars from the body of a PLY file, ascii or binary little-endian.
class PlyBody {
 public:
  PlyBody(std::string_view body, bool ascii) : body_(body), ascii_(ascii) {}

  double read(PlyType type, const std::string& where) {
    if (ascii_) return read_ascii(where);
    const std::size_t size = ply_type_size(type);
    if (pos_ + size > body_.size()) throw InputError(where, "file ends early");
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
    if (start == pos_) throw InputError(where, "file ends early");
    double value = 0.0;
    if (!parse_double(body_.substr(start, pos_ - start), value))
      throw InputError(where,
                       "bad number '" + std::string(body_.substr(start, pos_ - start)) + "'");
    return value;
  }

  std::string_view body_;
  bool ascii_;
  std::size_t pos_ = 0;
};

// "property <type> <name>" or "property list <count type> <type> <name>".
PlyProperty parse_property_line(const std::vector<std::string_view>& words,
                                const std::string& where) {
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
    throw InputError(where, "bad property line");
  }
  return property;
}

PlyHeader parse_ply_header(std::string_view text) {
  LineReader lines(text);
  std::string_view line;
  if (!lines.next(line) || line != "ply") throw InputError("line 1", "expected 'ply'");
  PlyHeader header;
  bool have_format = false;
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
      if (words.size() < 2) throw InputError(where, "incomplete format line");
      if (words[1] == "ascii")
        header.ascii = true;
      else if (words[1] == "binary_little_endian")
        header.ascii = false;
      else
        throw InputError(where, "PLY format '" + std::string(words[1]) +
                                    "' is not supported (use ascii or binary_little_endian)");
      have_format = true;
    } else if (words[0] == "element") {
      long long count = 0;
      if (words.size() < 3 || !parse_long(words[2], count) || count < 0)
        throw InputError(where, "bad element line");
      header.elements.push_back({std::string(words[1]), static_cast<std::size_t>(count), {}});
    } else if (words[0] == "property") {
      if (header.elements.empty()) throw InputError(where, "property before any element");
      header.elements.back().properties.push_back(parse_property_line(words, where));
    } else {
      throw InputError(where, "unexpected '" + std::string(words[0]) + "'");
    }
  }
  if (!header_done) throw InputError("header", "no end_header");
  if (!have_format) throw InputError("header", "no format line");
  header.body_offset = lines.position();
  return header;
}

// Reads the instances of one element from the body, keeping vertex positions and face index
// lists. `xyz` are the positions of a vertex element's x, y, z properties, `index_list` that of a
// face element's index list (-1 for other elements).
void read_element(const PlyElement& element, const int (&xyz)[3], int index_list,
                  bool have_vertices, PlyBody& body, TriangleMesh& mesh) {
  const bool is_vertex = element.name == "vertex";
  std::vector<long long> polygon;
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
      if (n < 0 || n != std::floor(n)) throw InputError(where, "bad list length");
      const bool wanted = static_cast<int>(k) == index_list;
      if (wanted) polygon.clear();
      for (long long j = 0; j < static_cast<long long>(n); ++j) {
        const double value = body.read(property.type, where);
        if (wanted) polygon.push_back(static_cast<long long>(value));
      }
      if (wanted) {
        if (!have_vertices)
          throw InputError("header", "faces come before vertices, which this reader needs first");
        add_polygon(mesh, polygon, mesh.vertices.size(), where);
      }
    }
    if (is_vertex) {
      if (!p.allFinite()) throw InputError(where, "coordinate is not finite");
      mesh.vertices.push_back(p);
    }
  }
}

// Little-endian whatever the host: the header says binary_little_endian.
void append_u32_le(std::string& out, std::uint32_t bits) {
  for (int k = 0; k < 4; ++k) out.push_back(static_cast<char>((bits >> (8 * k)) & 0xffu));
}

void append_float_le(std::string& out, float value) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &value, sizeof bits);
  append_u32_le(out, bits);
}

}  // namespace

TriangleMesh read_ply(std::string_view text) {
  const PlyHeader header = parse_ply_header(text);
  TriangleMesh mesh;
  PlyBody body(text.substr(header.body_offset), header.ascii);
  bool have_vertices = false;
  for (const PlyElement& element : header.elements) {
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
        throw InputError("header", "element vertex lacks an x, y or z property");
      have_vertices = true;
      // A corrupt count must not reserve more than the file can hold.
      mesh.vertices.reserve(std::min<std::size_t>(element.count, text.size() / 3));
    }
    if (is_face && index_list < 0)
      throw InputError("header", "element face lacks a vertex_indices list");
    // An element without properties occupies no bytes, so its count cannot be checked against
    // the file and there is nothing to read: `element edge 9223372036854775807` alone would
    // otherwise be a loop of 2^63 empty steps.
    if (element.properties.empty()) continue;
    read_element(element, xyz, index_list, have_vertices, body, mesh);
  }
  if (!have_vertices) throw InputError("header", "no vertex element");
  return mesh;
}

std::string ply_bytes(const TriangleMesh& mesh) {
  std::string out = "ply\nformat binary_little_endian 1.0\ncomment written by sonoshape\n";
  out += "element vertex " + std::to_string(mesh.vertices.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  out += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  out += "property list uchar int vertex_indices\nend_header\n";
  out.reserve(out.size() + mesh.vertices.size() * 12 + mesh.triangles.size() * 13);
  for (const Vec3& p : mesh.vertices)
    for (int k = 0; k < 3; ++k) append_float_le(out, static_cast<float>(p[k]));
  for (const auto& t : mesh.triangles) {
    out.push_back(static_cast<char>(3));
    for (std::uint32_t index : t) append_u32_le(out, index);  // int32: indices checked < 2^31
  }
  return out;
}

}  // namespace sonoshape::mesh_io
