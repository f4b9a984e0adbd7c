#pragma once
// Triangle meshes as plain arrays: the output of reconstruction and the input of evaluation.
#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape {

/// An indexed triangle mesh; triangles are counter-clockwise seen from outside.
struct TriangleMesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<std::uint32_t, 3>> triangles;

  bool empty() const { return triangles.empty(); }
  Box3 bounds() const;
};

/// One closed surface per material label.
struct MeshSet {
  struct Entry {
    int label = 1;
    std::string name;
    TriangleMesh mesh;
  };
  std::vector<Entry> meshes;  ///< sorted by label
};

/// Topological health of a triangle mesh, as `sonoshape evaluate` reports it.
struct MeshHealth {
  std::size_t boundary_edges = 0;         ///< edges used by one triangle
  std::size_t non_manifold_edges = 0;     ///< edges used by more than two triangles
  std::size_t misoriented_edges = 0;      ///< edges used twice in the same direction
  std::size_t non_manifold_vertices = 0;  ///< vertices whose triangle fan is not one disc
  std::size_t degenerate_triangles = 0;   ///< triangles repeating a vertex index or of zero area
  bool closed_manifold_oriented() const {
    return boundary_edges == 0 && non_manifold_edges == 0 && misoriented_edges == 0 &&
           non_manifold_vertices == 0 && degenerate_triangles == 0;
  }
};

/// Counts the defects above (combinatorial, by vertex indices, except zero-area triangles).
MeshHealth check_mesh_health(const TriangleMesh& mesh);

/// Enclosed volume (divergence theorem); positive for an outward-oriented closed mesh.
double signed_volume(const TriangleMesh& mesh);

}  // namespace sonoshape
