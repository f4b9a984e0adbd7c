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

// Marching tetrahedra on the band, one material at a time (extract_label_surfaces). The band's
// corners (sorted keys), their rows and labels, each looked up once; the merge that lists them
// gives each cell's corners among them (the look-ups of every cell's eight corners were most of
// the mesher's time). Corners numbered in key order also keep the edge table small and its
// accesses near each other, as the cells are in key order too.
class BandMesher {
 public:
  explicit BandMesher(const SampledField& field)
      : field_(field),
        fc_(field.function_count),
        cells_(field.surface_cells),
        corners_(cube_corner_union(cells_, &cell_corners_)),
        corner_rows_(corners_.size()),
        corner_labels_(corners_.size()),
        chunk_triangles_((cells_.size() + kChunk - 1) / kChunk),
        vertex_of_edge_(corners_.size() * 8),
        corner_g_(corners_.size()) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, corners_.size(), 1024),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t n = r.begin(); n < r.end(); ++n) {
                          corner_rows_[n] = field_.index.at(corners_[n]);
                          corner_labels_[n] =
                              static_cast<std::uint16_t>(field_.row_label(corner_rows_[n]));
                        }
                      });
  }

  TriangleMesh mesh(int material) {
    TriangleMesh mesh;
    std::fill(vertex_of_edge_.begin(), vertex_of_edge_.end(), kNoVertex);
    list_triangles(material);
    compute_g(material);
    const std::vector<NewVertex> new_vertices = number_vertices(mesh);
    place_vertices(new_vertices, mesh);
    return mesh;
  }

 private:
  // Per material, the triangles of each cell are listed in parallel, in chunks of cells of a
  // fixed size, and numbered in one serial pass in cell order: the vertex order (and so the
  // mesh) is that of a serial walk over the band, whatever the thread count. A triangle is its
  // cell and, per vertex, the cube corners of its edge (inside, outside), 3 bits each.
  struct CellTriangle {
    std::uint32_t cell;
    std::uint32_t
        edge_corners;  // vertex e: inside corner at bits 6e, outside corner at bits 6e + 3
  };
  struct NewVertex {
    std::uint32_t cell;
    std::uint32_t edge;  // inside corner | outside corner << 3
  };
  static constexpr std::size_t kChunk = 1024;
  static constexpr std::uint32_t kNoVertex = 0xffffffffu;

  void list_triangles(int material) {
    static const CaseTable table;
    static const auto tets = kuhn_tetrahedra();
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, chunk_triangles_.size(), 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t chunk = r.begin(); chunk < r.end(); ++chunk) {
            std::vector<CellTriangle>& out = chunk_triangles_[chunk];
            out.clear();
            for (std::size_t n = chunk * kChunk; n < std::min(cells_.size(), (chunk + 1) * kChunk);
                 ++n) {
              int inside = 0;  // bit per cube corner
              for (int c = 0; c < 8; ++c)
                if (corner_labels_[cell_corners_[n * 8 + static_cast<std::size_t>(c)]] ==
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
  }

  // g = f_m - max_{k != m} f_k per corner, positive inside the label's region: computed in
  // parallel and read in corner order (reading the field's rows in the serial pass, scattered
  // over memory, was most of it).
  void compute_g(int material) {
    const std::size_t stride = static_cast<std::size_t>(fc_);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, corners_.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t n = r.begin(); n < r.end(); ++n) {
                          const double* row = field_.values.data() + corner_rows_[n] * stride;
                          double other = -std::numeric_limits<double>::infinity();
                          for (int l = 0; l < fc_; ++l)
                            if (l != material) other = std::max(other, row[l]);
                          corner_g_[n] = row[material] - other;
                        }
                      });
  }

  // The serial pass only numbers the vertices (first use in cell order) and records each new
  // vertex's cell and edge; their positions, which the numbering does not need, are computed
  // after it, in parallel. Mesh vertex per tetrahedron edge: the Kuhn tetrahedra are monotone
  // paths through the cube, so every edge joins a grid vertex to one at an offset in {0,1}^3:
  // (lower corner, offset) indexes a flat table.
  std::vector<NewVertex> number_vertices(TriangleMesh& mesh) {
    std::size_t triangle_count = 0;
    for (const std::vector<CellTriangle>& triangles : chunk_triangles_)
      triangle_count += triangles.size();
    mesh.triangles.reserve(triangle_count);
    std::vector<NewVertex> new_vertices;
    new_vertices.reserve(triangle_count / 2 + 2);  // closed surfaces: V = T/2 + 2 - 2 genus (Euler)
    for (const std::vector<CellTriangle>& triangles : chunk_triangles_)
      for (const CellTriangle& triangle : triangles) {
        const std::uint32_t* cube = &cell_corners_[static_cast<std::size_t>(triangle.cell) * 8];
        std::array<std::uint32_t, 3> ids;
        for (std::size_t e = 0; e < 3; ++e) {
          const std::uint32_t edge = (triangle.edge_corners >> (6 * e)) & 63u;
          const std::uint32_t ca = edge & 7u, cb = edge >> 3;  // inside, outside corner
          std::uint32_t& vertex =
              vertex_of_edge_[static_cast<std::size_t>(cube[ca & cb]) * 8 + (ca ^ cb)];
          if (vertex == kNoVertex) {
            vertex = static_cast<std::uint32_t>(new_vertices.size());
            new_vertices.push_back({triangle.cell, edge});
          }
          ids[e] = vertex;
        }
        mesh.triangles.push_back(ids);
      }
    return new_vertices;
  }

  // Each vertex where g crosses zero along its edge (linear in g).
  void place_vertices(const std::vector<NewVertex>& new_vertices, TriangleMesh& mesh) const {
    mesh.vertices.resize(new_vertices.size());
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, new_vertices.size(), 4096),
        [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t v = r.begin(); v < r.end(); ++v) {
            const NewVertex& nv = new_vertices[v];
            const std::uint32_t* cube = &cell_corners_[static_cast<std::size_t>(nv.cell) * 8];
            const int ca = static_cast<int>(nv.edge & 7u), cb = static_cast<int>(nv.edge >> 3);
            const double ga = std::max(0.0, corner_g_[cube[ca]]);
            const double gb = std::min(0.0, corner_g_[cube[cb]]);
            const double t_param = ga - gb > 0.0 ? ga / (ga - gb) : 0.5;
            int i, j, k;
            grid_unkey(cells_[nv.cell], i, j, k);
            const Vec3 pa =
                field_.grid.position(i + (ca & 1), j + ((ca >> 1) & 1), k + ((ca >> 2) & 1));
            const Vec3 pb =
                field_.grid.position(i + (cb & 1), j + ((cb >> 1) & 1), k + ((cb >> 2) & 1));
            mesh.vertices[v] = pa + t_param * (pb - pa);
          }
        });
  }

  const SampledField& field_;
  const int fc_;
  const std::vector<std::uint64_t>& cells_;
  // Per cell, its cube corner c (offset (c & 1, (c >> 1) & 1, (c >> 2) & 1)) in `corners_`.
  std::vector<std::uint32_t> cell_corners_;
  const std::vector<std::uint64_t> corners_;
  std::vector<std::uint32_t> corner_rows_;
  std::vector<std::uint16_t> corner_labels_;  // labels are function indices
  std::vector<std::vector<CellTriangle>> chunk_triangles_;
  std::vector<std::uint32_t> vertex_of_edge_;
  std::vector<double> corner_g_;
};

}  // namespace

std::vector<TriangleMesh> extract_label_surfaces(const SampledField& field) {
  const int fc = field.function_count;
  std::vector<TriangleMesh> meshes(static_cast<std::size_t>(std::max(0, fc - 1)));
  if (fc < 2) return meshes;
  BandMesher mesher(field);
  for (int material = 1; material < fc; ++material)
    meshes[static_cast<std::size_t>(material - 1)] = mesher.mesh(material);
  return meshes;
}

}  // namespace sonoshape::recon
