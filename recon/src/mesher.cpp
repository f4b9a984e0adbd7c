#include "mesher.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>

#include "key_masks.hpp"
#include "sorted_keys.hpp"

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
        for (int v = 0; v < 4; ++v)
          ((mask >> v) & 1 ? in : out).push_back(tets[t][static_cast<std::size_t>(v)]);
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
            p[static_cast<std::size_t>(k)] =
                0.5 * (corner_offset(tri.edges[static_cast<std::size_t>(k)][0]) +
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
  const std::size_t stride = static_cast<std::size_t>(fc);
  std::vector<TriangleMesh> meshes(static_cast<std::size_t>(std::max(0, fc - 1)));
  // The band's corners (sorted keys), their rows and labels, each looked up once; the merge that
  // lists them gives each cell's corners among them (the look-ups of every cell's
  // eight corners were most of the mesher's time). Corners numbered in key order also keep the
  // edge table below small and its accesses near each other, as the cells are in key order too.
  const std::vector<std::uint64_t>& cells = field.surface_cells;
  // Per cell, its cube corner c (offset (c & 1, (c >> 1) & 1, (c >> 2) & 1)) in `corners`.
  std::vector<std::uint32_t> cell_corners;
  const std::vector<std::uint64_t> corners = cube_corner_union(cells, &cell_corners);
  std::vector<std::uint32_t> corner_rows(corners.size());
  std::vector<std::uint16_t> corner_labels(corners.size());  // labels are function indices
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, corners.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t n = r.begin(); n < r.end(); ++n) {
                        corner_rows[n] = field.index.at(corners[n]);
                        corner_labels[n] =
                            static_cast<std::uint16_t>(field.row_label(corner_rows[n]));
                      }
                    });
  // Per material, the triangles of each cell are listed in parallel, in chunks of cells of a
  // fixed size, and numbered in one serial pass in cell order: the vertex order (and so the
  // mesh) is that of a serial walk over the band, whatever the thread count. A triangle is its
  // cell and, per vertex, the cube corners of its edge (inside, outside), 3 bits each.
  struct CellTriangle {
    std::uint32_t cell;
    std::uint32_t
        edge_corners;  // vertex e: inside corner at bits 6e, outside corner at bits 6e + 3
  };
  constexpr std::size_t kChunk = 1024;
  const std::size_t chunk_count = (cells.size() + kChunk - 1) / kChunk;
  std::vector<std::vector<CellTriangle>> chunk_triangles(chunk_count);
  // Mesh vertex per tetrahedron edge. The Kuhn tetrahedra are monotone paths through the cube,
  // so every edge joins a grid vertex to one at an offset in {0,1}^3: (lower corner, offset)
  // indexes a flat table.
  constexpr std::uint32_t kNoVertex = 0xffffffffu;
  std::vector<std::uint32_t> vertex_of_edge(corners.size() * 8);
  std::vector<double> corner_g(corners.size());
  for (int material = 1; material < fc; ++material) {
    TriangleMesh& mesh = meshes[static_cast<std::size_t>(material - 1)];
    std::fill(vertex_of_edge.begin(), vertex_of_edge.end(), kNoVertex);
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, chunk_count, 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t chunk = r.begin(); chunk < r.end(); ++chunk) {
            std::vector<CellTriangle>& out = chunk_triangles[chunk];
            out.clear();
            for (std::size_t n = chunk * kChunk; n < std::min(cells.size(), (chunk + 1) * kChunk);
                 ++n) {
              int inside = 0;  // bit per cube corner
              for (int c = 0; c < 8; ++c)
                if (corner_labels[cell_corners[n * 8 + static_cast<std::size_t>(c)]] ==
                    static_cast<std::uint16_t>(material))
                  inside |= 1 << c;
              if (inside == 0 || inside == 0xff) continue;
              for (std::size_t t = 0; t < 6; ++t) {
                int mask = 0;
                for (int v = 0; v < 4; ++v)
                  if ((inside >> tets[t][static_cast<std::size_t>(v)]) & 1) mask |= 1 << v;
                for (const Triangle& tri : table.cases[t][static_cast<std::size_t>(mask)]) {
                  std::uint32_t edge_corners = 0;
                  for (std::size_t e = 0; e < 3; ++e)
                    edge_corners |=
                        static_cast<std::uint32_t>(tri.edges[e][0] | (tri.edges[e][1] << 3))
                        << (6 * e);
                  out.push_back({static_cast<std::uint32_t>(n), edge_corners});
                }
              }
            }
          }
        });
    // g = f_m - max_{k != m} f_k per corner, positive inside the label's region: computed in
    // parallel and read in corner order below (reading the field's rows there, scattered over
    // memory, was most of the serial pass).
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, corners.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t n = r.begin(); n < r.end(); ++n) {
                          const double* row = field.values.data() + corner_rows[n] * stride;
                          double other = -std::numeric_limits<double>::infinity();
                          for (int l = 0; l < fc; ++l)
                            if (l != material) other = std::max(other, row[l]);
                          corner_g[n] = row[material] - other;
                        }
                      });
    std::size_t triangle_count = 0;
    for (const std::vector<CellTriangle>& triangles : chunk_triangles)
      triangle_count += triangles.size();
    mesh.triangles.reserve(triangle_count);
    // The serial pass only numbers the vertices (first use in cell order) and records each new
    // vertex's cell and edge; their positions, which the numbering does not need, are computed
    // after it, in parallel.
    struct NewVertex {
      std::uint32_t cell;
      std::uint32_t edge;  // inside corner | outside corner << 3
    };
    std::vector<NewVertex> new_vertices;
    new_vertices.reserve(triangle_count / 2 + 2);  // closed surfaces: V = T/2 + 2 - 2 genus (Euler)
    for (const std::vector<CellTriangle>& triangles : chunk_triangles)
      for (const CellTriangle& triangle : triangles) {
        const std::uint32_t* cube = &cell_corners[static_cast<std::size_t>(triangle.cell) * 8];
        std::array<std::uint32_t, 3> ids;
        for (std::size_t e = 0; e < 3; ++e) {
          const std::uint32_t edge = (triangle.edge_corners >> (6 * e)) & 63u;
          const std::uint32_t ca = edge & 7u, cb = edge >> 3;  // inside, outside corner
          std::uint32_t& vertex =
              vertex_of_edge[static_cast<std::size_t>(cube[ca & cb]) * 8 + (ca ^ cb)];
          if (vertex == kNoVertex) {
            vertex = static_cast<std::uint32_t>(new_vertices.size());
            new_vertices.push_back({triangle.cell, edge});
          }
          ids[e] = vertex;
        }
        mesh.triangles.push_back(ids);
      }
    mesh.vertices.resize(new_vertices.size());
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, new_vertices.size(), 4096),
        [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t v = r.begin(); v < r.end(); ++v) {
            const NewVertex& nv = new_vertices[v];
            const std::uint32_t* cube = &cell_corners[static_cast<std::size_t>(nv.cell) * 8];
            const int ca = static_cast<int>(nv.edge & 7u), cb = static_cast<int>(nv.edge >> 3);
            const double ga = std::max(0.0, corner_g[cube[ca]]);
            const double gb = std::min(0.0, corner_g[cube[cb]]);
            const double t_param = ga - gb > 0.0 ? ga / (ga - gb) : 0.5;
            int i, j, k;
            grid_unkey(cells[nv.cell], i, j, k);
            const Vec3 pa =
                field.grid.position(i + (ca & 1), j + ((ca >> 1) & 1), k + ((ca >> 2) & 1));
            const Vec3 pb =
                field.grid.position(i + (cb & 1), j + ((cb >> 1) & 1), k + ((cb >> 2) & 1));
            mesh.vertices[v] = pa + t_param * (pb - pa);
          }
        });
  }
  return meshes;
}

}  // namespace sonoshape::recon
