#include "mean_value.hpp"

#include <algorithm>
#include <cmath>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

namespace sonoshape::recon {

// The same sum split as 2 pi * winding + sum of (c/q phi(q) - sign(c) phi(|c|)) (see
// edge_projected_angle_split): the second part is O(h^2) per edge and computed without
// cancellation, so a foot outside the ring at small height keeps its relative accuracy. The
// winding part is rounded to its exact value, which is only valid when no edge passes exactly
// through the foot (then the plain sum is kept).
double projected_angle_split(const Vec2* points, std::size_t count, const Vec2& foot, double height,
                             double plain) {
  const double h2 = height * height;
  double planar = 0.0, remainder = 0.0;
  Vec2 a = points[count - 1] - foot;
  for (std::size_t i = 0; i < count; ++i) {
    const Vec2 b = points[i] - foot;
    if (!edge_projected_angle_split(a, b, h2, planar, remainder)) return plain;
    a = b;
  }
  return split_result(planar, remainder, plain);
}

double projected_angle(const Vec2* points, std::size_t count, const Vec2& foot, double height) {
  if (count < 2 || !(height > 0.0)) return 0.0;
  const double plain = projected_angle_plain(points, count, foot, height);
  // Small results come from a foot outside the ring, where the plain sum cancels.
  return std::abs(plain) < kSplitBelow ? projected_angle_split(points, count, foot, height, plain)
                                       : plain;
}

namespace {

double projected_angle_plain_scalar(const Vec2* points, std::size_t count, const Vec2& foot,
                                    double height) {
  const double h2 = height * height;
  double sum = 0.0;
  Vec2 a = points[count - 1] - foot;
  for (std::size_t i = 0; i < count; ++i) {
    const Vec2 b = points[i] - foot;
    sum += edge_projected_angle(a, b, h2);
    a = b;
  }
  return sum;
}

#if defined(__x86_64__) && defined(__GNUC__)
#define SONOSHAPE_AVX2_KERNEL 1
// The completion's 3D parts and the field spend a third of their time in this sum, over rings of
// a handful of edges: four edges at a time in AVX2 lanes. Each lane does the operations of
// edge_projected_angle and fast_atan2 in the same order (both branches computed, the scalar
// code's one selected; no FMA), so every edge term is the scalar one to the bit and only the
// order of the additions differs. Chosen at run time (not every x86-64 has AVX2).
inline __attribute__((target("avx2"), always_inline)) __m256d atan_small_avx2(__m256d x) {
  const __m256d z = _mm256_mul_pd(x, x);
  using atan_detail::kAtanP, atan_detail::kAtanQ;
  __m256d p = _mm256_set1_pd(kAtanP[0]);
  for (int k = 1; k < 5; ++k) p = _mm256_add_pd(_mm256_mul_pd(p, z), _mm256_set1_pd(kAtanP[k]));
  __m256d q = _mm256_add_pd(z, _mm256_set1_pd(kAtanQ[0]));
  for (int k = 1; k < 5; ++k) q = _mm256_add_pd(_mm256_mul_pd(q, z), _mm256_set1_pd(kAtanQ[k]));
  return _mm256_add_pd(x, _mm256_mul_pd(x, _mm256_div_pd(_mm256_mul_pd(z, p), q)));
}

// fast_atan2(y, x) for y >= 0 (y = +0 included), lane by lane.
inline __attribute__((target("avx2"), always_inline)) __m256d atan2_nonnegative_y_avx2(__m256d y,
                                                                                       __m256d x) {
  const __m256d sign_bit = _mm256_set1_pd(-0.0);
  const __m256d ax = _mm256_andnot_pd(sign_bit, x);
  const __m256d steep = _mm256_cmp_pd(y, ax, _CMP_GT_OQ);  // ay > ax: the pi/2 - atan(ax/ay) branch
  const __m256d numerator = _mm256_blendv_pd(y, ax, steep);
  const __m256d denominator = _mm256_blendv_pd(ax, y, steep);
  const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0);
  // ax = 0 with ay <= ax: fast_atan2 returns 0 there without dividing.
  const __m256d flat_zero = _mm256_cmp_pd(denominator, zero, _CMP_EQ_OQ);
  const __m256d t = _mm256_blendv_pd(_mm256_div_pd(numerator, denominator), zero, flat_zero);
  const __m256d large = _mm256_cmp_pd(t, _mm256_set1_pd(atan_detail::kAtanReduceAbove), _CMP_GT_OQ);
  const __m256d reduced = _mm256_div_pd(_mm256_sub_pd(t, one), _mm256_add_pd(t, one));
  const __m256d small_angle = atan_small_avx2(_mm256_blendv_pd(t, reduced, large));
  const __m256d unit_angle = _mm256_blendv_pd(
      small_angle,
      _mm256_add_pd(_mm256_set1_pd(atan_detail::kAtanQuarterPi),
                    _mm256_add_pd(small_angle, _mm256_set1_pd(atan_detail::kAtanQuarterPiLow))),
      large);
  __m256d angle = _mm256_blendv_pd(
      unit_angle, _mm256_sub_pd(_mm256_set1_pd(1.57079632679489661923), unit_angle), steep);
  // signbit(x): pi - angle (blendv selects on the sign bit of its mask, here x's own).
  angle = _mm256_blendv_pd(angle, _mm256_sub_pd(_mm256_set1_pd(3.14159265358979323846), angle), x);
  return angle;
}

// edge_angle (mean_value.hpp) of four edges a -> b (coordinates relative to the foot), lane by
// lane, with the edge's d = b - a, cross (c L) and L^2 that its callers use too.
struct EdgeAngleLanes {
  __m256d dx, dy, cross, length_sq, angle, q_length;
};
inline __attribute__((target("avx2"), always_inline)) EdgeAngleLanes edge_angle_avx2(
    __m256d ax, __m256d ay, __m256d bx, __m256d by, __m256d h2) {
  EdgeAngleLanes e;
  e.dx = _mm256_sub_pd(bx, ax);
  e.dy = _mm256_sub_pd(by, ay);
  e.length_sq = _mm256_add_pd(_mm256_mul_pd(e.dx, e.dx), _mm256_mul_pd(e.dy, e.dy));
  e.cross = _mm256_sub_pd(_mm256_mul_pd(ax, by), _mm256_mul_pd(ay, bx));
  const __m256d big_q =
      _mm256_add_pd(_mm256_mul_pd(e.cross, e.cross), _mm256_mul_pd(h2, e.length_sq));
  e.q_length = _mm256_sqrt_pd(big_q);
  const __m256d a_dot_d = _mm256_add_pd(_mm256_mul_pd(ax, e.dx), _mm256_mul_pd(ay, e.dy));
  const __m256d b_dot_d = _mm256_add_pd(_mm256_mul_pd(bx, e.dx), _mm256_mul_pd(by, e.dy));
  e.angle = atan2_nonnegative_y_avx2(_mm256_mul_pd(e.q_length, e.length_sq),
                                     _mm256_add_pd(big_q, _mm256_mul_pd(a_dot_d, b_dot_d)));
  return e;
}

// edge_projected_angle of four edges, lane by lane (0 where it exits early: cross == 0 or a
// zero or NaN length).
inline __attribute__((target("avx2"), always_inline)) __m256d edge_terms_avx2(
    __m256d ax, __m256d ay, __m256d bx, __m256d by, __m256d h2) {
  const __m256d zero = _mm256_setzero_pd();
  const EdgeAngleLanes e = edge_angle_avx2(ax, ay, bx, by, h2);
  const __m256d term = _mm256_mul_pd(_mm256_div_pd(e.cross, e.q_length), e.angle);
  const __m256d skip = _mm256_or_pd(_mm256_cmp_pd(e.cross, zero, _CMP_EQ_OQ),
                                    _mm256_cmp_pd(e.length_sq, zero, _CMP_NGT_UQ));
  return _mm256_blendv_pd(term, zero, skip);
}

__attribute__((target("avx2"))) double projected_angle_plain_avx2(const Vec2* points,
                                                                  std::size_t count,
                                                                  const Vec2& foot, double height) {
  constexpr std::size_t kChunk = 64;  // edges per pass through the lane arrays
  alignas(32) double xs[kChunk + 4], ys[kChunk + 4];
  const __m256d h2 = _mm256_set1_pd(height * height);
  const __m256d zero = _mm256_setzero_pd();
  __m256d sums = zero;
  for (std::size_t first = 0; first < count; first += kChunk) {
    const std::size_t edges = std::min(kChunk, count - first);
    // xs/ys[k] is the start of edge first + k and xs/ys[k + 1] its end, relative to the foot;
    // the lanes past the last edge repeat its end (zero-length edges add nothing).
    const Vec2 start = points[(first + count - 1) % count] - foot;
    xs[0] = start.x();
    ys[0] = start.y();
    for (std::size_t k = 0; k < edges; ++k) {
      const Vec2 end = points[first + k] - foot;
      xs[k + 1] = end.x();
      ys[k + 1] = end.y();
    }
    const std::size_t padded = (edges + 3) / 4 * 4;
    for (std::size_t k = edges + 1; k <= padded; ++k) {
      xs[k] = xs[edges];
      ys[k] = ys[edges];
    }
    for (std::size_t k = 0; k < padded; k += 4)
      sums = _mm256_add_pd(
          sums, edge_terms_avx2(_mm256_loadu_pd(xs + k), _mm256_loadu_pd(ys + k),
                                _mm256_loadu_pd(xs + k + 1), _mm256_loadu_pd(ys + k + 1), h2));
  }
  alignas(32) double lanes[4];
  _mm256_store_pd(lanes, sums);
  return (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
}

// projected_angle_plain_avx2 of one ring from four feet at once, one foot per lane. Per foot it
// adds the same edge terms in the same order as that function: there edge k goes to lane k mod 4
// and the lanes are summed pairwise at the end; here each foot keeps one sum per residue k mod 4
// and combines them the same way, so every result is projected_angle_plain_avx2's to the bit
// (the padding edges it adds are zero-length: they add +0). Rings of a handful of edges fill the
// lanes here, where one foot at a time left most of them padding.
__attribute__((target("avx2"))) void projected_angle_plain4_avx2(
    const Vec2* points, std::size_t count, const double (&foot_x)[4], const double (&foot_y)[4],
    const double (&height)[4], double (&out)[4]) {
  const __m256d fx = _mm256_loadu_pd(foot_x), fy = _mm256_loadu_pd(foot_y);
  const __m256d hs = _mm256_loadu_pd(height);
  const __m256d h2 = _mm256_mul_pd(hs, hs);
  __m256d sums[4] = {_mm256_setzero_pd(), _mm256_setzero_pd(), _mm256_setzero_pd(),
                     _mm256_setzero_pd()};
  const Vec2& start = points[count - 1];
  __m256d ax = _mm256_sub_pd(_mm256_set1_pd(start.x()), fx),
          ay = _mm256_sub_pd(_mm256_set1_pd(start.y()), fy);
  for (std::size_t k = 0; k < count; ++k) {
    const __m256d bx = _mm256_sub_pd(_mm256_set1_pd(points[k].x()), fx);
    const __m256d by = _mm256_sub_pd(_mm256_set1_pd(points[k].y()), fy);
    sums[k % 4] = _mm256_add_pd(sums[k % 4], edge_terms_avx2(ax, ay, bx, by, h2));
    ax = bx;
    ay = by;
  }
  const __m256d total =
      _mm256_add_pd(_mm256_add_pd(sums[0], sums[1]), _mm256_add_pd(sums[2], sums[3]));
  _mm256_storeu_pd(out, total);
}

__attribute__((target("avx2"))) double edge_projected_angle_sum_avx2(
    const double* ax, const double* ay, const double* bx, const double* by, std::size_t count,
    double height_sq) {
  const __m256d h2 = _mm256_set1_pd(height_sq);
  __m256d sums = _mm256_setzero_pd();
  std::size_t i = 0;
  for (; i + 4 <= count; i += 4)
    sums =
        _mm256_add_pd(sums, edge_terms_avx2(_mm256_loadu_pd(ax + i), _mm256_loadu_pd(ay + i),
                                            _mm256_loadu_pd(bx + i), _mm256_loadu_pd(by + i), h2));
  if (i < count) {
    // The last edges, padded with zero-length edges (which add nothing).
    alignas(32) double tail[4][4] = {};
    for (std::size_t k = 0; i + k < count; ++k) {
      tail[0][k] = ax[i + k];
      tail[1][k] = ay[i + k];
      tail[2][k] = bx[i + k];
      tail[3][k] = by[i + k];
    }
    sums =
        _mm256_add_pd(sums, edge_terms_avx2(_mm256_load_pd(tail[0]), _mm256_load_pd(tail[1]),
                                            _mm256_load_pd(tail[2]), _mm256_load_pd(tail[3]), h2));
  }
  alignas(32) double lanes[4];
  _mm256_store_pd(lanes, sums);
  return (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
}

const bool kHaveAvx2 = __builtin_cpu_supports("avx2");
#endif

// What triangle_weights computes of one triangle before and after its edge terms (its edge
// terms themselves are computed four triangles at a time below).
struct TrianglePrologue {
  bool valid;
  double twice_area, longest_sq;
  Vec2 ring[3];  // counter-clockwise
};
TrianglePrologue triangle_prologue(const Vec2* corners, const Vec2& foot, double height) {
  const Vec2& a = corners[0];
  const Vec2& b = corners[1];
  const Vec2& c = corners[2];
  TrianglePrologue out;
  out.twice_area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
  // Slivers (two corners rounded onto each other) carry no area but would blow up the
  // barycentric gradients: they contribute nothing.
  // (and so do triangles tiny against their distance to the point: their gradients overflow too).
  out.longest_sq = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  const double reach_sq = (foot - a).squaredNorm() + height * height;
  out.valid =
      std::abs(out.twice_area) > 1e-12 * std::max(out.longest_sq, 1e-12 * reach_sq) && height > 0.0;
  // Traverse counter-clockwise so outward normals are (d.y, -d.x) / L.
  const int order[3] = {0, out.twice_area > 0 ? 1 : 2, out.twice_area > 0 ? 2 : 1};
  for (int k = 0; k < 3; ++k) out.ring[k] = corners[order[k]];
  return out;
}

// A foot outside the triangle at a height small against the triangle makes the edge terms of I
// cancel (their sum is O(h) while each is O(1)); the split form keeps I's relative accuracy
// there. Higher up, the terms are at most about size / height times their sum (far away much
// less): the plain sum holds.
bool takes_split_form(const TrianglePrologue& t, double projected, double height) {
  return std::abs(projected) < kSplitBelow &&
         height * height < kSplitHeightRatio * kSplitHeightRatio * t.longest_sq;
}

// The weights from the edge sums I (`projected`, 2 h I) and M (`moment`).
bool triangle_epilogue(const Vec2* corners, const TrianglePrologue& t, const Vec2& foot,
                       double height, double projected, const Vec2& moment, double weights[3]) {
  if (takes_split_form(t, projected, height))
    projected = projected_angle_split(t.ring, 3, foot, height, projected);
  // Barycentric coordinate of corner i: lambda_i(y) = cross(e_i, y - start_i) / twice_area with
  // e_i the opposite edge; its gradient is perp(e_i) / twice_area.
  const double inverse_area = 1.0 / t.twice_area, projected_over_height = projected / height;
  for (int i = 0; i < 3; ++i) {
    const Vec2& p1 = corners[(i + 1) % 3];
    const Vec2& p2 = corners[(i + 2) % 3];
    const Vec2 e = p2 - p1;
    const Vec2 gradient = Vec2(-e.y(), e.x()) * inverse_area;
    const double lambda_at_foot = gradient.dot(foot - p1);
    weights[i] = lambda_at_foot * projected_over_height + 2.0 * gradient.dot(moment);
  }
  return std::isfinite(weights[0]) && std::isfinite(weights[1]) && std::isfinite(weights[2]);
}

#ifdef SONOSHAPE_AVX2_KERNEL
// triangle_weights of four triangles, one per lane: each lane does triangle_weights' operations
// on its triangle in the same order (the edge term as in projected_angle_plain_avx2, no FMA), so
// every weight is the scalar one to the bit; the rare split form is computed lane by lane. One
// triangle at a time, these weights were about a quarter of the perf samples of a sector sweep's
// updates (`perf record` of `reconstruct SET --online --threads 1`).
__attribute__((target("avx2"))) void triangle_weights4_avx2(const Vec2* const corners[4],
                                                            std::size_t count, const Vec2& foot,
                                                            double height, double weights[4][3],
                                                            bool ok[4]) {
  TrianglePrologue triangles[4];
  alignas(32) double ring_x[3][4], ring_y[3][4], corner_x[3][4], corner_y[3][4], twice_area[4];
  for (std::size_t t = 0; t < 4; ++t) {  // lanes past `count` repeat the last triangle
    const Vec2* c = corners[std::min(t, count - 1)];
    triangles[t] = triangle_prologue(c, foot, height);
    twice_area[t] = triangles[t].twice_area;
    for (int k = 0; k < 3; ++k) {
      const Vec2 p = triangles[t].ring[k] - foot;
      ring_x[k][t] = p.x();
      ring_y[k][t] = p.y();
      corner_x[k][t] = c[k].x();
      corner_y[k][t] = c[k].y();
    }
  }
  const __m256d sign_bit = _mm256_set1_pd(-0.0);
  const __m256d h2 = _mm256_set1_pd(height * height);
  const __m256d minus_half_height = _mm256_set1_pd(-0.5 * height);
  __m256d sum = _mm256_setzero_pd(), moment_x = _mm256_setzero_pd(), moment_y = _mm256_setzero_pd();
  for (int k = 0; k < 3; ++k) {
    const EdgeAngleLanes e = edge_angle_avx2(_mm256_load_pd(ring_x[k]), _mm256_load_pd(ring_y[k]),
                                             _mm256_load_pd(ring_x[(k + 1) % 3]),
                                             _mm256_load_pd(ring_y[(k + 1) % 3]), h2);
    const __m256d angle_over_q_length = _mm256_div_pd(e.angle, e.q_length);
    sum = _mm256_add_pd(sum, _mm256_mul_pd(e.cross, angle_over_q_length));
    const __m256d scale = _mm256_mul_pd(minus_half_height, angle_over_q_length);
    moment_x = _mm256_add_pd(moment_x, _mm256_mul_pd(scale, e.dy));
    moment_y = _mm256_add_pd(moment_y, _mm256_mul_pd(scale, _mm256_xor_pd(e.dx, sign_bit)));  // -dx
  }
  // The split form where triangle_epilogue takes it (rare), lane by lane.
  alignas(32) double projected[4];
  _mm256_store_pd(projected, sum);
  for (std::size_t t = 0; t < count; ++t)
    if (triangles[t].valid && takes_split_form(triangles[t], projected[t], height))
      projected[t] = projected_angle_split(triangles[t].ring, 3, foot, height, projected[t]);
  const __m256d inverse_area = _mm256_div_pd(_mm256_set1_pd(1.0), _mm256_load_pd(twice_area));
  const __m256d projected_over_height =
      _mm256_div_pd(_mm256_load_pd(projected), _mm256_set1_pd(height));
  const __m256d foot_x = _mm256_set1_pd(foot.x()), foot_y = _mm256_set1_pd(foot.y()),
                two = _mm256_set1_pd(2.0);
  alignas(32) double lane_weights[3][4];
  for (int i = 0; i < 3; ++i) {
    const __m256d p1x = _mm256_load_pd(corner_x[(i + 1) % 3]),
                  p1y = _mm256_load_pd(corner_y[(i + 1) % 3]);
    const __m256d ex = _mm256_sub_pd(_mm256_load_pd(corner_x[(i + 2) % 3]), p1x);
    const __m256d ey = _mm256_sub_pd(_mm256_load_pd(corner_y[(i + 2) % 3]), p1y);
    const __m256d gx =
        _mm256_mul_pd(_mm256_xor_pd(ey, sign_bit), inverse_area);  // (-e.y, e.x) / 2A
    const __m256d gy = _mm256_mul_pd(ex, inverse_area);
    const __m256d lambda_at_foot = _mm256_add_pd(_mm256_mul_pd(gx, _mm256_sub_pd(foot_x, p1x)),
                                                 _mm256_mul_pd(gy, _mm256_sub_pd(foot_y, p1y)));
    const __m256d gradient_dot_moment =
        _mm256_add_pd(_mm256_mul_pd(gx, moment_x), _mm256_mul_pd(gy, moment_y));
    _mm256_store_pd(lane_weights[i],
                    _mm256_add_pd(_mm256_mul_pd(lambda_at_foot, projected_over_height),
                                  _mm256_mul_pd(two, gradient_dot_moment)));
  }
  for (std::size_t t = 0; t < count; ++t) {
    for (int i = 0; i < 3; ++i) weights[t][i] = lane_weights[i][t];
    ok[t] = triangles[t].valid && std::isfinite(weights[t][0]) && std::isfinite(weights[t][1]) &&
            std::isfinite(weights[t][2]);
  }
}
#endif

}  // namespace

double projected_angle_plain(const Vec2* points, std::size_t count, const Vec2& foot,
                             double height) {
#ifdef SONOSHAPE_AVX2_KERNEL
  if (kHaveAvx2) return projected_angle_plain_avx2(points, count, foot, height);
#endif
  return projected_angle_plain_scalar(points, count, foot, height);
}

void projected_angle_plain4(const Vec2* points, std::size_t count, const double (&foot_x)[4],
                            const double (&foot_y)[4], const double (&height)[4],
                            double (&out)[4]) {
#ifdef SONOSHAPE_AVX2_KERNEL
  if (kHaveAvx2) return projected_angle_plain4_avx2(points, count, foot_x, foot_y, height, out);
#endif
  for (int k = 0; k < 4; ++k)
    out[k] = projected_angle_plain_scalar(points, count, Vec2(foot_x[k], foot_y[k]), height[k]);
}

double edge_projected_angle_sum(const double* ax, const double* ay, const double* bx,
                                const double* by, std::size_t count, double h2) {
#ifdef SONOSHAPE_AVX2_KERNEL
  if (kHaveAvx2) return edge_projected_angle_sum_avx2(ax, ay, bx, by, count, h2);
#endif
  double sum = 0.0;
  for (std::size_t i = 0; i < count; ++i)
    sum += edge_projected_angle(Vec2(ax[i], ay[i]), Vec2(bx[i], by[i]), h2);
  return sum;
}

int winding_number(const Vec2* points, std::size_t count, const Vec2& p) {
  // Sunday's crossing rule with the orientation sign; boundary points count as inside.
  int winding = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const Vec2& a = points[i];
    const Vec2& b = points[(i + 1) % count];
    const double side = (b.x() - a.x()) * (p.y() - a.y()) - (p.x() - a.x()) * (b.y() - a.y());
    if (side == 0.0 && (p - a).dot(p - b) <= 0.0) return 1;  // on the edge
    if (a.y() <= p.y()) {
      if (b.y() > p.y() && side > 0.0) ++winding;
    } else if (b.y() <= p.y() && side < 0.0) {
      --winding;
    }
  }
  return winding;
}

}  // namespace sonoshape::recon

namespace sonoshape::recon {

bool triangle_weights(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& foot, double height,
                      double weights[3]) {
  const Vec2 corners[3] = {a, b, c};
  const TrianglePrologue t = triangle_prologue(corners, foot, height);
  if (!t.valid) return false;
  const double h2 = height * height;
  Vec2 moment = Vec2::Zero();  // M
  double projected = 0.0;      // 2 h I, from the same edge angles as M
  for (int k = 0; k < 3; ++k) {
    // The edge term of mean_value.hpp through edge_angle: one square root and one division per
    // edge.
    const Vec2 p = t.ring[k] - foot;
    const Vec2 q_end = t.ring[(k + 1) % 3] - foot;
    const Vec2 d = q_end - p;
    const double cross = p.x() * q_end.y() - p.y() * q_end.x();  // c L
    const EdgeAngle edge = edge_angle(p, q_end, d, cross, d.squaredNorm(), h2);
    const double angle_over_q_length = edge.angle / edge.q_length;
    projected += cross * angle_over_q_length;  // (c / q) angle
    // -h / (2 q) angle times the outward unit normal (d.y, -d.x) / L.
    moment += (-0.5 * height * angle_over_q_length) * Vec2(d.y(), -d.x());
  }
  return triangle_epilogue(corners, t, foot, height, projected, moment, weights);
}

void triangle_weights4(const Vec2* const corners[4], std::size_t count, const Vec2& foot,
                       double height, double weights[4][3], bool ok[4]) {
#ifdef SONOSHAPE_AVX2_KERNEL
  if (kHaveAvx2 && count > 1)
    return triangle_weights4_avx2(corners, count, foot, height, weights, ok);
#endif
  for (std::size_t t = 0; t < count; ++t)
    ok[t] = triangle_weights(corners[t][0], corners[t][1], corners[t][2], foot, height, weights[t]);
}

void ju_triangle_weights(const Vec3& x, const Vec3& p0, const Vec3& p1, const Vec3& p2,
                         double weights[3]) {
  const Vec3 p[3] = {p0, p1, p2};
  double d[3];
  Vec3 u[3];
  for (int i = 0; i < 3; ++i) {
    d[i] = (p[i] - x).norm();
    u[i] = (p[i] - x) / d[i];
  }
  double theta[3];
  for (int i = 0; i < 3; ++i) {
    const double l = (u[(i + 1) % 3] - u[(i + 2) % 3]).norm();
    theta[i] = 2.0 * std::asin(std::min(1.0, l / 2.0));
  }
  const double h = 0.5 * (theta[0] + theta[1] + theta[2]);
  const double pi = 3.14159265358979323846;
  if (pi - h < 1e-12) {  // x on the triangle: 2D barycentric weights (scale irrelevant there)
    for (int i = 0; i < 3; ++i) weights[i] = std::sin(theta[i]) * d[(i + 2) % 3] * d[(i + 1) % 3];
    return;
  }
  // Ju et al. sign s_i by the orientation of the triangle seen from x, as a closed mesh needs;
  // dropping it gives the unsigned weights, which are 2 * integral of lambda_i / r d(omega): the
  // units of triangle_weights.
  double c[3], s[3];
  for (int i = 0; i < 3; ++i) {
    c[i] = 2.0 * std::sin(h) * std::sin(h - theta[i]) /
               (std::sin(theta[(i + 1) % 3]) * std::sin(theta[(i + 2) % 3])) -
           1.0;
    s[i] = std::sqrt(std::max(0.0, 1.0 - c[i] * c[i]));
  }
  for (int i = 0; i < 3; ++i) {
    const int ip = (i + 1) % 3, im = (i + 2) % 3;
    weights[i] =
        (theta[i] - c[ip] * theta[im] - c[im] * theta[ip]) / (d[i] * std::sin(theta[ip]) * s[im]);
  }
}

double edge_weight_2d(const Vec2& a_world, const Vec2& b_world, const Vec2& p) {
  const Vec2 a = a_world - p, b = b_world - p;
  const Vec2 d = b - a;
  const double length = d.norm();
  if (length == 0.0) return 0.0;
  const double c = (a.x() * b.y() - a.y() * b.x()) / length;
  if (c == 0.0) return 0.0;
  const double s_a = a.dot(d) / length, s_b = b.dot(d) / length;
  const double r_a = std::sqrt(s_a * s_a + c * c), r_b = std::sqrt(s_b * s_b + c * c);
  // (1/c) (s_b / r_b - s_a / r_a); when p's foot on the edge line is outside the edge the two
  // terms nearly cancel, so use the equivalent c (s_b^2 - s_a^2) / ((s_b r_a + s_a r_b) r_a r_b).
  if (s_a * s_b > 0.0) return c * (s_b * s_b - s_a * s_a) / ((s_b * r_a + s_a * r_b) * r_a * r_b);
  return (s_b / r_b - s_a / r_a) / c;
}

}  // namespace sonoshape::recon
