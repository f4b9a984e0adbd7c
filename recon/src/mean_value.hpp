#pragma once
// Closed form of the mean-value integral of a planar polygon (Bermano et al. 2011, Appendix A).
//
// For a point x at height h > 0 above a plane and a region R of that plane,
//   I_R(x) = integral over the directions s that hit R of 1 / |x - y(s)| ds
//          = h * integral over R of 1 / |x - y|^4 dA.
// With p the in-plane coordinates relative to the foot point of x, the radial field
// G(p) = p / (2 h (|p|^2 + h^2)) has divergence h / (|p|^2 + h^2)^2, so by Stokes I_R is the flux
// of G through the boundary of R. One straight edge a -> b of length L contributes
//   c / (2 h q) * [atan(s_b / q) - atan(s_a / q)],   c = cross(a, b) / L,  q = sqrt(c^2 + h^2),
// where s_a, s_b are the positions of a and b along the edge direction, and the bracket equals
// atan2(q L, q^2 + s_a s_b) without cancellation. Counter-clockwise rings add, clockwise rings
// (holes) subtract, so any set of oriented rings integrates to the region they bound.
#include <cmath>
#include <cstddef>

#include "atan2.hpp"
#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon {

/// 2 h I_R for the ring `points[0..count)` (closed, counter-clockwise counts positive): the
/// "projected solid angle" of the ring seen from (foot, h), in [0, 2 pi] for a simple CCW ring.
/// `foot` is the foot point of x in the ring's 2D coordinates, `height` = h >= 0. The result is
/// exact to rounding for every h > 0 (no quadrature); for h = 0 it returns 0 (use the winding).
double projected_angle(const Vec2* points, std::size_t count, const Vec2& foot, double height);

/// The plain edge sum behind projected_angle (no treatment of cancellation; for tests).
double projected_angle_plain(const Vec2* points, std::size_t count, const Vec2& foot,
                             double height);

/// projected_angle_plain of one ring from four feet (foot_x[k], foot_y[k]) at heights height[k],
/// each result equal to projected_angle_plain's to the bit (count >= 1).
void projected_angle_plain4(const Vec2* points, std::size_t count, const double (&foot_x)[4],
                            const double (&foot_y)[4], const double (&height)[4], double (&out)[4]);

/// The sum of edge_projected_angle (below) over `count` separate edges (ax[i], ay[i]) ->
/// (bx[i], by[i]), coordinates relative to the foot, h2 = height^2: four edges at a time in AVX2
/// lanes where the CPU has them (each term equal to edge_projected_angle's to the bit, summed in
/// four lanes).
double edge_projected_angle_sum(const double* ax, const double* ay, const double* bx,
                                const double* by, std::size_t count, double h2);

/// projected_angle takes the cancellation-free split form below this magnitude of the plain sum.
constexpr double kSplitBelow = 1e-2;
/// triangle_weights takes it only below this height relative to the triangle's longest edge.
constexpr double kSplitHeightRatio = 1e-2;

/// projected_angle in its cancellation-free split form (`plain`: the plain sum, kept when the
/// split does not apply).
double projected_angle_split(const Vec2* points, std::size_t count, const Vec2& foot, double height,
                             double plain);

/// The term of one edge a -> b (coordinates relative to the foot) in projected_angle_plain;
/// h2 = height^2.
/// The angle of the edge a -> b (coordinates relative to the foot, d = b - a, cross = c L,
/// length_sq = L^2 > 0): atan2(q L, q^2 + s_a s_b) with both arguments scaled by L^2, and q L.
/// With Q = (q L)^2 = cross^2 + h^2 L^2 it takes one square root (the completion and the field
/// spend most of their time here).
struct EdgeAngle {
  double angle;
  double q_length;
};
inline EdgeAngle edge_angle(const Vec2& a, const Vec2& b, const Vec2& d, double cross,
                            double length_sq, double h2) {
  const double big_q = cross * cross + h2 * length_sq;
  const double q_length = std::sqrt(big_q);
  return {fast_atan2(q_length * length_sq, big_q + a.dot(d) * b.dot(d)), q_length};
}

inline double edge_projected_angle(const Vec2& a, const Vec2& b, double h2) {
  // (c / q) angle = (cross / (q L)) angle: one division.
  const Vec2 d = b - a;
  const double length_sq = d.squaredNorm();
  const double cross = a.x() * b.y() - a.y() * b.x();  // c L
  if (cross == 0.0 || !(length_sq > 0.0)) return 0.0;
  const EdgeAngle edge = edge_angle(a, b, d, cross, length_sq, h2);
  return (cross / edge.q_length) * edge.angle;
}

/// The same term split into its planar angle (added to `planar`) and an O(h^2) remainder
/// computed without cancellation (added to `remainder`). Returns false when the edge's line
/// passes exactly through the foot (the split is then invalid: keep the plain sum).
inline bool edge_projected_angle_split(const Vec2& a, const Vec2& b, double h2, double& planar,
                                       double& remainder) {
  const Vec2 d = b - a;
  const double length_sq = d.squaredNorm();
  if (!(length_sq > 0.0)) return true;
  const double length = std::sqrt(length_sq);
  const double c = (a.x() * b.y() - a.y() * b.x()) / length;
  if (c == 0.0) return false;
  const double s_a = a.dot(d) / length, s_b = b.dot(d) / length;
  const double abs_c = std::abs(c), sign = c > 0.0 ? 1.0 : -1.0;
  const double q = std::sqrt(c * c + h2);
  const double phi_c = fast_atan2(abs_c * length, c * c + s_a * s_b);
  const double phi_q = fast_atan2(q * length, q * q + s_a * s_b);
  // phi(q) - phi(|c|) = [atan(s_b/q) - atan(s_b/|c|)] - [atan(s_a/q) - atan(s_a/|c|)], and
  // atan(s/q) - atan(s/|c|) = atan2(-s h^2 / (q + |c|), q |c| + s^2).
  const double shrink = h2 / (q + abs_c);
  const double phi_difference = fast_atan2(-s_b * shrink, q * abs_c + s_b * s_b) -
                                fast_atan2(-s_a * shrink, q * abs_c + s_a * s_a);
  planar += sign * phi_c;
  remainder += sign * (-shrink / q * phi_q + phi_difference);
  return true;
}

/// The split sum's value: the remainder when the planar angles add up to no winding (a foot
/// outside), else the plain sum (inside, the winding part and the remainder cancel instead).
inline double split_result(double planar, double remainder, double plain) {
  const double two_pi = 6.283185307179586476925286766559;
  return std::round(planar / two_pi) != 0.0 ? plain : remainder;
}

/// Winding number of `p` around the closed ring (0 for outside, +1 / -1 inside CCW / CW rings).
/// Points on the ring count as inside (the caller tests boundaries separately when it matters).
int winding_number(const Vec2* points, std::size_t count, const Vec2& p);

}  // namespace sonoshape::recon

namespace sonoshape::recon {

/// Mean-value weights of the corners of a planar triangle (Ju, Schaefer & Warren 2005) seen from
/// (foot, height): w_i = 2 * integral over the triangle of lambda_i(y) / |x - y| d(omega), with
/// lambda_i the barycentric coordinates, in the units of projected_angle / height. Computed by
/// Stokes like the polygons: with I the triangle's integral and
/// M = integral of (y - foot) h / |x - y|^4 dA = sum over edges of -h / (2 q) * angle * n_edge,
/// w_i = 2 (lambda_i(foot) I + grad(lambda_i) . M), exact on and near the triangle's plane where
/// the spherical form of Ju et al. loses precision. Returns false for a degenerate triangle.
bool triangle_weights(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& foot, double height,
                      double weights[3]);

/// triangle_weights of `count` (1 to 4) triangles, corners[t] pointing to the three corners of
/// triangle t: ok[t] and weights[t] are triangle_weights' result and weights, to the bit. Four
/// triangles at a time in AVX2 lanes where the CPU has them.
void triangle_weights4(const Vec2* const corners[4], std::size_t count, const Vec2& foot,
                       double height, double weights[4][3], bool ok[4]);

/// The same weights by the spherical formula of Ju et al. (2005), for a point x and a triangle
/// in 3D (the reference the tests compare against).
void ju_triangle_weights(const Vec3& x, const Vec3& p0, const Vec3& p1, const Vec3& p2,
                         double weights[3]);

/// 2D mean-value weight of the edge a -> b seen from p inside a planar domain: the integral of
/// 1 / |p - y| over the directions d(theta) in which p sees the edge (signed: positive when the
/// edge turns counter-clockwise around p).
double edge_weight_2d(const Vec2& a, const Vec2& b, const Vec2& p);

}  // namespace sonoshape::recon
