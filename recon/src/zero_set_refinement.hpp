#pragma once
// Where the surface bends, a marching-tetrahedra mesh's triangles are chords of it: a circle of
// radius r meshed with chords c loses about c^2 / (12 r) of its radius (a 4.8 mm rib with the
// default depth's 0.9 mm cells, 0.6 % of its section), and its vertices, the zeros of g
// interpolated linearly along cell edges, lie off the zero set of a field that is not linear
// there. Moving them onto it, and splitting the bent edges at midpoints moved onto it, leaves a
// quarter of the chords' loss.
#include <functional>
#include <vector>

#include "sonoshape/core/mesh.hpp"

namespace sonoshape::recon {

/// The field's function_count values at each point (function_count doubles per point).
using PointFieldEvaluator = std::function<void(const std::vector<Vec3>& points, double* values)>;

struct ZeroSetRefinement {
  int material = 1;        ///< the mesh's function index
  int function_count = 2;  ///< values per point the evaluator writes
  double cell_size_mm = 1.0;
  /// An edge is split where the arc between its vertices (estimated from their normals) lies
  /// more than this share of a cell off its chord.
  double min_sagitta_cells = 0.01;
};

/// Moves every vertex of `mesh` along its normal onto the zero set of g = f_m - max_{k != m} f_k,
/// and splits each edge along which the surface bends (above) at its midpoint moved likewise
/// along its endpoints' mean normal, each triangle into 2, 3 or 4 accordingly. A point moves by
/// a secant step within a fifth of a cell, and stays where the step is longer. A closed, manifold,
/// oriented mesh stays so (its connectivity is only refined); the same mesh in gives the same mesh
/// out. Returns the number of edges split.
std::size_t refine_on_zero_set(TriangleMesh& mesh, const ZeroSetRefinement& options,
                               const PointFieldEvaluator& evaluate);

}  // namespace sonoshape::recon
