// The closed-form mean-value integral against independent quadrature, its known values and
// limits, and the ring clipping the face images are built with.
//
// Notation: I_R(x) = h * integral over R of |x - y|^-4 dA for x at height h above the foot f;
// projected_angle returns 2 h I_R.
#include "mean_value.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "cell_field.hpp"

namespace sonoshape::recon::mean_value_test {
namespace {

constexpr double kPi = std::numbers::pi;

double cross(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

double angle(const Ring2& ring, const Vec2& foot, double h) {
  return projected_angle(ring.data(), ring.size(), foot, h);
}

// I_R from the closed form.
double closed_form(const std::vector<Ring2>& rings, const Vec2& foot, double h) {
  double sum = 0.0;
  for (const Ring2& ring : rings) sum += angle(ring, foot, h);
  return sum / (2.0 * h);
}

Ring2 reversed(Ring2 ring) {
  std::reverse(ring.begin(), ring.end());
  return ring;
}

// ---------------------------------------------------------------------------------------------
// Reference quadrature. Each edge a -> b spans the signed triangle (foot, a, b); in polar
// coordinates about the foot, the radial integral of h r / (r^2 + h^2)^2 from 0 to R is
//   1 / (2 h) - h / (2 (R^2 + h^2)).
// The first term sums over the ring to pi k / h (k = winding, exact); the second is integrated
// in angle by adaptive Gauss-Kronrod. R(theta) comes from intersecting the ray with the edge's
// line, which shares nothing with the closed form's Stokes/atan derivation.

constexpr std::array<double, 8> kXgk{
    0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
    0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
    0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
    0.207784955007898467600689403773245, 0.000000000000000000000000000000000};
constexpr std::array<double, 8> kWgk{
    0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
    0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
    0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
    0.204432940075298892414161999234649, 0.209482141084727828012999174891714};
constexpr std::array<double, 4> kWg{
    0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
    0.381830050505118944950369775488975, 0.417959183673469387755102040816327};

// G7-K15 on [lo, hi]: returns the Kronrod value, `error` gets |K15 - G7| floored at the
// rounding level of the sum (so the recursion stops when no further digit can be gained).
template <class F>
double gauss_kronrod(const F& f, double lo, double hi, double& error) {
  const double center = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  const double fc = f(center);
  double kronrod = kWgk[7] * fc, gauss = kWg[3] * fc, magnitude = kWgk[7] * std::abs(fc);
  for (int j = 0; j < 7; ++j) {
    const double f1 = f(center - half * kXgk[j]), f2 = f(center + half * kXgk[j]);
    kronrod += kWgk[j] * (f1 + f2);
    magnitude += kWgk[j] * (std::abs(f1) + std::abs(f2));
    if (j % 2 == 1) gauss += kWg[j / 2] * (f1 + f2);
  }
  error = std::abs((kronrod - gauss) * half);
  if (error < 50.0 * 2.2e-16 * magnitude * std::abs(half)) error = 0.0;
  return kronrod * half;
}

// Globally adaptive over the pieces between `breaks`: bisects the piece of largest error
// estimate until the total estimate is below `tolerance` (bounded work; QUADPACK QAG style).
template <class F>
double adaptive(const F& f, const std::vector<double>& breaks, double tolerance) {
  struct Piece {
    double lo, hi, value, error;
    bool operator<(const Piece& o) const { return error < o.error; }
  };
  std::vector<Piece> heap;
  double total_error = 0.0;
  for (std::size_t i = 0; i + 1 < breaks.size(); ++i) {
    double error = 0.0;
    const double value = gauss_kronrod(f, breaks[i], breaks[i + 1], error);
    heap.push_back({breaks[i], breaks[i + 1], value, error});
    total_error += error;
  }
  std::make_heap(heap.begin(), heap.end());
  for (int split = 0; split < 4000 && total_error > tolerance; ++split) {
    std::pop_heap(heap.begin(), heap.end());
    const Piece worst = heap.back();
    heap.pop_back();
    const double mid = 0.5 * (worst.lo + worst.hi);
    double e1 = 0.0, e2 = 0.0;
    const double v1 = gauss_kronrod(f, worst.lo, mid, e1), v2 = gauss_kronrod(f, mid, worst.hi, e2);
    total_error += e1 + e2 - worst.error;
    heap.push_back({worst.lo, mid, v1, e1});
    std::push_heap(heap.begin(), heap.end());
    heap.push_back({mid, worst.hi, v2, e2});
    std::push_heap(heap.begin(), heap.end());
  }
  EXPECT_LE(total_error, tolerance) << "quadrature did not converge";
  double value = 0.0;
  for (const Piece& p : heap) value += p.value;
  return value;
}

// I_R by quadrature (foot not on a ring: the winding must be well defined).
double quadrature(const std::vector<Ring2>& rings, const Vec2& foot, double h) {
  // When the edge passes close to the foot, R changes from |a| to ~h within a tiny angle of
  // the sweep's ends; breaks graded geometrically towards each end resolve that. Each half of
  // the sweep is parametrised from its own end so the angle keeps full precision there.
  std::vector<double> breaks{0.0};
  for (int k = 26; k >= 0; --k) breaks.push_back(0.5 * std::pow(0.25, k));
  double angle_sum = 0.0, remainder = 0.0;
  for (const Ring2& ring : rings) {
    for (std::size_t i = 0; i < ring.size(); ++i) {
      const Vec2 a = ring[i] - foot, b = ring[(i + 1) % ring.size()] - foot;
      const double area2 = cross(a, b);
      if (area2 == 0.0) continue;  // a triangle of no area
      const double phi = std::atan2(area2, a.dot(b));
      const Vec2 e = b - a;
      // Direction d = end/|end| turned by t * sweep; the ray meets the edge's line at
      // R = cross(a, e) / cross(d, e), with cross(d, e) expanded about the end direction so
      // that nothing cancels when the ray runs nearly along the edge.
      const auto g_from = [&](const Vec2& end, double sweep) {
        const double length = end.norm(), along = end.dot(e);
        return [=](double t) {
          const double r =
              length * area2 / (std::cos(t * sweep) * area2 - std::sin(t * sweep) * along);
          return h / (2.0 * (r * r + h * h));
        };
      };
      const auto g_a = g_from(a, phi), g_b = g_from(b, -phi);
      double unused = 0.0;
      const double rough =
          std::abs(gauss_kronrod(g_a, 0.0, 0.5, unused) + gauss_kronrod(g_b, 0.0, 0.5, unused));
      const double tolerance = 1e-15 * rough;
      angle_sum += phi;
      remainder += phi * (adaptive(g_a, breaks, tolerance) + adaptive(g_b, breaks, tolerance));
    }
  }
  const double winding = std::round(angle_sum / (2.0 * kPi));
  EXPECT_NEAR(angle_sum, 2.0 * kPi * winding, 1e-9) << "foot on the boundary";
  return kPi * winding / h - remainder;
}

// ---------------------------------------------------------------------------------------------
// Random test geometry.

struct StarPolygon {
  Vec2 center;
  double r_min, r_max;
  Ring2 ring;  // counter-clockwise
};

// Star-shaped about `center`: stratified angles keep every angular gap below pi.
StarPolygon random_star(std::mt19937_64& rng, int n, const Vec2& center, double r_lo, double r_hi) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  StarPolygon star{center, r_hi, r_lo, {}};
  const double phase = 2.0 * kPi * unit(rng);
  for (int i = 0; i < n; ++i) {
    const double theta = phase + 2.0 * kPi * (i + 0.8 * unit(rng)) / n;
    const double r = r_lo + (r_hi - r_lo) * unit(rng);
    star.r_min = std::min(star.r_min, r);
    star.r_max = std::max(star.r_max, r);
    star.ring.push_back(center + r * Vec2(std::cos(theta), std::sin(theta)));
  }
  return star;
}

// Feet of every kind for a ring set whose first ring is `star`.
std::vector<Vec2> test_feet(std::mt19937_64& rng, const StarPolygon& star,
                            const std::vector<Ring2>& rings) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Vec2> feet;
  const auto random_dir = [&] {
    const double t = 2.0 * kPi * unit(rng);
    return Vec2(std::cos(t), std::sin(t));
  };
  const std::size_t n = star.ring.size();
  // Inside the fan triangle (center, v_i, v_i+1).
  for (int k = 0; k < 2; ++k) {
    const std::size_t i = rng() % n;
    double s = unit(rng), t = unit(rng);
    if (s + t > 1.0) s = 1.0 - s, t = 1.0 - t;
    feet.push_back(star.center + s * (star.ring[i] - star.center) +
                   t * (star.ring[(i + 1) % n] - star.center));
  }
  // Outside, beyond the largest radius.
  feet.push_back(star.center + star.r_max * (1.05 + 2.0 * unit(rng)) * random_dir());
  // Near edges and vertices of every ring, at several distances, on both sides.
  for (const double delta : {1e-9, 1e-6, 1e-3}) {
    const Ring2& ring = rings[rng() % rings.size()];
    const std::size_t i = rng() % ring.size();
    const Vec2 a = ring[i], b = ring[(i + 1) % ring.size()];
    const Vec2 normal = Vec2(-(b - a).y(), (b - a).x()).normalized();
    const double side = unit(rng) < 0.5 ? -1.0 : 1.0;
    feet.push_back(a + (0.1 + 0.8 * unit(rng)) * (b - a) + side * delta * star.r_max * normal);
    feet.push_back(a + delta * star.r_max * random_dir());
  }
  return feet;
}

double log_uniform(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  return lo * std::pow(hi / lo, unit(rng));
}

double relative_error(double value, double reference) {
  return std::abs(value - reference) / std::abs(reference);
}

// ---------------------------------------------------------------------------------------------

TEST(MeanValueQuadrature, ReferenceIntegratesATriangleOfKnownValue) {
  // Sanity check of the reference itself: a triangle at a height where the integrand is smooth,
  // against a plain 2D product rule over the triangle (no polar coordinates, no windings).
  const std::vector<Ring2> tri{{Vec2(0, 0), Vec2(1, 0), Vec2(0, 1)}};
  const Vec2 foot(0.2, 0.3);
  const double h = 0.7;
  // The 15-point Kronrod rule on each axis of the square collapsed onto the triangle.
  double brute = 0.0;
  for (int i = 0; i < 15; ++i) {
    const double xi = i < 7 ? -kXgk[i] : (i == 7 ? 0.0 : kXgk[14 - i]);
    const double wi = i < 7 ? kWgk[i] : (i == 7 ? kWgk[7] : kWgk[14 - i]);
    for (int j = 0; j < 15; ++j) {
      const double xj = j < 7 ? -kXgk[j] : (j == 7 ? 0.0 : kXgk[14 - j]);
      const double wj = j < 7 ? kWgk[j] : (j == 7 ? kWgk[7] : kWgk[14 - j]);
      const double s = 0.5 * (xi + 1.0), t = 0.5 * (xj + 1.0) * (1.0 - s);
      const double jac = 0.25 * (1.0 - s);
      const double r2 = (Vec2(s, t) - foot).squaredNorm();
      brute += wi * wj * jac * h / ((r2 + h * h) * (r2 + h * h));
    }
  }
  EXPECT_LT(relative_error(quadrature(tri, foot, h), brute), 1e-9);
}

// Worst errors of the closed form against the quadrature over many checks. The closed form is
// accurate in absolute terms (its edge terms are O(1) angles); relative to I_R that degrades
// only where the terms cancel, i.e. feet outside the region at small heights (2 h I ~ h^2).
struct Accuracy {
  int checks = 0;
  double worst_relative = 0.0;     // |I - I_ref| / I_ref
  double worst_angle_error = 0.0;  // |2 h (I - I_ref)| / edges, in units of the projected angle

  void check(const std::vector<Ring2>& rings, const Vec2& foot, double h) {
    std::size_t edges = 0;
    for (const Ring2& r : rings) edges += r.size();
    const double reference = quadrature(rings, foot, h), value = closed_form(rings, foot, h);
    const double relative = relative_error(value, reference);
    const double angle_error = 2.0 * h * std::abs(value - reference) / static_cast<double>(edges);
    ++checks;
    worst_relative = std::max(worst_relative, relative);
    worst_angle_error = std::max(worst_angle_error, angle_error);
    EXPECT_LT(relative, 1e-6) << "foot " << foot.transpose() << " h " << h;
    EXPECT_LT(angle_error, 1e-15) << "foot " << foot.transpose() << " h " << h;
  }
  void print(const char* what) const {
    std::printf("[ info ] %s: %d checks, worst relative error %.3g, worst angle error/edge %.3g\n",
                what, checks, worst_relative, worst_angle_error);
  }
};

TEST(MeanValueQuadrature, RandomStarPolygonsAgreeWithQuadrature) {
  std::mt19937_64 rng(20110301);
  std::uniform_int_distribution<int> vertices(5, 30);
  Accuracy accuracy;
  for (int trial = 0; trial < 40; ++trial) {
    const double size = log_uniform(rng, 0.01, 100.0);
    const Vec2 center(size * static_cast<double>(rng() % 7),
                      -size * static_cast<double>(rng() % 5));
    const StarPolygon star = random_star(rng, vertices(rng), center, 0.3 * size, size);
    const std::vector<Ring2> rings{star.ring};
    for (const Vec2& foot : test_feet(rng, star, rings))
      for (int k = 0; k < 2; ++k) accuracy.check(rings, foot, log_uniform(rng, 1e-3, 10.0) * size);
  }
  accuracy.print("star polygons");
}

TEST(MeanValueQuadrature, PolygonsWithHolesAgreeWithQuadrature) {
  std::mt19937_64 rng(42);
  std::uniform_int_distribution<int> vertices(5, 30);
  Accuracy accuracy;
  for (int trial = 0; trial < 30; ++trial) {
    const double size = log_uniform(rng, 0.1, 10.0);
    const Vec2 center(0.5 * size, 0.25 * size);
    const StarPolygon outer = random_star(rng, vertices(rng), center, 0.7 * size, size);
    const StarPolygon hole = random_star(rng, vertices(rng), center, 0.1 * size, 0.3 * size);
    const std::vector<Ring2> rings{outer.ring, reversed(hole.ring)};
    std::vector<Vec2> feet = test_feet(rng, outer, rings);
    feet.push_back(center + Vec2(0.05, -0.03) * size);  // inside the hole
    for (const Vec2& foot : feet)
      for (int k = 0; k < 2; ++k) accuracy.check(rings, foot, log_uniform(rng, 1e-3, 10.0) * size);
  }
  accuracy.print("polygons with holes");
}

TEST(MeanValueQuadrature, FeetInsideAreRelativelyExact) {
  // Where nothing cancels (foot inside), the closed form is exact to rounding, relative.
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  double worst = 0.0;
  for (int trial = 0; trial < 30; ++trial) {
    const StarPolygon star = random_star(rng, 5 + trial % 26, Vec2(1.0, 2.0), 0.3, 1.0);
    const std::size_t i = rng() % star.ring.size();
    const Vec2 foot = star.center + 0.5 * unit(rng) * (star.ring[i] - star.center);
    for (const double h : {1e-3, 1e-2, 0.3, 3.0, 10.0}) {
      const double err =
          relative_error(closed_form({star.ring}, foot, h), quadrature({star.ring}, foot, h));
      worst = std::max(worst, err);
      EXPECT_LT(err, 1e-12);  // the reference itself cancels ~h^2/area at h = 10
    }
  }
  std::printf("[ info ] feet inside: worst relative error %.3g\n", worst);
}

// ---------------------------------------------------------------------------------------------
// Known values.

// Disc of radius rho centred at the foot: I = 2 pi * (1 / (2 h)) rho^2 / (rho^2 + h^2).
double disc_value(double rho, double h) { return kPi * rho * rho / (h * (rho * rho + h * h)); }

Ring2 regular_polygon(int n, double rho, const Vec2& center, double phase) {
  Ring2 ring;
  for (int i = 0; i < n; ++i) {
    const double t = phase + 2.0 * kPi * i / n;
    ring.push_back(center + rho * Vec2(std::cos(t), std::sin(t)));
  }
  return ring;
}

TEST(MeanValueKnown, Regular2000GonIsSqueezedBetweenItsDiscs) {
  const int n = 2000;
  const Vec2 center(3.0, -1.0);
  for (const double rho : {0.5, 1.0, 7.0}) {
    const Ring2 ring = regular_polygon(n, rho, center, 0.3);
    const double apothem = rho * std::cos(kPi / n);
    for (const double h : {1e-3, 0.1, 1.0, 10.0, 100.0}) {
      const double value = closed_form({ring}, center, h);
      // Inscribed disc <= polygon <= circumscribed disc (the integrand is positive) ...
      EXPECT_GE(value, disc_value(apothem, h) * (1.0 - 1e-14)) << rho << " " << h;
      EXPECT_LE(value, disc_value(rho, h) * (1.0 + 1e-14)) << rho << " " << h;
      // ... and the n isosceles triangles integrate in closed form:
      // integral over |theta| < pi/n of a^2 / (2 h (a^2 + h^2 cos^2 theta)) dtheta.
      const double q = std::sqrt(apothem * apothem + h * h);
      const double exact = n * apothem / (h * q) * std::atan(apothem * std::tan(kPi / n) / q);
      EXPECT_LT(relative_error(value, exact), 1e-12) << rho << " " << h;
      EXPECT_LT(relative_error(value, disc_value(rho, h)), 2e-6);
    }
  }
}

TEST(MeanValueKnown, Regular64GonOffCentreMatchesQuadrature) {
  const Ring2 ring = regular_polygon(64, 1.0, Vec2(0.0, 0.0), 0.0);
  for (const Vec2& foot : {Vec2(0.4, 0.1), Vec2(0.999, 0.0), Vec2(1.5, 0.5)})
    for (const double h : {1e-3, 0.05, 2.0})
      EXPECT_LT(relative_error(closed_form({ring}, foot, h), quadrature({ring}, foot, h)), 1e-10);
}

TEST(MeanValueKnown, ZeroHeightAndDegenerateRingsGiveZero) {
  const Ring2 square{Vec2(0, 0), Vec2(1, 0), Vec2(1, 1), Vec2(0, 1)};
  EXPECT_EQ(angle(square, Vec2(0.5, 0.5), 0.0), 0.0);
  EXPECT_EQ(projected_angle(square.data(), 1, Vec2(0.5, 0.5), 1.0), 0.0);
  // Back-and-forth segment and repeated points.
  const Ring2 sliver{Vec2(0, 0), Vec2(1, 1), Vec2(1, 1), Vec2(0, 0)};
  EXPECT_NEAR(angle(sliver, Vec2(0.7, 0.2), 0.3), 0.0, 1e-16);
}

// A ring of `count` random points in [-2, 2]^2; with repeats, every fourth point repeats the one
// before (a zero-length edge).
Ring2 random_ring(std::size_t count, bool repeats, std::mt19937& random) {
  std::uniform_real_distribution<double> coordinate(-2.0, 2.0);
  Ring2 ring;
  for (std::size_t i = 0; i < count; ++i) {
    if (i > 0 && repeats && i % 4 == 0)
      ring.push_back(ring.back());
    else
      ring.emplace_back(coordinate(random), coordinate(random));
  }
  return ring;
}

// projected_angle_plain may sum several edges at a time (SIMD lanes, chosen at run time): it must
// be the sum of edge_projected_angle over the ring's edges, up to the order of the additions, for
// rings of every length (lane tails, more edges than one pass holds), repeated points, feet on a
// vertex or on an edge's line, and any height.
TEST(MeanValueAlgebra, PlainSumIsTheSumOfItsEdgeTerms) {
  std::mt19937 random(17);
  std::uniform_real_distribution<double> coordinate(-2.0, 2.0);
  for (const std::size_t count : {1u, 2u, 3u, 4u, 5u, 7u, 8u, 9u, 63u, 64u, 65u, 129u, 200u}) {
    for (int trial = 0; trial < 20; ++trial) {
      const Ring2 ring = random_ring(count, trial % 3 == 0, random);
      Vec2 foot(coordinate(random), coordinate(random));
      if (trial % 5 == 1) foot = ring[count / 2];                               // on a vertex
      if (trial % 5 == 2 && count > 1) foot = 0.25 * ring[0] + 0.75 * ring[1];  // on an edge's line
      const double height = trial % 4 == 0 ? 1e-7 : std::abs(coordinate(random)) + 1e-3;
      double sum = 0.0, magnitude = 0.0;
      Vec2 a = ring.back() - foot;
      for (std::size_t i = 0; i < ring.size(); ++i) {
        const Vec2 b = ring[i] - foot;
        const double term = edge_projected_angle(a, b, height * height);
        sum += term;
        magnitude += std::abs(term);
        a = b;
      }
      const double plain = projected_angle_plain(ring.data(), ring.size(), foot, height);
      EXPECT_NEAR(plain, sum, 1e-15 * static_cast<double>(ring.size()) * magnitude)
          << ring.size() << " points, trial " << trial;
    }
  }
}

// projected_angle_plain4 (one ring from four feet, one per AVX2 lane) gives projected_angle_plain's
// sum for each foot to the bit: the completion's 3D parts rely on it to stay the same as corner
// by corner. Rings past 64 edges cross the one-foot kernel's chunks; zero-length edges, feet on
// vertices and tiny heights are included.
TEST(MeanValueAlgebra, FourFeetAtOnceGiveEachFootsPlainSum) {
  std::mt19937 random(23);
  std::uniform_real_distribution<double> coordinate(-2.0, 2.0);
  for (const std::size_t count : {1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u, 9u, 63u, 64u, 65u, 129u}) {
    for (int trial = 0; trial < 20; ++trial) {
      const Ring2 ring = random_ring(count, trial % 3 == 0, random);
      double foot_x[4], foot_y[4], height[4], out[4];
      for (int k = 0; k < 4; ++k) {
        Vec2 foot(coordinate(random), coordinate(random));
        if ((trial + k) % 5 == 1) foot = ring[count / 2];  // on a vertex
        foot_x[k] = foot.x();
        foot_y[k] = foot.y();
        height[k] = (trial + k) % 4 == 0 ? 1e-7 : std::abs(coordinate(random)) + 1e-3;
      }
      projected_angle_plain4(ring.data(), ring.size(), foot_x, foot_y, height, out);
      for (int k = 0; k < 4; ++k)
        EXPECT_EQ(out[k], projected_angle_plain(ring.data(), ring.size(),
                                                Vec2(foot_x[k], foot_y[k]), height[k]))
            << ring.size() << " points, trial " << trial << ", lane " << k;
    }
  }
}

// triangle_weights4 (four triangles in AVX2 lanes) gives triangle_weights' weights to the bit:
// ordinary triangles, slivers, both orientations, feet on a corner or an edge, and heights small
// enough for the split form.
TEST(MeanValueAlgebra, FourTrianglesAtOnceGiveEachTrianglesWeights) {
  std::mt19937 random(23);
  std::uniform_real_distribution<double> coordinate(-2.0, 2.0);
  int compared = 0;
  for (int trial = 0; trial < 400; ++trial) {
    std::array<std::array<Vec2, 3>, 4> triangles;
    for (std::size_t t = 0; t < 4; ++t) {
      for (Vec2& corner : triangles[t]) corner = Vec2(coordinate(random), coordinate(random));
      if ((trial + t) % 7 == 0) triangles[t][2] = triangles[t][1];  // a sliver
      if ((trial + t) % 11 == 0)
        triangles[t][2] = 0.5 * (triangles[t][0] + triangles[t][1]);  // flat
    }
    Vec2 foot(coordinate(random), coordinate(random));
    if (trial % 5 == 1) foot = triangles[0][1];                                  // on a corner
    if (trial % 5 == 2) foot = 0.25 * triangles[1][0] + 0.75 * triangles[1][2];  // on an edge
    const double height =
        trial % 4 == 0 ? 1e-7 : (trial % 4 == 1 ? 1e-3 : std::abs(coordinate(random)) + 1e-3);
    const std::size_t count = 1 + static_cast<std::size_t>(trial % 4);
    const Vec2* corners[4];
    for (std::size_t t = 0; t < 4; ++t) corners[t] = triangles[t].data();
    double weights[4][3];
    bool ok[4];
    triangle_weights4(corners, count, foot, height, weights, ok);
    for (std::size_t t = 0; t < count; ++t) {
      double expected[3];
      const bool expected_ok = triangle_weights(triangles[t][0], triangles[t][1], triangles[t][2],
                                                foot, height, expected);
      ASSERT_EQ(ok[t], expected_ok) << "trial " << trial << ", triangle " << t;
      if (!expected_ok) continue;
      ++compared;
      for (int k = 0; k < 3; ++k)
        EXPECT_EQ(weights[t][k], expected[k])
            << "trial " << trial << ", triangle " << t << ", corner " << k;
    }
  }
  EXPECT_GT(compared, 600);
}

// ---------------------------------------------------------------------------------------------
// Limits h -> 0: the projected angle tends to the angle the region subtends at the foot.

TEST(MeanValueLimit, SmallHeightGivesTheSubtendedAngle) {
  const Ring2 square{Vec2(-1, -1), Vec2(1, -1), Vec2(1, 1), Vec2(-1, 1)};
  // A concave L to have a reflex vertex as well.
  const Ring2 ell{Vec2(0, 0), Vec2(2, 0), Vec2(2, 1), Vec2(1, 1), Vec2(1, 2), Vec2(0, 2)};
  for (const double h : {1e-8, 1e-10}) {
    const double tol = 100.0 * h;
    EXPECT_NEAR(angle(square, Vec2(0.3, 0.2), h), 2.0 * kPi, tol);  // inside
    EXPECT_NEAR(angle(square, Vec2(0.999, -0.9), h), 2.0 * kPi, 1e3 * tol);
    EXPECT_NEAR(angle(square, Vec2(3.0, 0.5), h), 0.0, tol);  // outside
    EXPECT_NEAR(angle(square, Vec2(1.0 + 1e-3, 0.5), h), 0.0, 1e3 * tol);
    EXPECT_NEAR(angle(square, Vec2(1.0, 0.2), h), kPi, tol);  // on an edge
    EXPECT_NEAR(angle(square, Vec2(-0.4, 1.0), h), kPi, tol);
    EXPECT_NEAR(angle(square, Vec2(1.0, 1.0), h), 0.5 * kPi, tol);             // at a vertex
    EXPECT_NEAR(angle(ell, Vec2(1.0, 1.0), h), 1.5 * kPi, tol);                // reflex vertex
    EXPECT_NEAR(angle(ell, Vec2(1.5, 1.5), h), 0.0, tol);                      // in the notch
    EXPECT_NEAR(angle(reversed(square), Vec2(0.3, 0.2), h), -2.0 * kPi, tol);  // clockwise
    // Hole: solid part, hole, hole boundary.
    // (An axis-parallel hole, so that its edge midpoint is exactly on the edge: a foot off the
    // line by one rounding error d gives a term ~ d / h, visible at h = 1e-10.)
    const Ring2 hole{Vec2(-0.5, -0.5), Vec2(-0.5, 0.5), Vec2(0.5, 0.5), Vec2(0.5, -0.5)};
    const auto holed = [&](const Vec2& f) { return angle(square, f, h) + angle(hole, f, h); };
    EXPECT_NEAR(holed(Vec2(0.8, 0.8)), 2.0 * kPi, tol);
    EXPECT_NEAR(holed(Vec2(0.1, 0.0)), 0.0, tol);
    EXPECT_NEAR(holed(0.5 * (hole[2] + hole[3])), kPi, tol);
  }
}

// ---------------------------------------------------------------------------------------------
// Orientation, additivity and invariances.

TEST(MeanValueAlgebra, ReversalNegatesAndCancels) {
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    const StarPolygon star = random_star(rng, 5 + trial, Vec2(0.3, -0.2), 0.4, 1.0);
    const Ring2 back = reversed(star.ring);
    for (const Vec2& foot : test_feet(rng, star, {star.ring})) {
      for (const double h : {1e-3, 0.2, 5.0}) {
        const double forward = angle(star.ring, foot, h), backward = angle(back, foot, h);
        // Each edge term is exactly antisymmetric; the two sums add them in opposite orders, so
        // they differ by a few roundings of partial sums up to 2 pi.
        EXPECT_NEAR(forward + backward, 0.0, 4e-15 * std::max(1.0, std::abs(forward)));
        // The ring followed by its reverse as ONE ring: every edge is walked both ways (plus
        // two zero-length joins) - the degenerate bridges clipping produces.
        Ring2 both = star.ring;
        both.insert(both.end(), back.begin(), back.end());
        EXPECT_NEAR(angle(both, foot, h), 0.0, 1e-14 * std::max(1.0, std::abs(forward)));
      }
    }
  }
}

TEST(MeanValueAlgebra, SplittingAlongAChordAdds) {
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const StarPolygon star = random_star(rng, 12, Vec2(0.0, 0.0), 0.5, 1.0);
    // Split along the chord v0 -> v_k through the interior via the centre: two star pieces
    // (v0..vk, c) and (vk..v0, c) whose shared edges run in opposite directions.
    const std::size_t k = 6;
    Ring2 first(star.ring.begin(), star.ring.begin() + k + 1);
    first.push_back(star.center);
    Ring2 second(star.ring.begin() + k, star.ring.end());
    second.push_back(star.ring[0]);
    second.push_back(star.center);
    for (const Vec2& foot : test_feet(rng, star, {star.ring})) {
      for (const double h : {1e-4, 0.3, 3.0}) {
        const double whole = angle(star.ring, foot, h);
        const double parts = angle(first, foot, h) + angle(second, foot, h);
        EXPECT_NEAR(parts, whole, 1e-13 * std::max(1.0, std::abs(whole)));
      }
    }
  }
}

TEST(MeanValueAlgebra, ScaleTranslationAndStartPointInvariance) {
  std::mt19937_64 rng(3);
  const StarPolygon star = random_star(rng, 17, Vec2(0.0, 0.0), 0.3, 1.0);
  for (const Vec2& foot : test_feet(rng, star, {star.ring})) {
    for (const double h : {1e-3, 0.5, 4.0}) {
      const double base = angle(star.ring, foot, h);
      const double tol = 1e-12 * std::max(1.0, std::abs(base));
      for (const double s : {1e-3, 7.0, 1e4}) {  // projected angle is scale-free
        Ring2 scaled = star.ring;
        for (Vec2& p : scaled) p *= s;
        EXPECT_NEAR(angle(scaled, s * foot, s * h), base, tol);
      }
      const Vec2 shift(123.25, -7.5);
      Ring2 moved = star.ring;
      for (Vec2& p : moved) p += shift;
      EXPECT_NEAR(angle(moved, foot + shift, h), base, 1e-10 * std::max(1.0, std::abs(base)));
      Ring2 rotated = star.ring;
      std::rotate(rotated.begin(), rotated.begin() + 5, rotated.end());
      EXPECT_NEAR(angle(rotated, foot, h), base, tol);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Winding numbers.

TEST(MeanValueWinding, SimpleCases) {
  const Ring2 square{Vec2(0, 0), Vec2(2, 0), Vec2(2, 2), Vec2(0, 2)};
  const Ring2 ell{Vec2(0, 0), Vec2(2, 0), Vec2(2, 1), Vec2(1, 1), Vec2(1, 2), Vec2(0, 2)};
  const auto wn = [](const Ring2& r, const Vec2& p) {
    return winding_number(r.data(), r.size(), p);
  };
  EXPECT_EQ(wn(square, Vec2(1, 1)), 1);
  EXPECT_EQ(wn(square, Vec2(3, 1)), 0);
  EXPECT_EQ(wn(square, Vec2(1, -1e-12)), 0);
  EXPECT_EQ(wn(square, Vec2(-1, 2)), 0);  // on the line of an edge, beyond it
  EXPECT_EQ(wn(reversed(square), Vec2(1, 1)), -1);
  EXPECT_EQ(wn(ell, Vec2(0.5, 1.5)), 1);
  EXPECT_EQ(wn(ell, Vec2(1.5, 1.5)), 0);  // the notch
  EXPECT_EQ(wn(ell, Vec2(1.5, 0.5)), 1);
  // Points on the ring count as inside (documented), also vertices.
  EXPECT_EQ(wn(square, Vec2(2, 1)), 1);
  EXPECT_EQ(wn(square, Vec2(0, 0)), 1);
  EXPECT_EQ(wn(ell, Vec2(1, 1)), 1);
  // A ring wound twice.
  Ring2 twice = regular_polygon(5, 1.0, Vec2(0, 0), 0.0);
  const Ring2 again = twice;
  twice.insert(twice.end(), again.begin(), again.end());
  EXPECT_EQ(wn(twice, Vec2(0.1, 0.05)), 2);
  // Agrees with the small-height projected angle / 2 pi on random star polygons.
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> coord(-1.5, 1.5);
  for (int trial = 0; trial < 10; ++trial) {
    const StarPolygon star = random_star(rng, 5 + 2 * trial, Vec2(0, 0), 0.3, 1.0);
    for (int k = 0; k < 50; ++k) {
      const Vec2 p(coord(rng), coord(rng));
      EXPECT_EQ(wn(star.ring, p),
                static_cast<int>(std::lround(angle(star.ring, p, 1e-9) / (2 * kPi))));
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Clipping rings to convex faces.

using HalfPlanes = std::vector<Eigen::Vector3d>;

// a x + b y + c >= 0
Eigen::Vector3d half_plane(double a, double b, double c) { return Eigen::Vector3d(a, b, c); }

// Random feet over a square around the clipped geometry (inside, outside, across clip lines).
std::vector<Vec2> clip_feet(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> coord(lo, hi);
  std::vector<Vec2> feet;
  for (int k = 0; k < 40; ++k) feet.emplace_back(coord(rng), coord(rng));
  return feet;
}

TEST(Clip, SquareByHalfPlanesIsARectangle) {
  const Ring2 square{Vec2(0, 0), Vec2(2, 0), Vec2(2, 2), Vec2(0, 2)};
  const HalfPlanes planes{half_plane(1, 0, -0.5), half_plane(0, -1, 1.5)};  // x >= .5, y <= 1.5
  const Ring2 clipped = clip_ring_to_convex(square, planes);
  const Ring2 rectangle{Vec2(0.5, 0), Vec2(2, 0), Vec2(2, 1.5), Vec2(0.5, 1.5)};
  EXPECT_NEAR(signed_area(clipped), 1.5 * 1.5, 1e-15);
  std::mt19937_64 rng(1);
  std::vector<Vec2> feet = clip_feet(rng, -0.5, 2.5);
  feet.emplace_back(0.5, 1.0);  // on a clip line
  feet.emplace_back(0.5, 1.5);  // at the clipped corner
  for (const Vec2& foot : feet)
    for (const double h : {1e-6, 0.1, 3.0})
      EXPECT_NEAR(angle(clipped, foot, h), angle(rectangle, foot, h), 1e-14);
  // Clockwise rings (holes) stay clockwise.
  EXPECT_NEAR(signed_area(clip_ring_to_convex(reversed(square), planes)), -2.25, 1e-15);
}

TEST(Clip, TrivialCases) {
  const Ring2 square{Vec2(0, 0), Vec2(2, 0), Vec2(2, 2), Vec2(0, 2)};
  EXPECT_EQ(clip_ring_to_convex(square, {}), square);
  EXPECT_EQ(clip_ring_to_convex(square, {half_plane(1, 0, 5)}), square);     // all inside
  EXPECT_TRUE(clip_ring_to_convex(square, {half_plane(1, 0, -5)}).empty());  // all outside
  // Touching the clip line in an edge or a vertex only leaves nothing of positive area: the
  // result need not be empty (a back-and-forth sliver along the line is kept) but it must
  // integrate to nothing.
  for (const Eigen::Vector3d& touching : {half_plane(-1, 0, 0), half_plane(-1, -1, 0)}) {
    const Ring2 sliver = clip_ring_to_convex(square, {touching});
    EXPECT_EQ(signed_area(sliver), 0.0);
    for (const Vec2& foot : {Vec2(-1.0, 0.5), Vec2(1.0, 1.0), Vec2(0.0, 1.0)})
      EXPECT_EQ(angle(sliver, foot, 0.5), 0.0) << foot.transpose();
  }
  // Two disjoint clip regions (empty intersection).
  EXPECT_TRUE(
      clip_ring_to_convex(square, {half_plane(1, 0, -1.5), half_plane(-1, 0, 0.5)}).empty());
}

TEST(Clip, LShapeSplitIntoTwoPiecesKeepsCancellingBridges) {
  // L = [0,3]x[0,1] u [0,1]x[0,3], cut by x + y >= 2.5, x <= 2.8, y <= 2.8: two separate
  // quadrilaterals, which the clipped single ring joins by back-and-forth edges on x + y = 2.5.
  const Ring2 ell{Vec2(0, 0), Vec2(3, 0), Vec2(3, 1), Vec2(1, 1), Vec2(1, 3), Vec2(0, 3)};
  const HalfPlanes planes{half_plane(1, 1, -2.5), half_plane(-1, 0, 2.8), half_plane(0, -1, 2.8)};
  const Ring2 piece_a{Vec2(2.5, 0), Vec2(2.8, 0), Vec2(2.8, 1), Vec2(1.5, 1)};
  const Ring2 piece_b{Vec2(1, 1.5), Vec2(1, 2.8), Vec2(0, 2.8), Vec2(0, 2.5)};
  const Ring2 clipped = clip_ring_to_convex(ell, planes);
  ASSERT_FALSE(clipped.empty());
  EXPECT_NEAR(signed_area(clipped), signed_area(piece_a) + signed_area(piece_b), 1e-14);
  std::mt19937_64 rng(2);
  std::vector<Vec2> feet = clip_feet(rng, -0.5, 3.5);
  // On the bridge line (between and on the pieces), at piece corners, near the bridge.
  for (const Vec2& f : {Vec2(1.25, 1.25), Vec2(2.0, 0.5), Vec2(0.5, 2.0), Vec2(1.5, 1.0),
                        Vec2(1.0, 1.5), Vec2(2.5, 0.0), Vec2(1.25 + 1e-9, 1.25)})
    feet.push_back(f);
  double worst = 0.0;
  for (const Vec2& foot : feet) {
    for (const double h : {1e-7, 1e-3, 0.2, 4.0}) {
      const double want = angle(piece_a, foot, h) + angle(piece_b, foot, h);
      const double got = angle(clipped, foot, h);
      worst = std::max(worst, std::abs(got - want));
      EXPECT_NEAR(got, want, 1e-13) << foot.transpose() << " h " << h;
    }
  }
  std::printf("[ info ] L-shape clip worst absolute error %.3g\n", worst);
}

TEST(Clip, HoleRingClippedSeparatelyMatchesExactIntersection) {
  // Square [0,4]^2 with hole [1,3]^2, clipped to the strip 2 <= x <= 5: U-shaped piece
  // [2,4]x[0,4] minus [2,3]x[1,3], i.e. the rectangles [2,4]x[0,1], [3,4]x[1,3], [2,4]x[3,4].
  const Ring2 outer{Vec2(0, 0), Vec2(4, 0), Vec2(4, 4), Vec2(0, 4)};
  const Ring2 hole = reversed(Ring2{Vec2(1, 1), Vec2(3, 1), Vec2(3, 3), Vec2(1, 3)});
  const HalfPlanes strip{half_plane(1, 0, -2), half_plane(-1, 0, 5)};
  const Ring2 a = clip_ring_to_convex(outer, strip), b = clip_ring_to_convex(hole, strip);
  const std::vector<Ring2> truth{{Vec2(2, 0), Vec2(4, 0), Vec2(4, 1), Vec2(2, 1)},
                                 {Vec2(3, 1), Vec2(4, 1), Vec2(4, 3), Vec2(3, 3)},
                                 {Vec2(2, 3), Vec2(4, 3), Vec2(4, 4), Vec2(2, 4)}};
  std::mt19937_64 rng(4);
  for (const Vec2& foot : clip_feet(rng, -1.0, 5.0)) {
    for (const double h : {1e-5, 0.3, 2.0}) {
      double want = 0.0;
      for (const Ring2& r : truth) want += angle(r, foot, h);
      EXPECT_NEAR(angle(a, foot, h) + angle(b, foot, h), want, 1e-13);
    }
  }
}

TEST(Clip, RandomRingsPartitionedByConvexPolygonAddUp) {
  // For half-planes H_1..H_m: ring = (ring n H_1..H_m) + sum_i (ring n H_1..H_{i-1} n not H_i),
  // a partition of the plane, so the clipped integrals must add up to the unclipped one.
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int trial = 0; trial < 25; ++trial) {
    const StarPolygon star =
        random_star(rng, 5 + static_cast<int>(rng() % 26), Vec2(0, 0), 0.3, 1.0);
    const bool hole = trial % 3 == 0;
    const Ring2 ring = hole ? reversed(star.ring) : star.ring;
    HalfPlanes planes;
    const int m = 3 + static_cast<int>(rng() % 4);
    const double phase = 2.0 * kPi * unit(rng);
    for (int i = 0; i < m; ++i) {  // a convex polygon around a point near the centre
      const double t = phase + 2.0 * kPi * i / m;
      const Vec2 n(std::cos(t), std::sin(t));
      planes.push_back(half_plane(-n.x(), -n.y(), 0.2 + 0.6 * unit(rng)));
    }
    std::vector<Ring2> pieces{clip_ring_to_convex(ring, planes)};
    for (int i = 0; i < m; ++i) {
      HalfPlanes chain(planes.begin(), planes.begin() + i);
      chain.push_back(-planes[static_cast<std::size_t>(i)]);
      pieces.push_back(clip_ring_to_convex(ring, chain));
    }
    double area = 0.0;
    for (const Ring2& p : pieces) area += signed_area(p);
    EXPECT_NEAR(area, signed_area(ring), 1e-13);
    for (const Vec2& foot : test_feet(rng, star, {ring})) {
      for (const double h : {1e-4, 0.1, 2.0}) {
        const double whole = angle(ring, foot, h);
        double sum = 0.0;
        for (const Ring2& p : pieces) sum += angle(p, foot, h);
        EXPECT_NEAR(sum, whole, 1e-12 * std::max(1.0, std::abs(whole)));
      }
    }
  }
}

}  // namespace
}  // namespace sonoshape::recon::mean_value_test
