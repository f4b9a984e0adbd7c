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

/// Winding number of `p` around the closed ring (0 for outside, +1 / -1 inside CCW / CW rings).
/// Points on the ring count as inside (the caller tests boundaries separately when it matters).
int winding_number(const Vec2* points, std::size_t count, const Vec2& p);

}  // namespace sonoshape::recon
