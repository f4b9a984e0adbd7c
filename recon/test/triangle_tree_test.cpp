// The far-field tree of the unknown triangles against the exact triangle-by-triangle sums.
#include "triangle_tree.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>
#include <vector>

namespace sonoshape::recon::triangle_tree_test {
namespace {

// Reference moments: the triangle split into n^2 similar pieces, each integrated with the
// 7-point degree-5 rule of Strang and Fix (an independent rule in barycentric coordinates).
std::vector<double> reference_moments(const Vec2 (&c)[3], const double (&r)[3], const Vec2& centre,
                                      int n) {
  static const double kA = 0.059715871789770, kB = 0.470142064105115, kC = 0.797426985353087,
                      kD = 0.101286507323456, kW0 = 0.225, kW1 = 0.132394152788506,
                      kW2 = 0.125939180544827;
  const double bary[7][3] = {{1.0 / 3, 1.0 / 3, 1.0 / 3},
                             {kA, kB, kB},
                             {kB, kA, kB},
                             {kB, kB, kA},
                             {kC, kD, kD},
                             {kD, kC, kD},
                             {kD, kD, kC}};
  const double weight[7] = {kW0, kW1, kW1, kW1, kW2, kW2, kW2};
  std::vector<double> out(kTriangleMomentCount, 0.0);
  const double area =
      0.5 * std::abs((c[1] - c[0]).x() * (c[2] - c[0]).y() - (c[1] - c[0]).y() * (c[2] - c[0]).x());
  auto piece = [&](const double(&l)[3][2]) {
    for (int q = 0; q < 7; ++q) {
      double s = 0, t = 0;
      for (int k = 0; k < 3; ++k) {
        s += bary[q][k] * l[k][0];
        t += bary[q][k] * l[k][1];
      }
      // Barycentrics of the big triangle: (1 - s - t, s, t).
      const double lambda[3] = {1.0 - s - t, s, t};
      const Vec2 y = lambda[0] * c[0] + lambda[1] * c[1] + lambda[2] * c[2] - centre;
      const double rho = lambda[0] * r[0] + lambda[1] * r[1] + lambda[2] * r[2];
      const std::complex<double> z(y.x(), y.y());
      for (int a = 0; a <= kTriangleTreeOrder; ++a)
        for (int b = 0; b <= a && a + b <= kTriangleTreeOrder; ++b) {
          const std::complex<double> value =
              weight[q] * area / (n * n) * rho * std::pow(z, a) * std::pow(std::conj(z), b);
          out[2 * triangle_moment_index(a, b)] += value.real();
          out[2 * triangle_moment_index(a, b) + 1] += value.imag();
        }
    }
  };
  // Pieces with corners on the barycentric lattice (i, j) / n: upright and inverted.
  for (int i = 0; i < n; ++i)
    for (int j = 0; i + j < n; ++j) {
      const double a = 1.0 / n;
      const double up[3][2] = {{i * a, j * a}, {(i + 1) * a, j * a}, {i * a, (j + 1) * a}};
      piece(up);
      if (i + j + 1 < n) {
        const double down[3][2] = {
            {(i + 1) * a, j * a}, {(i + 1) * a, (j + 1) * a}, {i * a, (j + 1) * a}};
        piece(down);
      }
    }
  return out;
}

TEST(TriangleTree, MomentsOfALinearDensityAreExact) {
  const Vec2 c[3] = {Vec2(3.0, -1.0), Vec2(11.0, 2.5), Vec2(4.5, 7.0)};
  const double r[3] = {0.2, 0.9, 0.45};
  const Vec2 centre(5.0, 1.5);
  std::vector<double> moments(kTriangleMomentCount, 0.0);
  add_triangle_moments(c, r, centre, moments.data());
  // Pieces of a fiftieth of the size: the rule is exact to degree 5 and the error of the higher
  // moments shrinks like the piece size to the 6th power.
  const std::vector<double> reference = reference_moments(c, r, centre, 50);
  const double radius = 8.0;  // about the largest |z| over the triangle
  for (int a = 0; a <= kTriangleTreeOrder; ++a)
    for (int b = 0; b <= a && a + b <= kTriangleTreeOrder; ++b)
      for (int part = 0; part < 2; ++part) {
        const std::size_t k = 2 * triangle_moment_index(a, b) + static_cast<std::size_t>(part);
        EXPECT_NEAR(moments[k], reference[k], 1e-11 * moments[0] * std::pow(radius, a + b))
            << "Z_" << a << b << (part ? " imaginary" : " real");
      }

  // The closed forms up to degree 2 (integrals of products of barycentrics), in Cartesian form:
  // Z_10 = Mx + i My, Z_11 = Mxx + Myy, Z_20 = Mxx - Myy + 2 i Mxy.
  const Vec2 p[3] = {c[0] - centre, c[1] - centre, c[2] - centre};
  const double area =
      0.5 * std::abs((c[1] - c[0]).x() * (c[2] - c[0]).y() - (c[1] - c[0]).y() * (c[2] - c[0]).x());
  EXPECT_NEAR(moments[0], area * (r[0] + r[1] + r[2]) / 3.0, 1e-12 * area);
  const Vec2 sum = p[0] + p[1] + p[2];
  Vec2 first = Vec2::Zero();
  for (int i = 0; i < 3; ++i) first += area / 12.0 * r[i] * (sum + p[i]);
  EXPECT_NEAR(moments[2 * triangle_moment_index(1, 0)], first.x(), 1e-11 * area);
  EXPECT_NEAR(moments[2 * triangle_moment_index(1, 0) + 1], first.y(), 1e-11 * area);
  Eigen::Matrix2d second = Eigen::Matrix2d::Zero();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) {
        const double integral = (i == j && j == k)             ? area / 10.0
                                : (i == j || j == k || i == k) ? area / 30.0
                                                               : area / 60.0;
        second += r[i] * integral * p[j] * p[k].transpose();
      }
  EXPECT_NEAR(moments[2 * triangle_moment_index(1, 1)], second(0, 0) + second(1, 1), 1e-10 * area);
  EXPECT_NEAR(moments[2 * triangle_moment_index(2, 0)], second(0, 0) - second(1, 1), 1e-10 * area);
  EXPECT_NEAR(moments[2 * triangle_moment_index(2, 0) + 1], 2.0 * second(0, 1), 1e-10 * area);
}

// A square of side 100 mm in a jittered grid of 22 x 22 cells (968 triangles, counter-clockwise),
// with random completed values at every corner of every triangle.
struct Mesh {
  std::vector<UnknownTriangle> triangles;
  std::vector<double> values;
};

Mesh square_mesh(int functions, std::mt19937& rng) {
  const int n = 22;
  const double step = 100.0 / n;
  std::uniform_real_distribution<double> jitter(-0.3 * step, 0.3 * step), value(-1.0, 1.0);
  std::vector<Vec2> grid;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      Vec2 p(i * step, j * step);
      if (i > 0 && i < n) p.x() += jitter(rng);
      if (j > 0 && j < n) p.y() += jitter(rng);
      grid.push_back(p);
    }
  Mesh mesh;
  auto at = [&](int i, int j) { return grid[static_cast<std::size_t>(j * (n + 1) + i)]; };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      mesh.triangles.push_back({{at(i, j), at(i + 1, j), at(i + 1, j + 1)}, 0});
      mesh.triangles.push_back({{at(i, j), at(i + 1, j + 1), at(i, j + 1)}, 0});
    }
  for (std::size_t k = 0; k < mesh.triangles.size() * 3 * static_cast<std::size_t>(functions); ++k)
    mesh.values.push_back(value(rng));
  return mesh;
}

TEST(TriangleTree, MatchesTheExactSumsNearAndFar) {
  constexpr int kFunctions = 3;
  std::mt19937 rng(7);
  Mesh mesh = square_mesh(kFunctions, rng);
  const Mesh original = mesh;
  std::vector<TriangleNode> nodes;
  std::vector<double> moments;
  const std::uint32_t root = build_triangle_tree(mesh.triangles.data(), mesh.values.data(),
                                                 mesh.triangles.size(), kFunctions, nodes, moments);
  ASSERT_EQ(moments.size(), nodes.size() * triangle_moment_stride(kFunctions));

  std::uniform_real_distribution<double> near_foot(-20.0, 120.0), far_foot(-400.0, 500.0);
  std::uniform_real_distribution<double> log_height(-4.0, 0.0), far_log_height(0.0, 2.5);
  double worst_total = 0.0, worst_ratio = 0.0;
  for (int k = 0; k < 600; ++k) {
    const bool far = k % 3 == 2;
    const Vec2 foot =
        far ? Vec2(far_foot(rng), far_foot(rng)) : Vec2(near_foot(rng), near_foot(rng));
    const double height = std::pow(10.0, far ? far_log_height(rng) : log_height(rng));
    double exact_w[kFunctions] = {}, tree_w[kFunctions] = {};
    // The reference on the triangles' order on entry: the sums do not depend on the layout.
    add_triangle_weights(original.triangles.data(), original.values.data(),
                         original.triangles.size(), kFunctions, foot, height, exact_w);
    add_triangle_weights_tree(mesh.triangles.data(), mesh.values.data(), kFunctions, nodes.data(),
                              moments.data(), root, foot, height, tree_w);
    double exact_total = 0.0, tree_total = 0.0;
    for (int l = 0; l < kFunctions; ++l) {
      exact_total += exact_w[l];
      tree_total += tree_w[l];
    }
    for (int l = 0; l < kFunctions; ++l) {
      worst_total = std::max(worst_total, std::abs(tree_w[l] - exact_w[l]) / exact_w[l]);
      worst_ratio =
          std::max(worst_ratio, std::abs(tree_w[l] / tree_total - exact_w[l] / exact_total));
    }
  }
  EXPECT_LT(worst_total, 1e-5);
  EXPECT_LT(worst_ratio, 1e-6);
  RecordProperty("worst_relative", std::to_string(worst_total));
  RecordProperty("worst_ratio", std::to_string(worst_ratio));
}

TEST(TriangleTree, LayoutDependsOnlyOnTheSetOfTriangles) {
  constexpr int kFunctions = 2;
  std::mt19937 rng(11);
  Mesh a = square_mesh(kFunctions, rng);
  // The same triangles shuffled, with their corners rotated.
  std::vector<std::size_t> permutation(a.triangles.size());
  for (std::size_t i = 0; i < permutation.size(); ++i) permutation[i] = i;
  std::shuffle(permutation.begin(), permutation.end(), rng);
  Mesh b;
  for (std::size_t i = 0; i < permutation.size(); ++i) {
    const std::size_t t = permutation[i];
    const int shift = static_cast<int>(i % 3);
    UnknownTriangle triangle = a.triangles[t];
    for (int k = 0; k < 3; ++k) {
      const int from = (k + shift) % 3;
      triangle.corners[k] = a.triangles[t].corners[from];
      for (int l = 0; l < kFunctions; ++l)
        b.values.push_back(a.values[(t * 3 + static_cast<std::size_t>(from)) * kFunctions +
                                    static_cast<std::size_t>(l)]);
    }
    b.triangles.push_back(triangle);
  }
  std::vector<TriangleNode> nodes_a, nodes_b;
  std::vector<double> moments_a, moments_b;
  build_triangle_tree(a.triangles.data(), a.values.data(), a.triangles.size(), kFunctions, nodes_a,
                      moments_a);
  build_triangle_tree(b.triangles.data(), b.values.data(), b.triangles.size(), kFunctions, nodes_b,
                      moments_b);
  ASSERT_EQ(nodes_a.size(), nodes_b.size());
  for (std::size_t n = 0; n < nodes_a.size(); ++n) {
    EXPECT_EQ(nodes_a[n].first, nodes_b[n].first);
    EXPECT_EQ(nodes_a[n].last, nodes_b[n].last);
    EXPECT_EQ(nodes_a[n].centre, nodes_b[n].centre);
    EXPECT_EQ(nodes_a[n].radius_sq, nodes_b[n].radius_sq);
  }
  // Equal up to rounding, which is relative to mass * radius^degree (odd moments cancel).
  const std::size_t stride = triangle_moment_stride(kFunctions);
  for (std::size_t n = 0; n < nodes_a.size(); ++n)
    for (std::size_t density = 0; density < kFunctions; ++density)
      for (int a = 0; a <= kTriangleTreeOrder; ++a)
        for (int b = 0; b <= a && a + b <= kTriangleTreeOrder; ++b)
          for (std::size_t part = 0; part < 2; ++part) {
            const std::size_t m = n * stride + density * kTriangleMomentCount +
                                  2 * triangle_moment_index(a, b) + part;
            const double scale =
                moments_a[n * stride] * std::pow(nodes_a[n].radius_sq, 0.5 * (a + b));
            EXPECT_NEAR(moments_a[m], moments_b[m], 1e-13 * scale);
          }
  // Same triangle at every position (up to the corner rotation).
  for (std::size_t t = 0; t < a.triangles.size(); ++t) {
    double sum_a = 0.0, sum_b = 0.0;
    for (int k = 0; k < 3; ++k) {
      sum_a += a.triangles[t].corners[k].x() + 7.0 * a.triangles[t].corners[k].y();
      sum_b += b.triangles[t].corners[k].x() + 7.0 * b.triangles[t].corners[k].y();
    }
    EXPECT_NEAR(sum_a, sum_b, 1e-9);
  }
}

}  // namespace
}  // namespace sonoshape::recon::triangle_tree_test
