// Object File Format: "OFF" (or COFF with vertex colours, NOFF with normals), the counts, the
// vertices, then each face as its size and indices (0-based), optionally followed by a colour.
#include <algorithm>

#include "formats.hpp"
#include "mesh_text.hpp"
#include "sonoshape/core/errors.hpp"

namespace sonoshape::mesh_io {
namespace {

// The words of the file with their line numbers: the header may share its line with the counts
// ("OFF 8 6 0"); comments start with '#'.
struct OffTokens {
  std::vector<std::string_view> words;
  std::vector<int> lines;
  std::size_t next = 0;

  explicit OffTokens(std::string_view text) {
    LineReader reader(text);
    std::string_view line;
    while (reader.next(line)) {
      const std::size_t hash = line.find('#');
      for (std::string_view w : split_words(line.substr(0, hash))) {
        words.push_back(w);
        lines.push_back(reader.number());
      }
    }
  }
  bool done() const { return next >= words.size(); }
  int line_of(std::size_t k) const { return lines[std::min(k, lines.size() - 1)]; }
  std::string where(std::size_t k) const { return "line " + std::to_string(line_of(k)); }
  long long take_long(const char* what) {
    long long value = 0;
    if (done()) throw InputError(where(next), std::string("file ends before ") + what);
    if (!parse_long(words[next], value))
      throw InputError(where(next),
                       std::string("bad ") + what + " '" + std::string(words[next]) + "'");
    ++next;
    return value;
  }
};

void read_vertices(OffTokens& tokens, long long vertex_count, std::size_t skip,
                   TriangleMesh& mesh) {
  for (long long i = 0; i < vertex_count; ++i) {
    Vec3 p;
    for (int k = 0; k < 3; ++k) {
      if (tokens.done()) throw InputError("vertex " + std::to_string(i), "file ends early");
      if (!parse_double(tokens.words[tokens.next], p[k]))
        throw InputError(tokens.where(tokens.next),
                         "vertex " + std::to_string(i) + ": bad coordinate '" +
                             std::string(tokens.words[tokens.next]) + "'");
      ++tokens.next;
    }
    tokens.next += skip;
    mesh.vertices.push_back(p);
  }
}

}  // namespace

TriangleMesh read_off(std::string_view text) {
  TriangleMesh mesh;
  OffTokens tokens(text);
  const std::string_view header = tokens.words.empty() ? "" : tokens.words[0];
  if (header != "OFF" && header != "COFF" && header != "NOFF")
    throw InputError("line 1", "expected the OFF header");
  ++tokens.next;
  const long long vertex_count = tokens.take_long("vertex count");
  const long long face_count = tokens.take_long("face count");
  tokens.take_long("edge count");
  if (vertex_count < 0 || face_count < 0)
    throw InputError(tokens.where(tokens.next), "negative element count");
  // A corrupt count must not reserve more than the file can hold.
  mesh.vertices.reserve(
      std::min<std::size_t>(static_cast<std::size_t>(vertex_count), text.size() / 3));
  read_vertices(tokens, vertex_count, header == "COFF" ? 4 : header == "NOFF" ? 3 : 0, mesh);
  std::vector<long long> polygon;
  for (long long f = 0; f < face_count; ++f) {
    const int line_number = tokens.line_of(tokens.next);
    const long long n = tokens.take_long("face size");
    polygon.clear();
    for (long long k = 0; k < n; ++k) polygon.push_back(tokens.take_long("face index"));
    // Optional per-face colour values follow on the same line: skip them.
    while (!tokens.done() && tokens.lines[tokens.next] == line_number) ++tokens.next;
    add_polygon(mesh, polygon, mesh.vertices.size(),
                "line " + std::to_string(line_number) + ", face " + std::to_string(f));
  }
  return mesh;
}

std::string off_text(const TriangleMesh& mesh) {
  std::string out = "OFF\n" + std::to_string(mesh.vertices.size()) + " " +
                    std::to_string(mesh.triangles.size()) + " 0\n";
  for (const Vec3& p : mesh.vertices) {
    append_number(out, p.x());
    out += ' ';
    append_number(out, p.y());
    out += ' ';
    append_number(out, p.z());
    out += '\n';
  }
  for (const auto& t : mesh.triangles)
    out += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) +
           "\n";
  return out;
}

}  // namespace sonoshape::mesh_io
