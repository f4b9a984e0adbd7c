#pragma once
// Far-field evaluation of the completed unknown triangles of a face.
//
// Each unknown triangle adds its three mean-value corner weights w_k (triangle_weights,
// mean_value.hpp) to the unknown total and 0.5 w_k (1 + v_kl) to every function l. Summed over
// the triangle these are integrals of the kernel K(y) = 2 h / (|y - foot|^2 + h^2)^2 against a
// density that is linear on the triangle: 1 for the total, 0.5 (1 + g_l) for function l (g_l the
// linear interpolant of the corner values). The trees expand the functions' densities only: for
// completed values they sum to 1, so the total is their sum (triangle_moment_stride). A face of a
// slice with a field of view carries
// hundreds of triangles, most of them far from the point; for a cluster of triangles, the
// integral is replaced by the Taylor expansion of K about the cluster's centre, to order
// kTriangleTreeOrder, against the cluster's exact moments of each density (precomputed, in
// complex form: z^a conj(z)^b with z = y - centre, which makes the kernel's coefficients a short
// closed form). Near the point, the cluster's halves are visited down to leaves of a few
// triangles, which are summed exactly. Same trade as chain_tree.hpp, for area densities; the
// second order that suffices there (where only a thin region is expanded) would need an opening
// under 0.1 here for 1e-5 relative accuracy, which saves almost nothing on coarse triangles.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon {

/// A triangle of a face's unknown part; its corners carry completed values of every function.
struct UnknownTriangle {
  Vec2 corners[3];
  int component = -1;  ///< the slice's unknown component it lies in
};

/// A node of the tree over the triangles [first, last) of a face: its bounding circle (over all
/// corners) and children. Its moments are at moments[node index * stride] (see
/// build_triangle_tree).
struct TriangleNode {
  Vec2 centre;
  double radius_sq = 0;                ///< bounding circle of the corners, squared
  std::uint32_t first = 0, last = 0;   ///< relative to the face's first triangle
  std::int32_t left = -1, right = -1;  ///< children (-1: a leaf, summed triangle by triangle)
};

/// Faces with at least this many triangles get a tree; fewer are summed directly.
constexpr std::size_t kTriangleTreeMinTriangles = 16;

/// Degree of the Taylor expansion of the kernel (and of the moments kept per node).
constexpr int kTriangleTreeOrder = 12;

/// Index of the complex moment Z_ab = integral of rho z^a conj(z)^b (z = y - centre as a complex
/// number) among those kept: a >= b (the others are conjugates), a + b <= kTriangleTreeOrder,
/// ordered by degree a + b, then by b.
constexpr std::size_t triangle_moment_index(int a, int b) {
  std::size_t index = 0;
  for (int n = 0; n < a + b; ++n) index += static_cast<std::size_t>(n / 2 + 1);
  return index + static_cast<std::size_t>(b);
}

/// Doubles of moments per density: (real, imaginary) of each Z_ab, in triangle_moment_index order.
constexpr std::size_t kTriangleMomentCount = 2 * triangle_moment_index(kTriangleTreeOrder + 1, 0);

/// Doubles of moments per node: densities 0.5 (1 + g_l) for l = 0..function_count-1. The
/// completed values are a partition of unity (these densities sum to 1: formula 7 splits one
/// denominator among the functions), so the unknown total is their sum and has no moments of
/// its own (a third fewer moments to build and read with one label).
constexpr std::size_t triangle_moment_stride(int function_count) {
  return static_cast<std::size_t>(function_count) * kTriangleMomentCount;
}

/// Exact moments of the linear density with corner values `density` over the triangle
/// `corners`, about `centre`, added to `out` (kTriangleMomentCount doubles).
void add_triangle_moments(const Vec2 (&corners)[3], const double (&density)[3], const Vec2& centre,
                          double* out);

/// Builds the tree of the `count` triangles of one face and appends it to `nodes` (root first),
/// with triangle_moment_stride(function_count) doubles per node appended to `moments` (kept the
/// size of nodes times the stride). Reorders the triangles and their corner values (3 corners x
/// function_count per triangle, as in CellField) into the tree's order, which depends only on
/// the set of triangles, not on their order on entry. Returns the root's index.
std::uint32_t build_triangle_tree(UnknownTriangle* triangles, double* corner_values,
                                  std::size_t count, int function_count,
                                  std::vector<TriangleNode>& nodes, std::vector<double>& moments);

/// The exact sums over `count` triangles seen from (foot, height): w[l] += sum of
/// 0.5 w_k (1 + v_kl) (units of projected_angle / height). For completed values (a partition of
/// unity) the triangles' total weight is the sum of the w[l].
void add_triangle_weights(const UnknownTriangle* triangles, const double* corner_values,
                          std::size_t count, int function_count, const Vec2& foot, double height,
                          double* w);

/// The sums w[l] of add_triangle_weights through the tree `root` (build_triangle_tree): exact
/// over the leaves near the point, expansions over the nodes seen under a small angle. No
/// unknown total: for completed values (a partition of unity) it is the sum of the w[l].
void add_triangle_weights_tree(const UnknownTriangle* triangles, const double* corner_values,
                               int function_count, const TriangleNode* nodes, const double* moments,
                               std::uint32_t root, const Vec2& foot, double height, double* w);

/// The constants of add_triangle_weights_tree for a device evaluator (kernels/cl/field.cl):
/// (a, b) of each moment pair in triangle_moment_index order, the expansion's coefficients
/// (kTriangleTreeOrder / 2 + 1 per pair) and the truncation bound of each degree (0 to
/// kTriangleTreeOrder).
void triangle_tree_tables(std::vector<int>& pairs, std::vector<double>& kernel_table,
                          std::vector<double>& truncation);

}  // namespace sonoshape::recon
