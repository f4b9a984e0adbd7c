#include "triangle_tree.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "mean_value.hpp"
#include "sonoshape/core/target_clones.hpp"

namespace sonoshape::recon {
namespace {

constexpr int kOrder = kTriangleTreeOrder;
constexpr std::size_t kMoments = kTriangleMomentCount;
constexpr std::size_t kPairs = kMoments / 2;
// Triangles per leaf: below this a node is summed triangle by triangle (4 rather than 8: about a
// third fewer exact triangles per evaluation, for twice the nodes).
constexpr std::uint32_t kLeafTriangles = 4;
// Opening criterion: a node is used whole when its bounding radius is below this fraction of its
// distance to the point. The expansion's error falls like kOpening^(order + 1); with order 12,
// 0.35 keeps the sums within ~2e-6 relative of the exact ones (triangle_tree_test), and the
// series converges for ratios below sqrt(2) - 1.
constexpr double kOpening = 0.35;

// Complex arithmetic by hand: std::complex's multiplication checks every product for NaNs (C99
// Annex G recovery), which also keeps it from vectorising.
struct Complex {
  double re, im;  // no default initialisers: the arrays of powers are filled before use
};
inline Complex operator*(const Complex& a, const Complex& b) {
  return {a.re * b.re - a.im * b.im, a.re * b.im + a.im * b.re};
}
inline Complex operator*(double a, const Complex& b) { return {a * b.re, a * b.im}; }
inline Complex& operator+=(Complex& a, const Complex& b) {
  a.re += b.re;
  a.im += b.im;
  return a;
}
inline Complex conj(const Complex& a) { return {a.re, -a.im}; }

struct Pair {
  int a, b;
};
constexpr std::array<Pair, kPairs> make_pairs() {
  std::array<Pair, kPairs> pairs{};
  for (int n = 0; n <= kOrder; ++n)
    for (int b = 0; 2 * b <= n; ++b) pairs[triangle_moment_index(n - b, b)] = {n - b, b};
  return pairs;
}
constexpr std::array<Pair, kPairs> kPairList = make_pairs();

constexpr double factorial(int n) { return n <= 1 ? 1.0 : n * factorial(n - 1); }

// With z = y - centre, d = centre - foot (w = d as a complex number) and s = |d|^2 + h^2,
//   K = 2 h / s^2 (1 + u)^-2 = 2 h / s^2 sum_N (-1)^N (N + 1) u^N,
//   u = (conj(w) z + w conj(z) + z conj(z)) / s,
// and the multinomial expansion of u^N gives the coefficient of z^a conj(z)^b (a >= b) as
//   conj(w)^(a-b) / s^a sum_{k=0..b} F(a, b, k) (|w|^2 / s)^(b-k),
//   F = (-1)^N (N + 1) N! / ((a - k)! (b - k)! k!),  N = a + b - k
// (k factors z conj(z), a - k factors conj(w) z, b - k factors w conj(z)).
constexpr int kMaxK = kOrder / 2 + 1;
constexpr std::array<std::array<double, kMaxK>, kPairs> make_kernel_table() {
  std::array<std::array<double, kMaxK>, kPairs> table{};
  for (std::size_t p = 0; p < kPairs; ++p) {
    const auto [a, b] = kPairList[p];
    for (int k = 0; k <= b; ++k) {
      const int n = a + b - k;
      table[p][static_cast<std::size_t>(k)] = (n % 2 == 0 ? 1.0 : -1.0) * (n + 1) * factorial(n) /
                                              (factorial(a - k) * factorial(b - k) * factorial(k));
    }
  }
  return table;
}
constexpr auto kKernelTable = make_kernel_table();

// Gauss-Legendre points and weights on [0, 1] (Newton on the Legendre polynomial): exact for the
// polynomials of degree up to kOrder + 2 that uniform_moments integrates along the edges.
constexpr int kGauss = kOrder / 2 + 2;
static_assert(2 * kGauss - 1 >= kOrder + 2);
struct GaussRule {
  double x[kGauss], w[kGauss];
};
const GaussRule& gauss_rule() {
  static const GaussRule rule = [] {
    GaussRule r{};
    constexpr double pi = 3.14159265358979323846;
    for (int i = 0; i < kGauss; ++i) {
      double x = std::cos(pi * (i + 0.75) / (kGauss + 0.5)), derivative = 1.0;
      for (int iteration = 0; iteration < 100; ++iteration) {
        double p0 = 1.0, p1 = x;
        for (int k = 2; k <= kGauss; ++k) {
          const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
          p0 = p1;
          p1 = p2;
        }
        derivative = kGauss * (x * p1 - p0) / (x * x - 1.0);
        const double step = p1 / derivative;
        x -= step;
        if (std::abs(step) < 1e-16) break;
      }
      r.x[i] = 0.5 * (1.0 - x);
      r.w[i] = 1.0 / ((1.0 - x * x) * derivative * derivative);  // half the weight on [-1, 1]
    }
    return r;
  }();
  return rule;
}

constexpr std::array<std::array<double, kOrder + 1>, kOrder + 1> make_binomials() {
  std::array<std::array<double, kOrder + 1>, kOrder + 1> c{};
  for (int n = 0; n <= kOrder; ++n)
    for (int k = 0; k <= n; ++k) c[n][k] = factorial(n) / (factorial(k) * factorial(n - k));
  return c;
}
constexpr auto kBinomial = make_binomials();

// Moments of `densities` densities about a new centre: with z' = z + delta,
//   Z'_ab = sum_{i <= a} C(a, i) delta^(a-i) sum_{j <= b} C(b, j) conj(delta)^(b-j) Z_ij,
// the inner sum first (Z_ij for i < j is conj(Z_ji)). The arrays are laid out so that the
// innermost loops run over contiguous doubles with a broadcast factor (the compiler vectorises
// them; every element sees the same operations in the same order as a plain double loop).
// Building the trees is up to a fifth of the completion on the 80 mm sector sets (rocker-arm's).
SONOSHAPE_AVX2_CLONES void add_translated(const double* in, std::size_t densities,
                                          const Vec2& shift, double* out) {
  constexpr int kSide = kOrder + 1;
  const Complex delta{shift.x(), shift.y()};
  Complex powers[kSide];
  Complex power{1.0, 0.0};
  for (int n = 0; n <= kOrder; ++n) {
    powers[n] = power;
    power = power * delta;
  }
  // conj_terms[b][j] = conj(C(b, j) delta^(b-j)); delta_re/im[i][a] = C(a, i) delta^(a-i).
  Complex conj_terms[kSide][kSide];
  alignas(32) double delta_re[kSide][kSide], delta_im[kSide][kSide];  // read only where i <= a
  for (int n = 0; n <= kOrder; ++n)
    for (int k = 0; k <= n; ++k) {
      const Complex term = kBinomial[n][k] * powers[n - k];
      conj_terms[n][k] = conj(term);
      delta_re[k][n] = term.re;
      delta_im[k][n] = term.im;
    }
  for (std::size_t density = 0; density < densities; ++density) {
    const double* z = in + density * kMoments;
    // full_re/im[j][i] = Z_ij for i + j <= kOrder.
    alignas(32) double full_re[kSide][kSide], full_im[kSide][kSide];
    for (std::size_t p = 0; p < kPairs; ++p) {
      const auto [a, b] = kPairList[p];
      full_re[b][a] = z[2 * p];
      full_im[b][a] = z[2 * p + 1];
      full_re[a][b] = z[2 * p];
      full_im[a][b] = -z[2 * p + 1];
    }
    // inner_re/im[b][i] = sum_{j <= b} conj_terms[b][j] Z_ij, for i + b <= kOrder.
    alignas(32) double inner_re[kSide][kSide], inner_im[kSide][kSide];
    for (int b = 0; b <= kOrder; ++b) {
      const int count = kSide - b;
      for (int i = 0; i < count; ++i) inner_re[b][i] = inner_im[b][i] = 0.0;
      for (int j = 0; j <= b; ++j) {
        const double c_re = conj_terms[b][j].re, c_im = conj_terms[b][j].im;
        for (int i = 0; i < count; ++i) {
          const double f_re = full_re[j][i], f_im = full_im[j][i];
          inner_re[b][i] += c_re * f_re - c_im * f_im;
          inner_im[b][i] += c_re * f_im + c_im * f_re;
        }
      }
    }
    // sums_re/im[b][a] = sum_{i <= a} C(a, i) delta^(a-i) inner[b][i], for b <= a, a + b <= kOrder.
    alignas(32) double sums_re[kSide][kSide], sums_im[kSide][kSide];
    for (int b = 0; 2 * b <= kOrder; ++b) {
      const int last = kOrder - b;
      for (int a = b; a <= last; ++a) sums_re[b][a] = sums_im[b][a] = 0.0;
      for (int i = 0; i <= last; ++i) {
        const double n_re = inner_re[b][i], n_im = inner_im[b][i];
        for (int a = std::max(i, b); a <= last; ++a) {
          sums_re[b][a] += delta_re[i][a] * n_re - delta_im[i][a] * n_im;
          sums_im[b][a] += delta_re[i][a] * n_im + delta_im[i][a] * n_re;
        }
      }
    }
    double* target = out + density * kMoments;
    for (std::size_t p = 0; p < kPairs; ++p) {
      const auto [a, b] = kPairList[p];
      target[2 * p] += sums_re[b][a];
      target[2 * p + 1] += sums_im[b][a];
    }
  }
}

// The expansion of K / (2 h / s^2) about a node seen from d = centre - foot, laid out like the
// moments, so that the integral of K against a density is 2 h / s^2 times a plain dot product
// with its moments.
void kernel_coefficients(const Vec2& d, double s, int degree, double* out) {
  const double inv_s = 1.0 / s;
  const Complex w_bar_over_s{d.x() * inv_s, -d.y() * inv_s};
  const double ratio = d.squaredNorm() * inv_s;  // |w|^2 / s < 1
  Complex power[kOrder + 1];                     // (conj(w) / s)^m
  double inv_s_power[kOrder / 2 + 1];
  power[0] = {1.0, 0.0};
  for (int m = 1; m <= degree; ++m) power[m] = power[m - 1] * w_bar_over_s;
  inv_s_power[0] = 1.0;
  for (int m = 1; m <= degree / 2; ++m) inv_s_power[m] = inv_s_power[m - 1] * inv_s;
  const std::size_t pairs = triangle_moment_index(degree + 1, 0);
  for (std::size_t p = 0; p < pairs; ++p) {
    const auto [a, b] = kPairList[p];
    double g = kKernelTable[p][0];
    for (int k = 1; k <= b; ++k) g = g * ratio + kKernelTable[p][static_cast<std::size_t>(k)];
    // conj(w)^(a-b) / s^a = (conj(w) / s)^(a-b) / s^b; Re(h Z) = h.re Z.re - h.im Z.im, and the
    // conjugate pair (b, a) doubles the terms with a > b.
    const double factor = (a > b ? 2.0 : 1.0) * g * inv_s_power[b];
    out[2 * p] = factor * power[a - b].re;
    out[2 * p + 1] = -factor * power[a - b].im;
  }
}

// Moments of the uniform density over a triangle (corners relative to the centre), for every
// degree up to kOrder + 1, by Green's theorem in complex form: the integral of z^a conj(z)^b dA
// is (1 / 2i) times the contour integral of z^a conj(z)^(b+1) / (b + 1) dz, a polynomial of degree
// a + b + 1 along each edge (integrated exactly by kGauss points). Stored transposed, re[b][a] and
// im[b][a] for a >= b, so that the loop over a runs over contiguous doubles (vectorised; these
// moments were half of the trees' building time in `perf record` of a loop building trees).
constexpr int kUniformSide = kOrder + 2;
struct UniformMoments {
  alignas(32) double re[kUniformSide][kUniformSide];
  alignas(32) double im[kUniformSide][kUniformSide];
  // Z_ab for any a, b (conjugate symmetry).
  Complex at(int a, int b) const {
    return a >= b ? Complex{re[b][a], im[b][a]} : Complex{re[a][b], -im[a][b]};
  }
};
SONOSHAPE_AVX2_CLONES void uniform_moments(const Complex (&corners)[3], UniformMoments& out) {
  constexpr int kDegree = kOrder + 1;
  constexpr int kPoints = 3 * kGauss;  // along the three edges
  const GaussRule& rule = gauss_rule();
  // The powers z^n of every point, then step z^a (step: the Gauss weight times the edge), point
  // by point in the same operations as Complex's, but in loops over the points: the chains of
  // products are independent across points (one chain per point was latency-bound).
  alignas(32) double z_re[kPoints], z_im[kPoints], step_re[kPoints], step_im[kPoints];
  for (int k = 0; k < 3; ++k) {
    const Complex p = corners[k], q = corners[(k + 1) % 3];
    const Complex e{q.re - p.re, q.im - p.im};
    for (int g = 0; g < kGauss; ++g) {
      z_re[k * kGauss + g] = p.re + rule.x[g] * e.re;
      z_im[k * kGauss + g] = p.im + rule.x[g] * e.im;
      step_re[k * kGauss + g] = rule.w[g] * e.re;
      step_im[k * kGauss + g] = rule.w[g] * e.im;
    }
  }
  alignas(32) double power_re[kDegree + 2][kPoints], power_im[kDegree + 2][kPoints];
  for (int i = 0; i < kPoints; ++i) {
    power_re[0][i] = 1.0;
    power_im[0][i] = 0.0;
  }
  for (int n = 1; n <= kDegree + 1; ++n)
    for (int i = 0; i < kPoints; ++i) {
      power_re[n][i] = power_re[n - 1][i] * z_re[i] - power_im[n - 1][i] * z_im[i];
      power_im[n][i] = power_re[n - 1][i] * z_im[i] + power_im[n - 1][i] * z_re[i];
    }
  alignas(32) double scaled_re[kPoints][kDegree + 1], scaled_im[kPoints][kDegree + 1];  // step z^a
  for (int a = 0; a <= kDegree; ++a)
    for (int i = 0; i < kPoints; ++i) {
      scaled_re[i][a] = step_re[i] * power_re[a][i] - step_im[i] * power_im[a][i];
      scaled_im[i][a] = step_re[i] * power_im[a][i] + step_im[i] * power_re[a][i];
    }
  for (int b = 0; 2 * b <= kDegree; ++b)
    for (int a = b; a + b <= kDegree; ++a) out.re[b][a] = out.im[b][a] = 0.0;
  // Summed point after point (the order of the sums of the scalar loop it replaced).
  for (int i = 0; i < kPoints; ++i)
    for (int b = 0; 2 * b <= kDegree; ++b) {
      // step z^a * conj(z^(b+1)), as Complex's product writes it.
      const double c_re = power_re[b + 1][i], c_im = -power_im[b + 1][i];
      for (int a = b; a + b <= kDegree; ++a) {
        out.re[b][a] += scaled_re[i][a] * c_re - scaled_im[i][a] * c_im;
        out.im[b][a] += scaled_re[i][a] * c_im + scaled_im[i][a] * c_re;
      }
    }
  // Divide by 2i (b + 1): (x + iy) / 2i = (y - ix) / 2; a clockwise contour counts negative.
  const double orientation =
      (corners[1].re - corners[0].re) * (corners[2].im - corners[0].im) -
                  (corners[1].im - corners[0].im) * (corners[2].re - corners[0].re) <
              0.0
          ? -1.0
          : 1.0;
  for (int b = 0; 2 * b <= kDegree; ++b) {
    const double scale = orientation * 0.5 / (b + 1);
    for (int a = b; a + b <= kDegree; ++a) {
      const double v_re = out.re[b][a], v_im = out.im[b][a];
      out.re[b][a] = scale * v_im;
      out.im[b][a] = -scale * v_re;
    }
  }
}

// Moments of the linear density with corner values `values` over a triangle (corners relative to
// the centre), added to `out`, from the triangle's uniform moments: the density is
// rho = alpha + beta . t = alpha + (conj(B) z + B conj(z)) / 2 with B = beta as a complex number.
void add_linear_moments(const Complex (&corners)[3], const UniformMoments& uniform,
                        const double (&values)[3], double* out) {
  const Complex e1{corners[1].re - corners[0].re, corners[1].im - corners[0].im};
  const Complex e2{corners[2].re - corners[0].re, corners[2].im - corners[0].im};
  const double twice_area = e1.re * e2.im - e1.im * e2.re;
  // Slivers contribute nothing, as in triangle_weights (their gradient would overflow).
  const double longest_sq =
      std::max({e1.re * e1.re + e1.im * e1.im, e2.re * e2.re + e2.im * e2.im,
                (e2.re - e1.re) * (e2.re - e1.re) + (e2.im - e1.im) * (e2.im - e1.im)});
  if (!(std::abs(twice_area) > 1e-12 * longest_sq)) return;
  // The linear interpolant through (corner k, values k), at t = 0 and its gradient.
  const double d1 = values[1] - values[0], d2 = values[2] - values[0];
  const double gx = (d1 * e2.im - d2 * e1.im) / twice_area,
               gy = (d2 * e1.re - d1 * e2.re) / twice_area;
  const double alpha = values[0] - (gx * corners[0].re + gy * corners[0].im);
  const Complex half_b{0.5 * gx, 0.5 * gy}, half_b_conj = conj(half_b);
  for (std::size_t p = 0; p < kPairs; ++p) {
    const auto [a, b] = kPairList[p];
    Complex z = alpha * uniform.at(a, b);
    z += half_b_conj * uniform.at(a + 1, b);
    z += half_b * uniform.at(a, b + 1);
    out[2 * p] += z.re;
    out[2 * p + 1] += z.im;
  }
}

// A total order of the triangles that does not depend on their order or corner rotation:
// centroid along the split axis, then across it, then the sorted corners.
using TriangleKey = std::array<double, 8>;
TriangleKey triangle_key(const UnknownTriangle& triangle) {
  std::array<Vec2, 3> corners{triangle.corners[0], triangle.corners[1], triangle.corners[2]};
  std::sort(corners.begin(), corners.end(), [](const Vec2& a, const Vec2& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  const Vec2 centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
  return {centroid.x(),   centroid.y(),   corners[0].x(), corners[0].y(),
          corners[1].x(), corners[1].y(), corners[2].x(), corners[2].y()};
}

struct Builder {
  const UnknownTriangle* triangles;
  const double* corner_values;
  std::size_t function_count;
  std::size_t stride;
  std::vector<TriangleKey> keys;
  std::vector<std::uint32_t> order;  // position -> triangle on entry
  TriangleNode* nodes;               // room for triangle_tree_node_count nodes from `next` on
  double* moments;                   // the nodes' moments (stride each), zero on entry
  std::uint32_t next;                // index of the next node

  bool less(int axis, std::uint32_t a, std::uint32_t b) const {
    const TriangleKey& ka = keys[a];
    const TriangleKey& kb = keys[b];
    if (ka[static_cast<std::size_t>(axis)] != kb[static_cast<std::size_t>(axis)])
      return ka[static_cast<std::size_t>(axis)] < kb[static_cast<std::size_t>(axis)];
    return ka < kb;
  }

  std::uint32_t build(std::uint32_t first, std::uint32_t last) {
    const std::uint32_t index = next++;
    TriangleNode node;
    node.first = first;
    node.last = last;
    Vec2 lo = triangles[order[first]].corners[0], hi = lo;
    Vec2 centroid_lo = Vec2(keys[order[first]][0], keys[order[first]][1]),
         centroid_hi = centroid_lo;
    for (std::uint32_t i = first; i < last; ++i) {
      for (const Vec2& corner : triangles[order[i]].corners) {
        lo = lo.cwiseMin(corner);
        hi = hi.cwiseMax(corner);
      }
      const Vec2 centroid(keys[order[i]][0], keys[order[i]][1]);
      centroid_lo = centroid_lo.cwiseMin(centroid);
      centroid_hi = centroid_hi.cwiseMax(centroid);
    }
    node.centre = 0.5 * (lo + hi);
    for (std::uint32_t i = first; i < last; ++i)
      for (const Vec2& corner : triangles[order[i]].corners)
        node.radius_sq = std::max(node.radius_sq, (corner - node.centre).squaredNorm());
    if (last - first > kLeafTriangles) {
      // Median split along the longest axis of the centroids' box.
      const Vec2 extent = centroid_hi - centroid_lo;
      const int axis = extent.x() >= extent.y() ? 0 : 1;
      const std::uint32_t middle = first + (last - first) / 2;
      std::nth_element(order.begin() + first, order.begin() + middle, order.begin() + last,
                       [&](std::uint32_t a, std::uint32_t b) { return less(axis, a, b); });
      node.left = static_cast<std::int32_t>(build(first, middle));
      node.right = static_cast<std::int32_t>(build(middle, last));
      for (const std::int32_t child : {node.left, node.right})
        add_translated(&moments[static_cast<std::size_t>(child) * stride], function_count,
                       nodes[static_cast<std::size_t>(child)].centre - node.centre,
                       &moments[index * stride]);
    } else {
      // Leaves in the key order too, so that the whole layout is canonical.
      std::sort(order.begin() + first, order.begin() + last,
                [&](std::uint32_t a, std::uint32_t b) { return less(0, a, b); });
      double* out = &moments[index * stride];
      UniformMoments uniform;
      for (std::uint32_t i = first; i < last; ++i) {
        const UnknownTriangle& triangle = triangles[order[i]];
        Complex corners[3];
        for (int k = 0; k < 3; ++k) {
          const Vec2 t = triangle.corners[k] - node.centre;
          corners[k] = {t.x(), t.y()};
        }
        uniform_moments(corners, uniform);
        // Density l is 0.5 (1 + g_l).
        const double* values =
            corner_values + static_cast<std::size_t>(order[i]) * 3 * function_count;
        for (std::size_t l = 0; l < function_count; ++l) {
          const double half[3] = {0.5 * (1.0 + values[l]), 0.5 * (1.0 + values[function_count + l]),
                                  0.5 * (1.0 + values[2 * function_count + l])};
          add_linear_moments(corners, uniform, half, out + l * kMoments);
        }
      }
    }
    nodes[index] = node;
    return index;
  }
};

// Adds the weights of triangles [first, last) in their order, computed four at a time
// (triangle_weights4: the same weights as one at a time, to the bit).
void add_exact(const UnknownTriangle* triangles, const double* corner_values, std::size_t first,
               std::size_t last, int function_count, const Vec2& foot, double height, double* w) {
  const std::size_t fc = static_cast<std::size_t>(function_count);
  for (std::size_t block = first; block < last; block += 4) {
    const std::size_t count = std::min<std::size_t>(4, last - block);
    const Vec2* corners[4];
    for (std::size_t t = 0; t < count; ++t) corners[t] = triangles[block + t].corners;
    double corner_weights[4][3];
    bool ok[4];
    triangle_weights4(corners, count, foot, height, corner_weights, ok);
    for (std::size_t t = 0; t < count; ++t) {
      if (!ok[t]) continue;
      const double* values = corner_values + (block + t) * 3 * fc;
      for (std::size_t k = 0; k < 3; ++k) {
        const double weight = corner_weights[t][k];
        for (std::size_t l = 0; l < fc; ++l) w[l] += 0.5 * weight * (1.0 + values[k * fc + l]);
      }
    }
  }
}

// The truncation error bound of each degree at the opening limit (add_triangle_weights_tree).
std::array<double, kOrder + 1> truncation_bounds() {
  std::array<double, kOrder + 1> t{};
  for (int degree = 0; degree <= kOrder; ++degree)
    t[static_cast<std::size_t>(degree)] = std::pow(kOpening, 2.0 * (kOrder + 1) / (degree + 1));
  return t;
}

// Number of nodes Builder::build makes for `count` triangles (its split rule), so that the node
// and moment arrays are sized once.
std::size_t triangle_tree_node_count(std::size_t count) {
  if (count <= kLeafTriangles) return 1;
  return 1 + triangle_tree_node_count(count / 2) + triangle_tree_node_count(count - count / 2);
}

}  // namespace

void add_triangle_moments(const Vec2 (&corners)[3], const double (&density)[3], const Vec2& centre,
                          double* out) {
  Complex z[3];
  for (int k = 0; k < 3; ++k) z[k] = {corners[k].x() - centre.x(), corners[k].y() - centre.y()};
  UniformMoments uniform;
  uniform_moments(z, uniform);
  add_linear_moments(z, uniform, density, out);
}

std::uint32_t build_triangle_tree(UnknownTriangle* triangles, double* corner_values,
                                  std::size_t count, int function_count,
                                  std::vector<TriangleNode>& nodes, std::vector<double>& moments) {
  const std::size_t fc = static_cast<std::size_t>(function_count);
  const std::size_t stride = triangle_moment_stride(function_count);
  const std::size_t first = nodes.size();
  nodes.resize(first + triangle_tree_node_count(count));
  moments.resize(nodes.size() * stride, 0.0);
  Builder builder{triangles,
                  corner_values,
                  fc,
                  stride,
                  {},
                  {},
                  nodes.data(),
                  moments.data(),
                  static_cast<std::uint32_t>(first)};
  builder.keys.reserve(count);
  builder.order.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    builder.keys.push_back(triangle_key(triangles[i]));
    builder.order[i] = static_cast<std::uint32_t>(i);
  }
  const std::uint32_t root = builder.build(0, static_cast<std::uint32_t>(count));
  if (builder.next != nodes.size())
    throw std::logic_error("triangle tree: triangle_tree_node_count disagrees with Builder::build");
  // Lay the triangles and their values out in the tree's order.
  const std::vector<UnknownTriangle> old_triangles(triangles, triangles + count);
  const std::vector<double> old_values(corner_values, corner_values + count * 3 * fc);
  for (std::size_t i = 0; i < count; ++i) {
    triangles[i] = old_triangles[builder.order[i]];
    std::copy_n(old_values.begin() + static_cast<std::ptrdiff_t>(builder.order[i] * 3 * fc), 3 * fc,
                corner_values + i * 3 * fc);
  }
  return root;
}

void triangle_tree_tables(std::vector<int>& pairs, std::vector<double>& kernel_table,
                          std::vector<double>& truncation) {
  pairs.clear();
  kernel_table.clear();
  for (std::size_t p = 0; p < kPairs; ++p) {
    pairs.push_back(kPairList[p].a);
    pairs.push_back(kPairList[p].b);
    kernel_table.insert(kernel_table.end(), kKernelTable[p].begin(), kKernelTable[p].end());
  }
  const auto bounds = truncation_bounds();
  truncation.assign(bounds.begin(), bounds.end());
}

void add_triangle_weights(const UnknownTriangle* triangles, const double* corner_values,
                          std::size_t count, int function_count, const Vec2& foot, double height,
                          double* w) {
  add_exact(triangles, corner_values, 0, count, function_count, foot, height, w);
}

void add_triangle_weights_tree(const UnknownTriangle* triangles, const double* corner_values,
                               int function_count, const TriangleNode* nodes, const double* moments,
                               std::uint32_t root, const Vec2& foot, double height, double* w) {
  if (!(height > 0.0)) return;
  const std::size_t fc = static_cast<std::size_t>(function_count);
  const std::size_t stride = triangle_moment_stride(function_count);
  const double h2 = height * height;
  const double opening_sq = kOpening * kOpening;
  static const auto truncation = truncation_bounds();
  std::uint32_t stack[64];
  int top = 0;
  stack[top++] = root;
  while (top > 0) {
    const std::uint32_t index = stack[--top];
    const TriangleNode& node = nodes[index];
    const Vec2 d = node.centre - foot;
    const double s = d.squaredNorm() + h2;
    if (node.radius_sq < opening_sq * s) {
      double coefficients[kMoments];
      const double scale = 2.0 * height / (s * s);
      const double* m = moments + static_cast<std::size_t>(index) * stride;
      // The lowest degree whose truncation error bound, (r / sqrt(s))^(degree + 1), is within
      // that of the full order at the opening limit (far nodes need few terms).
      int degree = 1;
      while (degree < kOrder && node.radius_sq > truncation[degree] * s) ++degree;
      const std::size_t used = 2 * triangle_moment_index(degree + 1, 0);
      kernel_coefficients(d, s, degree, coefficients);
      auto integral = [&](const double* density) {
        // Four partial sums: one chain of dependent additions would bound the speed. `used` is
        // even (real and imaginary parts).
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
        std::size_t k = 0;
        for (; k + 4 <= used; k += 4) {
          s0 += coefficients[k] * density[k];
          s1 += coefficients[k + 1] * density[k + 1];
          s2 += coefficients[k + 2] * density[k + 2];
          s3 += coefficients[k + 3] * density[k + 3];
        }
        if (k < used) {
          s0 += coefficients[k] * density[k];
          s1 += coefficients[k + 1] * density[k + 1];
        }
        return scale * ((s0 + s1) + (s2 + s3));
      };
      for (std::size_t l = 0; l < fc; ++l) w[l] += integral(m + l * kMoments);
      continue;
    }
    if (node.left < 0) {
      add_exact(triangles, corner_values, node.first, node.last, function_count, foot, height, w);
      continue;
    }
    stack[top++] = static_cast<std::uint32_t>(node.right);
    stack[top++] = static_cast<std::uint32_t>(node.left);
  }
}

}  // namespace sonoshape::recon
