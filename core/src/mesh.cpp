#include "sonoshape/core/mesh.hpp"

#include <algorithm>
#include <limits>
#include <numeric>
#include <unordered_map>
#include <unordered_set>

#include "sonoshape/core/mesh_components.hpp"

namespace sonoshape {

Box3 TriangleMesh::bounds() const {
  Box3 box{Vec3::Constant(std::numeric_limits<double>::infinity()),
           Vec3::Constant(-std::numeric_limits<double>::infinity())};
  for (const Vec3& p : vertices) {
    box.min = box.min.cwiseMin(p);
    box.max = box.max.cwiseMax(p);
  }
  return box;
}

namespace {
std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return (static_cast<std::uint64_t>(a) << 32) | b;
}
// Zero area relative to the triangle's size: |cross| at most 1e-12 of the longest edge squared
// (rounding of collinear points), or any vertex index out of range / non-finite.
bool zero_area(const TriangleMesh& mesh, const std::array<std::uint32_t, 3>& t) {
  if (t[0] >= mesh.vertices.size() || t[1] >= mesh.vertices.size() || t[2] >= mesh.vertices.size())
    return false;  // the index is the defect, not the area; other checks see it
  const Vec3& a = mesh.vertices[t[0]];
  const Vec3& b = mesh.vertices[t[1]];
  const Vec3& c = mesh.vertices[t[2]];
  const double longest =
      std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  return (b - a).cross(c - a).norm() <= 1e-12 * longest;
}

}  // namespace

MeshHealth check_mesh_health(const TriangleMesh& mesh) {
  MeshHealth health;
  // Directed edge counts: a closed oriented manifold uses each directed edge exactly once and
  // its reverse exactly once.
  std::unordered_map<std::uint64_t, int> directed;
  directed.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      ++health.degenerate_triangles;
      continue;
    }
    // A triangle of three distinct but collinear (or coincident) points has no area: a mesh
    // of such triangles encloses nothing, however well its edges pair up.
    if (zero_area(mesh, t)) ++health.degenerate_triangles;
    for (int k = 0; k < 3; ++k) ++directed[edge_key(t[k], t[(k + 1) % 3])];
  }
  for (const auto& [key, count] : directed) {
    const auto a = static_cast<std::uint32_t>(key >> 32);
    const auto b = static_cast<std::uint32_t>(key & 0xffffffffu);
    const auto reverse = directed.find(edge_key(b, a));
    const int reverse_count = reverse == directed.end() ? 0 : reverse->second;
    if (a < b || reverse_count == 0) {  // visit each undirected edge once
      const int total = count + reverse_count;
      if (total == 1)
        ++health.boundary_edges;
      else if (total > 2)
        ++health.non_manifold_edges;
      else if (count == 2 || reverse_count == 2)
        ++health.misoriented_edges;
    }
  }
  // Vertex fans: the triangles around a manifold vertex form a single cycle. Count the
  // connected components of each vertex's link (edges opposite the vertex).
  std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> link(mesh.vertices.size());
  for (const auto& t : mesh.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
    for (int k = 0; k < 3; ++k) link[t[k]].push_back({t[(k + 1) % 3], t[(k + 2) % 3]});
  }
  for (const auto& edges : link) {
    if (edges.empty()) continue;
    // Union-find over the link's vertices.
    std::unordered_map<std::uint32_t, std::uint32_t> parent;
    auto find = [&](std::uint32_t x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    for (const auto& [a, b] : edges) {
      parent.try_emplace(a, a);
      parent.try_emplace(b, b);
    }
    for (const auto& [a, b] : edges) parent[find(a)] = find(b);
    std::unordered_set<std::uint32_t> roots;
    for (const auto& [x, p] : parent) roots.insert(find(x));
    if (roots.size() > 1) ++health.non_manifold_vertices;
  }
  return health;
}

double signed_volume(const TriangleMesh& mesh) {
  double six_volume = 0.0;
  for (const auto& t : mesh.triangles) {
    const Vec3& a = mesh.vertices[t[0]];
    const Vec3& b = mesh.vertices[t[1]];
    const Vec3& c = mesh.vertices[t[2]];
    six_volume += a.dot(b.cross(c));
  }
  return six_volume / 6.0;
}

MeshParts mesh_parts(const TriangleMesh& mesh) {
  // Union-find over the vertices, with path halving.
  std::vector<std::uint32_t> parent(mesh.vertices.size());
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](std::uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& t : mesh.triangles) {
    parent[find(t[1])] = find(t[0]);
    parent[find(t[2])] = find(t[0]);
  }
  MeshParts parts;
  constexpr std::uint32_t kNone = ~0u;
  std::vector<std::uint32_t> number_of_root(mesh.vertices.size(), kNone);
  parts.part_of_triangle.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    std::uint32_t& number = number_of_root[find(t[0])];
    if (number == kNone) number = static_cast<std::uint32_t>(parts.count++);
    parts.part_of_triangle.push_back(number);
  }
  return parts;
}

}  // namespace sonoshape
