#pragma once
// atan2 for the mean-value integrals, which spend most of their time in it (one call per edge
// per evaluation). Why not std::atan2: glibc's is correctly rounded and pays for it; this one is
// the rational approximation of the Cephes library (S. L. Moshier, "Methods and Programs for
// Mathematical Functions", 1989; the same coefficients Go's math.Atan uses), within 1 ulp of
// std::atan2 (atan2_test.cpp) and inlined: 21 ns against 7 ns a call on this project's machine
// (build/bench/sonoshape_atan2_bench).
#include <cmath>

namespace sonoshape::recon {

namespace atan_detail {

// atan(x) for |x| <= 0.66: x + x z P(z) / Q(z) with z = x^2.
inline double atan_small(double x) {
  constexpr double P0 = -8.750608600031904122785e-01, P1 = -1.615753718733365076637e+01,
                   P2 = -7.500855792314704667340e+01, P3 = -1.228866684490136173410e+02,
                   P4 = -6.485021904942025371773e+01;
  constexpr double Q0 = 2.485846490142306297962e+01, Q1 = 1.650270098316988542046e+02,
                   Q2 = 4.328810604912902668951e+02, Q3 = 4.853903996359136964868e+02,
                   Q4 = 1.945506571482613964425e+02;
  const double z = x * x;
  const double p = (((P0 * z + P1) * z + P2) * z + P3) * z + P4;
  const double q = ((((z + Q0) * z + Q1) * z + Q2) * z + Q3) * z + Q4;
  return x + x * (z * p / q);
}

// atan(t) for 0 <= t <= 1 (above 0.66 through atan(t) = pi/4 + atan((t - 1) / (t + 1))).
inline double atan_unit(double t) {
  constexpr double kQuarterPi = 0.78539816339744830962;
  constexpr double kQuarterPiLow = 3.061616997868382943065e-17;  // pi/4 - kQuarterPi
  if (t <= 0.66) return atan_small(t);
  return kQuarterPi + (atan_small((t - 1.0) / (t + 1.0)) + kQuarterPiLow);
}

}  // namespace atan_detail

/// atan2(y, x) for finite arguments, in [-pi, pi], with std::atan2's signs and zeros.
inline double fast_atan2(double y, double x) {
  constexpr double kPi = 3.14159265358979323846, kHalfPi = 1.57079632679489661923;
  const double ay = std::abs(y), ax = std::abs(x);
  double angle;  // of (|x|, |y|), in [0, pi/2]
  if (ay <= ax) angle = ax > 0.0 ? atan_detail::atan_unit(ay / ax) : 0.0;
  else angle = kHalfPi - atan_detail::atan_unit(ax / ay);
  if (std::signbit(x)) angle = kPi - angle;
  return std::copysign(angle, y);
}

}  // namespace sonoshape::recon
