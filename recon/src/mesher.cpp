#include "mesher.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace sonoshape::recon {
namespace {

// Cube corner c has offset (c & 1, (c >> 1) & 1, (c >> 2) & 1).
Vec3 corner_offset(int c) { return Vec3(c & 1, (c >> 1) & 1, (c >> 2) & 1); }

struct Triangle {
  std::array<std::array<int, 2>, 3> edges;  // each vertex on the edge between two cube corners
};

// Kuhn tetrahedra: the paths 0 -> e_a -> e_a + e_b -> 7 over the permutations (a, b, c).
std::array<std::array<int, 4>, 6> kuhn_tetrahedra() {
  std::array<std::array<int, 4>, 6> tets{};
  const std::array<std::array<int, 3>, 6> perms{
      {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  for (std::size_t t = 0; t < 6; ++t) {
    const int a = 1 << perms[t][0], b = 1 << perms[t][1];
    tets[t] = {0, a, a | b, 7};
  }
  return tets;
}

// Triangles per (tetrahedron, inside mask), oriented so that their normal points from the
// inside corners to the outside ones. The orientation is decided once, on midpoints of the edges
// in cube coordinates, where every quantity is exact.
struct CaseTable {
  std::array<std::array<std::vector<Triangle>, 16>, 6> cases;
  CaseTable() {
    const auto tets = kuhn_tetrahedra();
    for (std::size_t t = 0; t < 6; ++t) {
      for (int mask = 1; mask < 15; ++mask) {
        std::vector<int> in, out;
        for (int v = 0; v < 4; ++v) ((mask >> v) & 1 ? in : out).push_back(tets[t][static_cast<std::size_t>(v)]);
        std::vector<Triangle> tris;
        if (in.size() == 1) {
          tris.push_back({{{{in[0], out[0]}, {in[0], out[1]}, {in[0], out[2]}}}});
        } else if (in.size() == 3) {
          tris.push_back({{{{in[0], out[0]}, {in[1], out[0]}, {in[2], out[0]}}}});
        } else {
          // Quad in order around: (i0,o0) (i0,o1) (i1,o1) (i1,o0).
          tris.push_back({{{{in[0], out[0]}, {in[0], out[1]}, {in[1], out[1]}}}});
          tris.push_back({{{{in[0], out[0]}, {in[1], out[1]}, {in[1], out[0]}}}});
        }
        Vec3 in_center = Vec3::Zero(), out_center = Vec3::Zero();
        for (int c : in) in_center += corner_offset(c) / static_cast<double>(in.size());
        for (int c : out) out_center += corner_offset(c) / static_cast<double>(out.size());
        for (Triangle& tri : tris) {
          std::array<Vec3, 3> p;
          for (int k = 0; k < 3; ++k)
            p[static_cast<std::size_t>(k)] = 0.5 * (corner_offset(tri.edges[static_cast<std::size_t>(k)][0]) +
                                                    corner_offset(tri.edges[static_cast<std::size_t>(k)][1]));
          const Vec3 normal = (p[1] - p[0]).cross(p[2] - p[0]);
          if (normal.dot(out_center - in_center) < 0.0) std::swap(tri.edges[1], tri.edges[2]);
        }
        cases[t][static_cast<std::size_t>(mask)] = std::move(tris);
      }
    }
  }
};

}  // namespace

std::vector<TriangleMesh> extract_label_surfaces(const SampledField& field) {
  static const CaseTable table;
  static const auto tets = kuhn_tetrahedra();
  const int fc = field.function_count;
  std::vector<TriangleMesh> meshes(static_cast<std::size_t>(std::max(0, fc - 1)));
  // The rows and labels of every band cell's corners, looked up once and in parallel (the
  // look-ups were most of the mesher's time; what follows must stay serial for its vertex order).
  const std::vector<std::uint64_t>& cells = field.surface_cells;
  std::vector<std::uint32_t> corner_rows(cells.size() * 8);
  std::vector<std::uint16_t> corner_labels(cells.size() * 8);  // labels are function indices
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t n = r.begin(); n < r.end(); ++n) {
                        int i, j, k;
                        grid_unkey(cells[n], i, j, k);
                        for (int c = 0; c < 8; ++c) {
                          const std::uint64_t key = grid_key(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                          corner_rows[n * 8 + static_cast<std::size_t>(c)] = field.index.at(key);
                          corner_labels[n * 8 + static_cast<std::size_t>(c)] = static_cast<std::uint16_t>(field.label(key));
                        }
                      }
                    });
  // Mesh vertex per tetrahedron edge. The Kuhn tetrahedra are monotone paths through the cube,
  // so every edge joins a grid vertex to one at an offset in {0,1}^3: (row of the lower vertex,
  // offset) indexes a flat table; `edges_set` lists its entries, to empty it between materials.
  constexpr std::uint32_t kNoVertex = 0xffffffffu;
  std::vector<std::uint32_t> vertex_of_edge(field.keys.size() * 8, kNoVertex);
  std::vector<std::size_t> edges_set;
  for (int material = 1; material < fc; ++material) {
    TriangleMesh& mesh = meshes[static_cast<std::size_t>(material - 1)];
    for (const std::size_t e : edges_set) vertex_of_edge[e] = kNoVertex;
    edges_set.clear();
    // g = f_m - max_{k != m} f_k: positive inside the label's region.
    auto g = [&](const double* row) {
      double other = -std::numeric_limits<double>::infinity();
      for (int l = 0; l < fc; ++l)
        if (l != material) other = std::max(other, row[l]);
      return row[material] - other;
    };
    for (std::size_t n = 0; n < cells.size(); ++n) {
      std::array<bool, 8> inside;
      bool any_in = false, any_out = false;
      for (std::size_t c = 0; c < 8; ++c) {
        inside[c] = corner_labels[n * 8 + c] == static_cast<std::uint16_t>(material);
        any_in |= inside[c];
        any_out |= !inside[c];
      }
      if (!any_in || !any_out) continue;
      int i, j, k;
      grid_unkey(cells[n], i, j, k);
      const std::uint32_t* rows = &corner_rows[n * 8];
      for (std::size_t t = 0; t < 6; ++t) {
        int mask = 0;
        for (int v = 0; v < 4; ++v)
          if (inside[static_cast<std::size_t>(tets[t][static_cast<std::size_t>(v)])]) mask |= 1 << v;
        for (const Triangle& tri : table.cases[t][static_cast<std::size_t>(mask)]) {
          std::array<std::uint32_t, 3> ids;
          for (int e = 0; e < 3; ++e) {
            const int ca = tri.edges[static_cast<std::size_t>(e)][0];  // inside corner
            const int cb = tri.edges[static_cast<std::size_t>(e)][1];  // outside corner
            const std::size_t edge = static_cast<std::size_t>(rows[ca & cb]) * 8 + static_cast<std::size_t>(ca ^ cb);
            std::uint32_t& vertex = vertex_of_edge[edge];
            if (vertex == kNoVertex) {
              vertex = static_cast<std::uint32_t>(mesh.vertices.size());
              edges_set.push_back(edge);
              const std::size_t stride = static_cast<std::size_t>(fc);
              const double ga = std::max(0.0, g(field.values.data() + rows[ca] * stride));
              const double gb = std::min(0.0, g(field.values.data() + rows[cb] * stride));
              const double t_param = ga - gb > 0.0 ? ga / (ga - gb) : 0.5;
              const Vec3 pa = field.grid.position(i + (ca & 1), j + ((ca >> 1) & 1), k + ((ca >> 2) & 1));
              const Vec3 pb = field.grid.position(i + (cb & 1), j + ((cb >> 1) & 1), k + ((cb >> 2) & 1));
              mesh.vertices.push_back(pa + t_param * (pb - pa));
            }
            ids[static_cast<std::size_t>(e)] = vertex;
          }
          mesh.triangles.push_back(ids);
        }
      }
    }
  }
  return meshes;
}

}  // namespace sonoshape::recon
