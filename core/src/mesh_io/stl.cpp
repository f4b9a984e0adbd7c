// STL, ascii or binary: every facet with its own three corners and no indices. Corners with
// identical coordinates (exact equality of the numbers as read, float for binary, double for
// ASCII; -0 and +0 are one value) become one vertex, so a mesh that is closed in the source is
// closed here. No tolerance: welding near-equal corners would join surfaces the source keeps
// apart. Facet normals are ignored (the corner order gives the orientation) and so are binary
// attribute bytes.
#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <map>

#include "formats.hpp"
#include "mesh_text.hpp"
#include "sonoshape/core/errors.hpp"

namespace sonoshape::mesh_io {
namespace {

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

TriangleMesh read_binary_stl(std::string_view data) {
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
        throw InputError("facet " + std::to_string(f) + ", corner " + std::to_string(k),
                         "coordinate is not finite (NaN or infinity); repair or re-export "
                         "the mesh");
    }
    welder.add_facet(corners);
  }
  return welder.take();
}

// ASCII: solid NAME { facet normal n n n / outer loop / vertex x y z (3x) / endloop / endfacet }
// endsolid NAME; several solids in one file are read as one mesh. A state machine over the
// keyword each line must start with.
class AsciiStlReader {
 public:
  explicit AsciiStlReader(std::string_view text) : lines_(text) {}

  TriangleMesh read() {
    std::string_view line;
    while (lines_.next(line)) {
      const auto words = split_words(line);
      if (!words.empty()) step(words);
    }
    if (expect_ != Expect::kSolid && expect_ != Expect::kFacet)
      fail("the file ends inside a facet; it is truncated, re-export it");
    if (expect_ == Expect::kFacet)
      throw InputError("", "the file ends without 'endsolid' after facet " +
                               std::to_string(facet_) + "; it is truncated, re-export it");
    return welder_.take();
  }

 private:
  // What the next line must start with (kFacet also accepts "endsolid").
  enum class Expect { kSolid, kFacet, kOuter, kVertex, kEndloop, kEndfacet };

  [[noreturn]] void fail(const std::string& what) const {
    throw InputError("line " + std::to_string(lines_.number()) +
                         (expect_ == Expect::kSolid ? "" : ", facet " + std::to_string(facet_)),
                     what);
  }
  [[noreturn]] void expected(const char* wanted, std::string_view found) const {
    fail("expected '" + std::string(wanted) + "', found '" + std::string(found) +
         "'; the file is not valid ASCII STL (re-export it, or export binary STL)");
  }

  void read_corner(const std::vector<std::string_view>& words) {
    if (words.size() != 4) fail("a vertex needs x y z");
    for (int k = 0; k < 3; ++k) {
      double value = 0.0;
      if (!parse_double(words[k + 1], value))
        fail("bad vertex coordinate '" + std::string(words[k + 1]) +
             "' (NaN and infinity are not coordinates); repair or re-export the mesh");
      corners_[corner_][k] = value;
    }
  }

  void step(const std::vector<std::string_view>& words) {
    const std::string keyword = lower(std::string(words[0]));
    switch (expect_) {
      case Expect::kSolid:
        if (keyword != "solid") expected("solid", words[0]);
        expect_ = Expect::kFacet;
        break;
      case Expect::kFacet:
        if (keyword == "endsolid") {
          expect_ = Expect::kSolid;
        } else if (keyword == "facet") {
          expect_ = Expect::kOuter;
        } else {
          expected("facet", words[0]);
        }
        break;
      case Expect::kOuter:
        if (keyword != "outer") expected("outer loop", words[0]);
        expect_ = Expect::kVertex;
        corner_ = 0;
        break;
      case Expect::kVertex:
        if (keyword != "vertex") expected("vertex", words[0]);
        read_corner(words);
        if (++corner_ == 3) expect_ = Expect::kEndloop;
        break;
      case Expect::kEndloop:
        if (keyword != "endloop")
          fail(keyword == "vertex" ? "a facet has more than 3 vertices; triangulate the mesh"
                                   : "expected 'endloop', found '" + std::string(words[0]) + "'");
        expect_ = Expect::kEndfacet;
        break;
      case Expect::kEndfacet:
        if (keyword != "endfacet") expected("endfacet", words[0]);
        welder_.add_facet(corners_);
        ++facet_;
        expect_ = Expect::kFacet;
        break;
    }
  }

  LineReader lines_;
  StlWelder welder_;
  std::size_t facet_ = 0;
  std::array<Vec3, 3> corners_;
  int corner_ = 0;
  Expect expect_ = Expect::kSolid;
};

// Why bytes that are neither whole binary STL nor ASCII STL cannot be read.
[[noreturn]] void fail_not_stl(std::string_view data) {
  if (data.empty()) throw InputError("", "the file is empty; re-export the mesh");
  if (data.size() < kStlHeaderBytes)
    throw InputError("", "binary STL needs an 84-byte header, the file has " +
                             std::to_string(data.size()) + " bytes; it is truncated, re-export it");
  const std::uint64_t count = stl_declared_facets(data);
  const std::uint64_t whole = (data.size() - kStlHeaderBytes) / kStlFacetBytes;
  throw InputError("",
                   "binary STL declares " + std::to_string(count) + " facets (" +
                       std::to_string(kStlHeaderBytes + kStlFacetBytes * count) +
                       " bytes) but the file has " + std::to_string(data.size()) + " bytes" +
                       (whole < count ? "; facet " + std::to_string(whole) + " is cut off" : "") +
                       ": the file is truncated or not STL, re-export it");
}

}  // namespace

TriangleMesh read_stl(std::string_view data) {
  if (is_binary_stl(data)) return read_binary_stl(data);
  // Text has no NUL or other control bytes; a truncated binary file (even one whose header
  // starts with "solid") has them among its floats.
  const bool text = std::none_of(data.begin(), data.end(), [](char c) {
    const auto byte = static_cast<unsigned char>(c);
    return byte < 0x20 && !std::isspace(byte);
  });
  if (text && trim_left(data).substr(0, 5) == "solid") return AsciiStlReader(data).read();
  fail_not_stl(data);
}

}  // namespace sonoshape::mesh_io
