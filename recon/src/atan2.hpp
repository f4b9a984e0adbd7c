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

// The coefficients of P and Q below (also read by the SIMD lanes of mean_value.cpp).
inline constexpr double kAtanP[5] = {-8.750608600031904122785e-01, -1.615753718733365076637e+01,
                                     -7.500855792314704667340e+01, -1.228866684490136173410e+02,
                                     -6.485021904942025371773e+01};
inline constexpr double kAtanQ[5] = {2.485846490142306297962e+01, 1.650270098316988542046e+02,
                                     4.328810604912902668951e+02, 4.853903996359136964868e+02,
                                     1.945506571482613964425e+02};

inline constexpr double kAtanQuarterPi = 0.78539816339744830962;
inline constexpr double kAtanQuarterPiLow = 3.061616997868382943065e-17;  // pi/4 - kAtanQuarterPi
inline constexpr double kAtanReduceAbove = 0.66;  // atan_unit reduces t above this

// atan(x) for |x| <= 0.66: x + x z P(z) / Q(z) with z = x^2.
inline double atan_small(double x) {
  constexpr double P0 = kAtanP[0], P1 = kAtanP[1], P2 = kAtanP[2], P3 = kAtanP[3], P4 = kAtanP[4];
  constexpr double Q0 = kAtanQ[0], Q1 = kAtanQ[1], Q2 = kAtanQ[2], Q3 = kAtanQ[3], Q4 = kAtanQ[4];
  const double z = x * x;
  const double p = (((P0 * z + P1) * z + P2) * z + P3) * z + P4;
  const double q = ((((z + Q0) * z + Q1) * z + Q2) * z + Q3) * z + Q4;
  return x + x * (z * p / q);
}

// atan(t) for 0 <= t <= 1 (above 0.66 through atan(t) = pi/4 + atan((t - 1) / (t + 1))).
inline double atan_unit(double t) {
  if (t <= kAtanReduceAbove) return atan_small(t);
  return kAtanQuarterPi + (atan_small((t - 1.0) / (t + 1.0)) + kAtanQuarterPiLow);
}

}  // namespace atan_detail

/// atan2(y, x) for finite arguments, in [-pi, pi], with std::atan2's signs and zeros.
inline double fast_atan2(double y, double x) {
  constexpr double kPi = 3.14159265358979323846, kHalfPi = 1.57079632679489661923;
  const double ay = std::abs(y), ax = std::abs(x);
  double angle;  // of (|x|, |y|), in [0, pi/2]
  if (ay <= ax)
    angle = ax > 0.0 ? atan_detail::atan_unit(ay / ax) : 0.0;
  else
    angle = kHalfPi - atan_detail::atan_unit(ax / ay);
  if (std::signbit(x)) angle = kPi - angle;
  return std::copysign(angle, y);
}

}  // namespace sonoshape::recon
