// Wavefront OBJ: "v x y z" and "f a b c ..." lines; everything else (texture coordinates,
// normals, groups, materials, lines) is not geometry a closed mesh needs.
#include "formats.hpp"
#include "mesh_text.hpp"
#include "sonoshape/core/errors.hpp"

namespace sonoshape::mesh_io {

TriangleMesh read_obj(std::string_view text) {
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
      if (words.size() < 4) throw InputError(where, "a vertex needs x y z");
      for (int k = 0; k < 3; ++k)
        if (!parse_double(words[k + 1], p[k]))
          throw InputError(where, "bad vertex coordinate '" + std::string(words[k + 1]) + "'");
      mesh.vertices.push_back(p);
    } else if (words[0] == "f") {
      polygon.clear();
      for (std::size_t k = 1; k < words.size(); ++k) {
        // "a", "a/b", "a//c", "a/b/c": only the position index matters.
        const std::string_view word = words[k].substr(0, words[k].find('/'));
        long long index = 0;
        if (!parse_long(word, index) || index == 0)
          throw InputError(where, "bad face index '" + std::string(words[k]) + "'");
        // OBJ indices are 1-based; negative ones count back from the last vertex read.
        polygon.push_back(index > 0 ? index - 1
                                    : static_cast<long long>(mesh.vertices.size()) + index);
      }
      add_polygon(mesh, polygon, mesh.vertices.size(), where);
    }
  }
  return mesh;
}

std::string obj_text(const TriangleMesh& mesh) {
  std::string out = "# written by sonoshape\n";
  for (const Vec3& p : mesh.vertices) {
    out += "v ";
    append_number(out, p.x());
    out += ' ';
    append_number(out, p.y());
    out += ' ';
    append_number(out, p.z());
    out += '\n';
  }
  for (const auto& t : mesh.triangles)  // OBJ indices are 1-based
    out += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " +
           std::to_string(t[2] + 1) + "\n";
  return out;
}

}  // namespace sonoshape::mesh_io
