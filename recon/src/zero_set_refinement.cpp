#include "zero_set_refinement.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

namespace sonoshape::recon {
namespace {

constexpr std::uint32_t kNoVertex = 0xffffffffu;

// Area-weighted vertex normals (the sum of the incident triangles' cross products), unit length.
std::vector<Vec3> vertex_normals(const TriangleMesh& mesh) {
  std::vector<Vec3> normals(mesh.vertices.size(), Vec3::Zero());
  for (const auto& t : mesh.triangles) {
    const Vec3 n = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                       .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    for (const std::uint32_t v : t) normals[v] += n;
  }
  for (Vec3& n : normals) {
    const double length = n.norm();
    if (length > 0.0) n /= length;
  }
  return normals;
}

// Per half-edge (3 t + e: from triangles[t][e] to the next vertex), the index of its edge's new
// vertex in `edges`, kNoVertex where the edge is not split. Both half-edges of an edge take the
// same decision (it depends on the two vertices alone). An edge is numbered at its half-edge
// from the lower vertex to the higher, in triangle order; the other half-edge finds that
// number among the lower vertex's numbered half-edges (listed per vertex by a counting sort).
std::vector<std::uint32_t> number_split_edges(const TriangleMesh& mesh,
                                              const std::vector<Vec3>& normals,
                                              double min_sagitta_mm,
                                              std::vector<std::array<std::uint32_t, 2>>& edges) {
  const std::size_t half_edges = mesh.triangles.size() * 3;
  std::vector<std::uint32_t> number(half_edges, kNoVertex);
  std::vector<char> bent(half_edges, 0);
  std::vector<std::uint32_t> row_start(mesh.vertices.size() + 1, 0);
  for (std::size_t h = 0; h < half_edges; ++h) {
    const std::uint32_t a = mesh.triangles[h / 3][h % 3], b = mesh.triangles[h / 3][(h + 1) % 3];
    // An arc of angle theta over a chord c lies c * theta / 8 off it; theta^2 ~ 2 (1 - cos).
    const double chord2 = (mesh.vertices[a] - mesh.vertices[b]).squaredNorm();
    const double theta2 = 2.0 * (1.0 - normals[a].dot(normals[b]));
    if (chord2 * theta2 <= 64.0 * min_sagitta_mm * min_sagitta_mm) continue;
    bent[h] = 1;
    if (a < b) {
      number[h] = static_cast<std::uint32_t>(edges.size());
      edges.push_back({a, b});
      ++row_start[a + 1];
    }
  }
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) row_start[v + 1] += row_start[v];
  std::vector<std::uint32_t> row_fill(row_start.begin(), row_start.end() - 1);
  std::vector<std::uint32_t> row_edges(edges.size());
  for (std::uint32_t n = 0; n < edges.size(); ++n) row_edges[row_fill[edges[n][0]]++] = n;
  for (std::size_t h = 0; h < half_edges; ++h) {
    const std::uint32_t a = mesh.triangles[h / 3][h % 3], b = mesh.triangles[h / 3][(h + 1) % 3];
    if (!bent[h] || a < b) continue;
    for (std::uint32_t k = row_start[b]; k < row_start[b + 1]; ++k)
      if (edges[row_edges[k]][1] == a) number[h] = row_edges[k];
  }
  return number;
}

// g = f_m - max_{k != m} f_k at each point.
std::vector<double> label_margin(const std::vector<Vec3>& points, const ZeroSetRefinement& options,
                                 const PointFieldEvaluator& evaluate) {
  const std::size_t fc = static_cast<std::size_t>(options.function_count);
  std::vector<double> values(points.size() * fc);
  if (!points.empty()) evaluate(points, values.data());
  std::vector<double> g(points.size());
  for (std::size_t p = 0; p < points.size(); ++p) {
    const double* row = values.data() + p * fc;
    double other = -std::numeric_limits<double>::infinity();
    for (std::size_t l = 0; l < fc; ++l)
      if (static_cast<int>(l) != options.material) other = std::max(other, row[l]);
    g[p] = row[options.material] - other;
  }
  return g;
}

// Each start moved along its direction to the zero of g by one secant step: g at the start and
// a tenth of a cell towards the zero (outward where g > 0: the normals point out of the region).
// The points lie within a few hundredths of a cell of the zero set, where the step is as good
// as Newton's. A step against the slope's sign or beyond a fifth of a cell (a thin part's tip,
// where g is far from linear) is not taken.
std::vector<Vec3> project_on_zero_set(const std::vector<Vec3>& starts,
                                      const std::vector<Vec3>& directions,
                                      const ZeroSetRefinement& options,
                                      const PointFieldEvaluator& evaluate) {
  const std::size_t count = starts.size();
  const double probe = 0.1 * options.cell_size_mm, reach = 0.2 * options.cell_size_mm;
  const std::vector<double> g0 = label_margin(starts, options, evaluate);
  std::vector<Vec3> points(count);
  for (std::size_t n = 0; n < count; ++n)
    points[n] = starts[n] + (g0[n] > 0.0 ? probe : -probe) * directions[n];
  const std::vector<double> g1 = label_margin(points, options, evaluate);
  for (std::size_t n = 0; n < count; ++n) {
    const double d1 = g0[n] > 0.0 ? probe : -probe;
    const double slope = (g1[n] - g0[n]) / d1;
    const double offset = slope < 0.0 ? -g0[n] / slope : 0.0;
    points[n] = starts[n] + (std::abs(offset) <= reach ? offset : 0.0) * directions[n];
  }
  return points;
}

// Triangle (a, b, c) with the midpoints m0 of ab, m1 of bc, m2 of ca (kNoVertex: not split),
// replaced by its parts, oriented as it was.
void split_triangle(const std::array<std::uint32_t, 3>& v, const std::array<std::uint32_t, 3>& m,
                    const std::vector<Vec3>& positions,
                    std::vector<std::array<std::uint32_t, 3>>& out) {
  const int count = (m[0] != kNoVertex) + (m[1] != kNoVertex) + (m[2] != kNoVertex);
  if (count == 0) {
    out.push_back(v);
  } else if (count == 3) {
    out.push_back({v[0], m[0], m[2]});
    out.push_back({m[0], v[1], m[1]});
    out.push_back({m[2], m[1], v[2]});
    out.push_back({m[0], m[1], m[2]});
  } else if (count == 1) {
    const std::size_t e = m[0] != kNoVertex ? 0 : (m[1] != kNoVertex ? 1 : 2);
    const std::uint32_t a = v[e], b = v[(e + 1) % 3], c = v[(e + 2) % 3];
    out.push_back({a, m[e], c});
    out.push_back({m[e], b, c});
  } else {
    // Rotated so that the edge (c, a) is the whole one: (a, m0, b, m1, c) around.
    const std::size_t whole = m[0] == kNoVertex ? 0 : (m[1] == kNoVertex ? 1 : 2);
    const std::size_t e = (whole + 1) % 3;
    const std::uint32_t a = v[e], b = v[(e + 1) % 3], c = v[(e + 2) % 3];
    const std::uint32_t m0 = m[e], m1 = m[(e + 1) % 3];
    out.push_back({m0, b, m1});
    // The quad (a, m0, m1, c) along its shorter diagonal.
    if ((positions[a] - positions[m1]).squaredNorm() <=
        (positions[m0] - positions[c]).squaredNorm()) {
      out.push_back({a, m0, m1});
      out.push_back({a, m1, c});
    } else {
      out.push_back({a, m0, c});
      out.push_back({m0, m1, c});
    }
  }
}

}  // namespace

std::size_t refine_on_zero_set(TriangleMesh& mesh, const ZeroSetRefinement& options,
                               const PointFieldEvaluator& evaluate) {
  const std::vector<Vec3> normals = vertex_normals(mesh);
  std::vector<std::array<std::uint32_t, 2>> edges;
  std::vector<std::uint32_t> midpoint =
      number_split_edges(mesh, normals, options.min_sagitta_cells * options.cell_size_mm, edges);
  // Every vertex and the new ones (numbered after them, in the order of `edges`) are moved onto
  // the zero set in one batch: the mesher's vertices interpolate g linearly along their cell
  // edges, which leaves them up to a tenth of a cell off the cubic field's zero set where it
  // bends.
  const std::uint32_t first = static_cast<std::uint32_t>(mesh.vertices.size());
  std::vector<Vec3> starts = mesh.vertices, directions = normals;
  starts.reserve(first + edges.size());
  directions.reserve(first + edges.size());
  for (const auto& [a, b] : edges) {
    starts.push_back(0.5 * (mesh.vertices[a] + mesh.vertices[b]));
    const Vec3 direction = normals[a] + normals[b];
    const double length = direction.norm();
    directions.push_back(length > 0.0 ? Vec3(direction / length) : Vec3::Zero());
  }
  for (std::uint32_t& m : midpoint)
    if (m != kNoVertex) m += first;
  mesh.vertices = project_on_zero_set(starts, directions, options, evaluate);
  std::vector<std::array<std::uint32_t, 3>> triangles;
  triangles.reserve(mesh.triangles.size() + 3 * edges.size());
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    split_triangle(mesh.triangles[t], {midpoint[3 * t], midpoint[3 * t + 1], midpoint[3 * t + 2]},
                   mesh.vertices, triangles);
  mesh.triangles = std::move(triangles);
  return edges.size();
}

}  // namespace sonoshape::recon
