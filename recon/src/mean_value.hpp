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
#include <cstddef>

#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon {

/// 2 h I_R for the ring `points[0..count)` (closed, counter-clockwise counts positive): the
/// "projected solid angle" of the ring seen from (foot, h), in [0, 2 pi] for a simple CCW ring.
/// `foot` is the foot point of x in the ring's 2D coordinates, `height` = h >= 0. The result is
/// exact to rounding for every h > 0 (no quadrature); for h = 0 it returns 0 (use the winding).
double projected_angle(const Vec2* points, std::size_t count, const Vec2& foot, double height);

/// The plain edge sum behind projected_angle (no treatment of cancellation; for tests).
double projected_angle_plain(const Vec2* points, std::size_t count, const Vec2& foot, double height);

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

/// The same weights by the spherical formula of Ju et al. (2005), for a point x and a triangle
/// in 3D (the reference the tests compare against).
void ju_triangle_weights(const Vec3& x, const Vec3& p0, const Vec3& p1, const Vec3& p2,
                         double weights[3]);

/// 2D mean-value weight of the edge a -> b seen from p inside a planar domain: the integral of
/// 1 / |p - y| over the directions d(theta) in which p sees the edge (signed: positive when the
/// edge turns counter-clockwise around p).
double edge_weight_2d(const Vec2& a, const Vec2& b, const Vec2& p);

}  // namespace sonoshape::recon
