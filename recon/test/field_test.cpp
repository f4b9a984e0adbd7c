// The per-cell mean-value field on small hand-made arrangements: constant precision, symmetry,
// frame independence, continuity across slice faces, face limits, several labels and
// degenerate arrangements.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include "arrangement.hpp"
#include "cell_field.hpp"
#include "sonoshape/core/errors.hpp"

namespace sonoshape::recon::field_test {
namespace {

constexpr double kPi = std::numbers::pi;
const Box3 kBox{Vec3::Constant(-2.0), Vec3::Constant(2.0)};
constexpr double kSize = 4.0;  // box side

// The engine's wiring (reconstruct.cpp): slices in order, plane normal u x v, then the field.
class BuiltField {
 public:
  BuiltField(const SliceSet& set, const Box3& box)
      : ids_(set.material_ids()), slices_(prepare_slices(set, ids_, box)), arrangement_(box) {
    for (std::size_t s = 0; s < slices_.size(); ++s) {
      const Vec3 normal = slices_[s].u.cross(slices_[s].v);
      arrangement_.insert_plane(normal, -normal.dot(slices_[s].origin), static_cast<int>(s));
    }
    field_ = std::make_unique<CellField>(arrangement_, slices_, static_cast<int>(ids_.size()));
  }
  BuiltField(const BuiltField&) = delete;
  BuiltField& operator=(const BuiltField&) = delete;

  std::vector<double> operator()(const Vec3& p) const {
    std::vector<double> out(static_cast<std::size_t>(field_->function_count()));
    field_->evaluate(p, out.data());
    return out;
  }
  int cell(const Vec3& p) const {
    std::vector<double> out(static_cast<std::size_t>(field_->function_count()));
    return field_->evaluate(p, out.data());
  }
  const Arrangement& arrangement() const { return arrangement_; }
  const CellField& field() const { return *field_; }

 private:
  std::vector<int> ids_;
  std::vector<PreparedSlice> slices_;
  Arrangement arrangement_;
  std::unique_ptr<CellField> field_;
};

// A slice on the plane x_axis = c. Variant 0: frame (e_{axis+1}, e_{axis+2}) at c e_axis.
// Variant 1: the same plane with the frame turned by 0.7 rad, u and v swapped (normal flipped)
// and the origin moved inside the plane - the field must not notice.
LabeledSlice axis_slice(int axis, double c, int variant = 0) {
  const Vec3 e1 = Vec3::Unit((axis + 1) % 3), e2 = Vec3::Unit((axis + 2) % 3);
  LabeledSlice s;
  s.origin_mm = c * Vec3::Unit(axis);
  s.u = e1;
  s.v = e2;
  if (variant == 1) {
    const double t = 0.7;
    s.u = std::cos(t) * e2 - std::sin(t) * e1;
    s.v = std::cos(t) * e1 + std::sin(t) * e2;
    s.origin_mm += 0.3 * e1 - 0.2 * e2;
  }
  return s;
}

// A region given by world points on the slice's plane.
Region world_region(int label, const LabeledSlice& s, const std::vector<Vec3>& outer,
                    const std::vector<std::vector<Vec3>>& holes = {}) {
  Region r;
  r.label = label;
  for (const Vec3& p : outer) r.outer.push_back(s.to_plane(p));
  for (const auto& hole : holes) {
    r.holes.emplace_back();
    for (const Vec3& p : hole) r.holes.back().push_back(s.to_plane(p));
  }
  return r;
}

// The rectangle [a0, a1] x [b0, b1] of a plane x_axis = c in the axes (axis+1, axis+2).
std::vector<Vec3> axis_rect(int axis, double c, double a0, double a1, double b0, double b1) {
  const auto point = [&](double a, double b) {
    Vec3 p;
    p[axis] = c;
    p[(axis + 1) % 3] = a;
    p[(axis + 2) % 3] = b;
    return p;
  };
  return {point(a0, b0), point(a1, b0), point(a1, b1), point(a0, b1)};
}

Vec3 random_point(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> coord(lo, hi);
  return Vec3(coord(rng), coord(rng), coord(rng));
}

// Every value finite and in [-1, 1], and the weights a partition of unity.
void expect_valid(const std::vector<double>& f, const Vec3& p) {
  double sum = 0.0;
  for (const double v : f) {
    ASSERT_TRUE(std::isfinite(v)) << p.transpose();
    EXPECT_GE(v, -1.0 - 1e-12) << p.transpose();
    EXPECT_LE(v, 1.0 + 1e-12) << p.transpose();
    sum += 0.5 * (v + 1.0);
  }
  EXPECT_NEAR(sum, 1.0, 1e-12) << p.transpose();
}

// ---------------------------------------------------------------------------------------------
// The cube [-1, 1]^3 cut out by six slices inside the box.

// `labelled(axis, sign)` returns the world rectangle covered by label 1 on that cube face's
// plane (empty: none).
template <class Labelled>
SliceSet cube_set(int variant, const Labelled& labelled) {
  SliceSet set;
  set.bounds = kBox;
  set.labels = {{1, "inside"}};  // declared, so a set with no region still has the material
  for (int axis = 0; axis < 3; ++axis) {
    for (const double sign : {-1.0, 1.0}) {
      LabeledSlice s = axis_slice(axis, sign, (variant == 1 && axis != 1) ? 1 : 0);
      const std::vector<Vec3> rect = labelled(axis, sign);
      if (!rect.empty()) s.regions.push_back(world_region(1, s, rect));
      set.slices.push_back(std::move(s));
    }
  }
  return set;
}

TEST(FieldConstant, CellWithAllFacesInsideIsExactlyInside) {
  // Every cube face lies inside a label-1 square larger than the face: f_1 = 1, f_0 = -1 in the
  // inner cell, whatever the point, frame or distance to the faces.
  for (const int variant : {0, 1}) {
    const BuiltField field(
        cube_set(variant,
                 [](int axis, double sign) { return axis_rect(axis, sign, -1.5, 1.5, -1.5, 1.5); }),
        kBox);
    std::mt19937_64 rng(17);
    for (int k = 0; k < 300; ++k) {
      const Vec3 p = random_point(rng, -0.999, 0.999);
      const std::vector<double> f = field(p);
      EXPECT_NEAR(f[1], 1.0, 1e-12) << "variant " << variant << " at " << p.transpose();
      EXPECT_NEAR(f[0], -1.0, 1e-12) << "variant " << variant << " at " << p.transpose();
    }
    // Near and on faces, edges and corners. With the turned frames the face polygon and its
    // clipped label part are rounded differently (~1e-16), which a point at distance d from a
    // face edge sees amplified by 1/d: conditioning, not an error of the formula.
    for (const double d : {1e-3, 1e-7, 1e-10, 0.0}) {
      if (variant == 1 && d == 0.0) continue;  // see the disabled test below
      const double tol = variant == 0 ? 1e-12 : std::max(1e-12, 1e-15 / d);
      for (const Vec3& p : {Vec3(1.0 - d, 0.2, -0.3), Vec3(1.0 - d, 1.0 - d, 0.5),
                            Vec3(-1.0 + d, 1.0 - d, -1.0 + d)}) {
        const std::vector<double> f = field(p);
        EXPECT_NEAR(f[1], 1.0, tol) << "variant " << variant << " at " << p.transpose();
        EXPECT_NEAR(f[0], -1.0, tol) << "variant " << variant << " at " << p.transpose();
      }
    }
    // Outside the cube the box faces (outside) pull the field down; it stays valid.
    for (int k = 0; k < 200; ++k) {
      const Vec3 p = random_point(rng, -1.999, 1.999);
      expect_valid(field(p), p);
    }
  }
  // No region at all: the inner cell is exactly outside.
  const BuiltField empty(cube_set(0, [](int, double) { return std::vector<Vec3>{}; }), kBox);
  std::mt19937_64 rng(18);
  for (int k = 0; k < 50; ++k) {
    const std::vector<double> f = empty(random_point(rng, -0.99, 0.99));
    EXPECT_EQ(f[0], 1.0);
    EXPECT_EQ(f[1], -1.0);
  }
}

// KNOWN ISSUE (reported, not fixed): a point exactly on an edge of the arrangement (on two
// slices) whose slices both carry the label there. It is located in one of the cells around the
// edge, and the on-face rule tests its foot against the label part clipped to that cell's face,
// where the foot lies exactly on the part's boundary. winding_number counts boundary points as
// inside only when the rounded coordinates agree exactly, which holds for axis-aligned frames
// (variant 0) but not for turned frames (variant 1), so f_1 flips to -1 at some edge points.
TEST(FieldConstant, OnAnEdgeBetweenTwoLabelledSlicesTheLabelHolds) {
  const BuiltField field(
      cube_set(1,
               [](int axis, double sign) { return axis_rect(axis, sign, -1.5, 1.5, -1.5, 1.5); }),
      kBox);
  for (const Vec3& p : {Vec3(-1.0, 1.0, -1.0), Vec3(1.0, 1.0, 1.0), Vec3(1.0, 0.3, 1.0),
                        Vec3(-1.0, -0.7, -1.0), Vec3(0.2, 1.0, -1.0)})
    EXPECT_EQ(field(p)[1], 1.0) << p.transpose();
}

// Label 1 on the half x > 0 of every cube face (all of x = +1, none of x = -1): the mirror
// x -> -x swaps the label with its complement on the inner cell's faces.
std::vector<Vec3> half_labelled(int axis, double sign) {
  if (axis == 0) return sign > 0 ? axis_rect(0, 1.0, -1.5, 1.5, -1.5, 1.5) : std::vector<Vec3>{};
  // On planes y = +-1 the in-plane axes are (z, x); on z = +-1 they are (x, y).
  return axis == 1 ? axis_rect(1, sign, -1.5, 1.5, 0.0, 1.5)
                   : axis_rect(2, sign, 0.0, 1.5, -1.5, 1.5);
}

TEST(FieldSymmetry, MirrorSwapsTheLabelWithItsComplement) {
  for (const int variant : {0, 1}) {
    const BuiltField field(cube_set(variant, half_labelled), kBox);
    std::mt19937_64 rng(5);
    double largest = 0.0;
    for (int k = 0; k < 300; ++k) {
      const Vec3 p = random_point(rng, -0.999, 0.999);
      const Vec3 mirror(-p.x(), p.y(), p.z());
      const double f = field(p)[1], g = field(mirror)[1];
      EXPECT_NEAR(f, -g, 1e-12) << p.transpose();
      largest = std::max(largest, std::abs(f));
      EXPECT_NEAR(field(Vec3(0.0, p.y(), p.z()))[1], 0.0, 1e-12) << p.transpose();
      // Labelled side wins.
      if (p.x() > 1e-3) {
        EXPECT_GT(f, 0.0) << p.transpose();
      }
    }
    EXPECT_GT(largest, 0.5);  // not trivially zero
  }
}

TEST(FieldFrames, FieldDoesNotDependOnTheSliceFrames) {
  // Same planes and regions, frames turned, flipped and shifted: the same field everywhere.
  const BuiltField a(cube_set(0, half_labelled), kBox), b(cube_set(1, half_labelled), kBox);
  std::mt19937_64 rng(6);
  for (int k = 0; k < 400; ++k) {
    const Vec3 p = random_point(rng, -1.999, 1.999);
    const std::vector<double> fa = a(p), fb = b(p);
    expect_valid(fa, p);
    for (std::size_t l = 0; l < fa.size(); ++l) EXPECT_NEAR(fa[l], fb[l], 1e-10) << p.transpose();
  }
}

// ---------------------------------------------------------------------------------------------
// A general set: z = 0 with a holed region, x = 0.5 and an oblique slice with regions, y = -0.3
// with none.

struct ProbeSet {
  SliceSet set;
  LabeledSlice oblique;
};

LabeledSlice oblique_slice() {
  LabeledSlice s;
  s.origin_mm = Vec3(0.1, -0.2, 0.9);
  s.u = Vec3(1.0, 0.0, -0.3).normalized();
  s.v = Vec3(0.0, 1.0, 0.2);
  s.v = (s.v - s.v.dot(s.u) * s.u).normalized();
  return s;
}

SliceSet probe_set() {
  SliceSet set;
  set.bounds = kBox;
  LabeledSlice z0 = axis_slice(2, 0.0);
  z0.regions.push_back(world_region(1, z0, axis_rect(2, 0.0, -1.0, 1.0, -1.0, 1.0),
                                    {axis_rect(2, 0.0, -0.4, -0.1, 0.1, 0.4)}));
  LabeledSlice x1 = axis_slice(0, 0.5);
  x1.regions.push_back(world_region(1, x1, axis_rect(0, 0.5, -0.8, 0.6, -0.9, 0.7)));
  LabeledSlice y1 = axis_slice(1, -0.3);
  LabeledSlice ob = oblique_slice();
  ob.regions.push_back(world_region(
      1, ob,
      {ob.to_world(Vec2(-0.6, -0.5)), ob.to_world(Vec2(0.8, -0.4)), ob.to_world(Vec2(0.1, 0.9))}));
  set.slices = {z0, x1, y1, ob};
  return set;
}

// Points on the plane of `s` (random in-plane positions) that stay in the box and at least
// `clearance` from the other probe planes, so one face dominates both sides.
std::vector<Vec2> feet_on(std::mt19937_64& rng, const LabeledSlice& s, const SliceSet& set,
                          double clearance) {
  std::uniform_real_distribution<double> coord(-1.6, 1.6);
  std::vector<Vec2> feet;
  while (feet.size() < 60) {
    const Vec2 f(coord(rng), coord(rng));
    const Vec3 p = s.to_world(f);
    if (!kBox.padded(-clearance).contains(p)) continue;
    bool clear = true;
    for (const LabeledSlice& other : set.slices) {
      const Vec3 n = other.normal().normalized();
      if (std::abs(n.dot(s.normal().normalized())) > 1.0 - 1e-12 &&
          std::abs(n.dot(p - other.origin_mm)) < 1e-12)
        continue;  // the plane itself
      clear &= std::abs(n.dot(p - other.origin_mm)) > clearance;
    }
    if (clear) feet.push_back(f);
  }
  return feet;
}

TEST(FieldContinuity, AcrossEverySliceFace) {
  const SliceSet set = probe_set();
  const BuiltField field(set, kBox);
  std::mt19937_64 rng(21);
  const double eps = 1e-7 * kSize;
  double worst = 0.0;
  for (const LabeledSlice& s : set.slices) {
    std::vector<Vec2> feet = feet_on(rng, s, set, 0.05 * kSize);
    if (&s == &set.slices[0]) {  // z = 0: on a contour, in the hole, outside the region
      feet.emplace_back(1.0, 0.35);
      feet.emplace_back(-0.25, 0.25);
      feet.emplace_back(1.5, -1.2);
    }
    const Vec3 n = s.normal().normalized();
    for (const Vec2& foot : feet) {
      const Vec3 p = s.to_world(foot);
      const Vec3 above = p + eps * n, below = p - eps * n;
      ASSERT_NE(field.cell(above), field.cell(below)) << "not across a face";
      const std::vector<double> fa = field(above), fb = field(below);
      for (std::size_t l = 0; l < fa.size(); ++l) {
        worst = std::max(worst, std::abs(fa[l] - fb[l]));
        EXPECT_NEAR(fa[l], fb[l], 1e-5)
            << "foot " << foot.transpose() << " on " << s.origin_mm.transpose();
      }
    }
  }
  std::printf("[ info ] continuity across faces: worst jump %.3g at eps %.3g\n", worst, eps);
}

TEST(FieldLimit, ApproachingASliceFace) {
  const SliceSet set = probe_set();
  const BuiltField field(set, kBox);
  // On z = 0 (feet in (x, y)); the face there is bounded by x = 0.5 and y = -0.3 for x < 0.5.
  struct Case {
    Vec2 foot;
    double limit;  // of f_1 as h -> 0+
  };
  const std::vector<Case> cases{
      {Vec2(0.2, 0.6), 1.0},      // inside the region
      {Vec2(-0.25, 0.25), -1.0},  // in its hole
      {Vec2(-1.5, 1.2), -1.0},    // outside
      {Vec2(-1.0, 0.35), 0.0},    // on the contour, half of the angle inside
      {Vec2(-0.1, 0.25), 0.0},    // on the hole's contour
      {Vec2(-1.0, 1.0), -0.5},    // at a convex corner of the region: a quarter inside
      {Vec2(-0.4, 0.4), 0.5},     // at a corner of the hole: three quarters inside
  };
  for (const Case& c : cases) {
    for (const double side : {1.0, -1.0}) {
      double previous = 2.0;
      for (const double h : {1e-3, 1e-5, 1e-7, 1e-9}) {
        const Vec3 p(c.foot.x(), c.foot.y(), side * h * kSize);
        const double f1 = field(p)[1];
        const double error = std::abs(f1 - c.limit);
        EXPECT_LE(error, std::max(1e-3, 20.0 * h)) << c.foot.transpose() << " h " << h;
        EXPECT_LE(error, previous + 1e-12) << "not converging at " << c.foot.transpose();
        previous = error;
      }
      EXPECT_NEAR(field(Vec3(c.foot.x(), c.foot.y(), side * 1e-9 * kSize))[1], c.limit, 1e-3);
    }
  }
  // Exactly on the face: the face's own indicator (the contour counts as inside).
  EXPECT_EQ(field(Vec3(0.2, 0.6, 0.0))[1], 1.0);
  EXPECT_EQ(field(Vec3(-0.25, 0.25, 0.0))[1], -1.0);
  EXPECT_EQ(field(Vec3(-1.5, 1.2, 0.0))[1], -1.0);
  EXPECT_EQ(field(Vec3(-1.5, 1.2, 0.0))[0], 1.0);
  EXPECT_EQ(field(Vec3(-1.0, 0.35, 0.0))[1], 1.0);
  // Outside the box (and on it) the outside label holds.
  for (const Vec3& p : {Vec3(2.5, 0.0, 0.0), Vec3(2.0, 0.0, 0.0), Vec3(0.0, -2.0, 0.3)}) {
    EXPECT_EQ(field.cell(p), -1);
    EXPECT_EQ(field(p)[0], 1.0);
    EXPECT_EQ(field(p)[1], -1.0);
  }
}

TEST(FieldLimit, OnAFaceOnlyThatFaceDecides) {
  // The point lies exactly on z = 0 (h = 0) with its foot outside that slice's region, but
  // another face of its cell (x = 0.5, fully labelled, at distance 0.1) has already added its
  // mean-value weight when the on-face face comes up (z = 0 is inserted last, so its face is
  // last in the cell). The value must be the face's indicator, i.e. the limit from h -> 0+.
  SliceSet set;
  set.bounds = kBox;
  LabeledSlice x1 = axis_slice(0, 0.5);
  x1.regions.push_back(world_region(1, x1, axis_rect(0, 0.5, -1.9, 1.9, -1.9, 1.9)));
  LabeledSlice z0 = axis_slice(2, 0.0);
  z0.regions.push_back(world_region(1, z0, axis_rect(2, 0.0, -1.5, -0.5, -1.0, 1.0)));
  set.slices = {x1, z0};
  const BuiltField field(set, kBox);
  for (const Vec3& p : {Vec3(0.6, 0.2, 0.0), Vec3(1.8, -1.0, 0.0), Vec3(0.0, 0.0, 0.0)}) {
    const double limit = field(p + Vec3(0.0, 0.0, 1e-9))[1];
    EXPECT_NEAR(limit, -1.0, 1e-6) << p.transpose();
    EXPECT_EQ(field(p)[1], -1.0) << "on the face at " << p.transpose();
    EXPECT_EQ(field(p)[0], 1.0) << "on the face at " << p.transpose();
  }
  // And inside the region on the face: label 1.
  EXPECT_EQ(field(Vec3(-1.0, 0.0, 0.0))[1], 1.0);
}

// ---------------------------------------------------------------------------------------------
// Several labels.

TEST(FieldLabels, ArgmaxNearEachRegionAndPartitionOfUnity) {
  // Material ids 3 and 7 become function indices 1 and 2.
  SliceSet set;
  set.bounds = kBox;
  LabeledSlice z0 = axis_slice(2, 0.0);
  z0.regions.push_back(world_region(3, z0, axis_rect(2, 0.0, -1.2, -0.1, -1.0, 1.0)));
  z0.regions.push_back(world_region(7, z0, axis_rect(2, 0.0, 0.1, 1.2, -1.0, 1.0)));
  LabeledSlice x0 = axis_slice(0, 0.05);
  x0.regions.push_back(world_region(7, x0, axis_rect(0, 0.05, -1.0, 1.0, -1.5, -0.5)));
  x0.regions.push_back(world_region(3, x0, axis_rect(0, 0.05, -1.0, 1.0, 0.5, 1.5)));
  LabeledSlice oblique = oblique_slice();
  oblique.regions.push_back(
      world_region(3, oblique,
                   {oblique.to_world(Vec2(-0.5, -0.5)), oblique.to_world(Vec2(0.5, -0.5)),
                    oblique.to_world(Vec2(0.0, 0.5))}));
  set.slices = {z0, x0, oblique};
  const BuiltField field(set, kBox);
  ASSERT_EQ(field.field().function_count(), 3);
  const auto argmax = [](const std::vector<double>& f) {
    return static_cast<int>(std::max_element(f.begin(), f.end()) - f.begin());
  };
  for (const double h : {1e-2, 1e-4, -1e-4}) {
    EXPECT_EQ(argmax(field(Vec3(-0.6, 0.3, h))), 1);         // label 3 below/above its region
    EXPECT_EQ(argmax(field(Vec3(0.6, -0.3, h))), 2);         // label 7
    EXPECT_EQ(argmax(field(Vec3(-1.6, 0.3, h))), 0);         // outside both
    EXPECT_EQ(argmax(field(Vec3(0.05 + h, 0.3, -1.0))), 2);  // label 7 on x = 0.05
    EXPECT_EQ(argmax(field(Vec3(0.05 + h, 0.3, 1.3))), 1);   // label 3 on x = 0.05
  }
  std::mt19937_64 rng(31);
  for (int k = 0; k < 500; ++k) {
    const Vec3 p = random_point(rng, -1.999, 1.999);
    expect_valid(field(p), p);
  }
}

TEST(FieldLabels, ManyLabelsEachWinsNearItsRegion) {
  // More functions than the evaluator's stack buffer (16): the heap path.
  SliceSet set;
  set.bounds = kBox;
  LabeledSlice z0 = axis_slice(2, 0.0);
  const int count = 20;
  for (int k = 0; k < count; ++k) {
    const double x = -1.9 + 0.19 * k;
    z0.regions.push_back(world_region(100 + k, z0, axis_rect(2, 0.0, x, x + 0.15, -1.0, 1.0)));
  }
  set.slices = {z0, axis_slice(0, 0.33)};
  const BuiltField field(set, kBox);
  ASSERT_EQ(field.field().function_count(), count + 1);
  for (int k = 0; k < count; ++k) {
    const Vec3 p(-1.9 + 0.19 * k + 0.075, 0.2, 1e-6);
    const std::vector<double> f = field(p);
    expect_valid(f, p);
    EXPECT_EQ(std::max_element(f.begin(), f.end()) - f.begin(), k + 1) << k;
    EXPECT_NEAR(f[static_cast<std::size_t>(k) + 1], 1.0, 1e-4) << k;
    EXPECT_EQ(field(Vec3(p.x(), p.y(), 0.0))[static_cast<std::size_t>(k) + 1], 1.0) << k;
  }
}

TEST(FieldLabels, PrepareSlicesOrientsRingsAndMapsIds) {
  SliceSet set;
  LabeledSlice s = axis_slice(2, 0.0);
  Region r;
  r.label = 7;
  r.outer = {Vec2(0, 0), Vec2(0, 2), Vec2(2, 2), Vec2(2, 0)};                    // clockwise
  r.holes = {{Vec2(0.5, 0.5), Vec2(1.5, 0.5), Vec2(1.5, 1.5), Vec2(0.5, 1.5)}};  // ccw
  s.regions.push_back(r);
  set.slices.push_back(s);
  const std::vector<PreparedSlice> prepared = prepare_slices(set, {3, 7}, kBox);
  ASSERT_EQ(prepared.size(), 1u);
  ASSERT_EQ(prepared[0].rings_by_material.size(), 3u);
  EXPECT_TRUE(prepared[0].rings_by_material[1].empty());
  ASSERT_EQ(prepared[0].rings_by_material[2].size(), 2u);
  EXPECT_GT(signed_area(prepared[0].rings_by_material[2][0]), 0.0);
  EXPECT_LT(signed_area(prepared[0].rings_by_material[2][1]), 0.0);
  EXPECT_TRUE(prepared[0].unit_normal.isApprox(Vec3::UnitZ()));
  EXPECT_THROW(prepare_slices(set, {3}, kBox), GeometryError);  // 7 is not a material
  // An unknown region becomes the slice's unknown set: no material left, one component whose
  // hole borders the outside.
  set.slices[0].regions[0].label = kUnknownLabel;
  const std::vector<PreparedSlice> unknown = prepare_slices(set, {3, 7}, kBox);
  EXPECT_TRUE(unknown[0].rings_by_material[2].empty());
  ASSERT_EQ(unknown[0].unknown.size(), 1u);
  ASSERT_EQ(unknown[0].unknown[0].rings.size(), 2u);
  for (const auto& labels : unknown[0].unknown[0].edge_labels)
    for (int label : labels) EXPECT_EQ(label, 0);
}

// ---------------------------------------------------------------------------------------------
// Degenerate arrangements.

void expect_valid_everywhere(const BuiltField& field, std::uint64_t seed,
                             const std::vector<Vec3>& special = {}) {
  std::mt19937_64 rng(seed);
  std::vector<Vec3> points = special;
  for (int k = 0; k < 400; ++k) points.push_back(random_point(rng, -1.999, 1.999));
  // Points very near the planes through the origin (the degenerate features here).
  std::uniform_real_distribution<double> tiny(-1e-9, 1e-9);
  for (int k = 0; k < 200; ++k) {
    Vec3 p = random_point(rng, -1.5, 1.5);
    p[static_cast<int>(rng() % 3)] = tiny(rng);
    if (k % 2 == 0) p[static_cast<int>(rng() % 3)] = tiny(rng);
    points.push_back(p);
  }
  for (const Vec3& p : points) expect_valid(field(p), p);
}

TEST(FieldDegenerate, DuplicatePlanesAreRejected) {
  Arrangement arr(kBox);
  arr.insert_plane(Vec3(0, 0, 1), -0.5, 0);
  EXPECT_THROW(arr.insert_plane(Vec3(0, 0, 1), -0.5, 1), GeometryError);
  EXPECT_THROW(arr.insert_plane(Vec3(0, 0, -1), 0.5, 1), GeometryError);  // flipped frame
  EXPECT_THROW(arr.insert_plane(Vec3(0, 0, 2), -1.0, 1), GeometryError);  // scaled
  EXPECT_THROW(arr.insert_plane(Vec3(0, 0, -3), 1.5, 1), GeometryError);
  // Through the slice-set path: the same plane given by two different frames.
  SliceSet set;
  set.bounds = kBox;
  set.slices = {axis_slice(2, 0.25, 0), axis_slice(2, 0.25, 0)};
  std::swap(set.slices[1].u, set.slices[1].v);
  set.slices[1].origin_mm += Vec3(0.5, -0.25, 0.0);
  EXPECT_THROW({ const BuiltField built(set, kBox); }, GeometryError);
}

TEST(FieldDegenerate, ThreeSlicesThroughOneLine) {
  SliceSet set;
  set.bounds = kBox;
  LabeledSlice z0 = axis_slice(2, 0.0), x0 = axis_slice(0, 0.0), diagonal;
  diagonal.origin_mm = Vec3::Zero();
  diagonal.u = Vec3(1.0, 0.0, -1.0) / std::sqrt(2.0);
  diagonal.v = Vec3::UnitY();  // normal (1, 0, 1) / sqrt(2): contains the y axis like the others
  z0.regions.push_back(world_region(1, z0, axis_rect(2, 0.0, -1.0, 1.0, -1.0, 1.0)));
  x0.regions.push_back(world_region(1, x0, axis_rect(0, 0.0, -1.0, 1.0, -1.0, 1.0)));
  diagonal.regions.push_back(
      world_region(1, diagonal,
                   {diagonal.to_world(Vec2(-1, -1)), diagonal.to_world(Vec2(1, -1)),
                    diagonal.to_world(Vec2(1, 1)), diagonal.to_world(Vec2(-1, 1))}));
  set.slices = {z0, x0, diagonal};
  const BuiltField field(set, kBox);
  EXPECT_EQ(field.arrangement().cell_count(), 6u);
  expect_valid_everywhere(field, 41, {Vec3(0, 0.3, 0), Vec3(1e-12, 0.3, -1e-12)});
  // Near the common line, between two labelled planes, the label holds.
  EXPECT_GT(field(Vec3(1e-6, 0.3, 1e-7))[1], 0.9);
}

TEST(FieldDegenerate, ContourVertexAndEdgeOnAnIntersectionLine) {
  // Slice x = 0 cuts z = 0 along the y axis; one region has its corner on that line, another
  // an edge along it. The x < 0 face gets only zero-area slivers of them.
  SliceSet set;
  set.bounds = kBox;
  LabeledSlice z0 = axis_slice(2, 0.0), x0 = axis_slice(0, 0.0);
  z0.regions.push_back(world_region(
      1, z0,
      {Vec3(0.0, 0.2, 0.0), Vec3(0.7, -0.5, 0.0), Vec3(1.4, 0.2, 0.0), Vec3(0.7, 0.9, 0.0)}));
  z0.regions.push_back(world_region(1, z0, axis_rect(2, 0.0, 0.0, 1.0, -1.5, -0.8)));
  set.slices = {z0, x0};
  const BuiltField field(set, kBox);
  expect_valid_everywhere(field, 43, {Vec3(0.0, 0.2, 0.0), Vec3(0.0, -1.0, 0.0)});
  const double h = 1e-9 * kSize;
  EXPECT_NEAR(field(Vec3(0.5, -1.1, h))[1], 1.0, 1e-6);    // in the edge-on region
  EXPECT_NEAR(field(Vec3(-0.5, -1.1, h))[1], -1.0, 1e-6);  // across the line: outside
  EXPECT_NEAR(field(Vec3(-1e-3, -1.1, h))[1], -1.0, 1e-3);
  EXPECT_NEAR(field(Vec3(1e-3, -1.1, h))[1], 1.0, 1e-3);
  EXPECT_NEAR(field(Vec3(-1e-3, 0.2, h))[1], -1.0, 1e-3);  // next to the touching corner
  EXPECT_NEAR(field(Vec3(0.7, 0.2, h))[1], 1.0, 1e-6);
  // On the x = 0 slice (no region) above the touching corner: that face's indicator, although
  // the z = 0 face next to it has already weighed the corner.
  EXPECT_EQ(field(Vec3(0.0, 0.2, h))[1], -1.0);
}

TEST(FieldDegenerate, SliceWithoutRegions) {
  SliceSet set;
  set.bounds = kBox;
  set.labels = {{1, "inside"}};
  LabeledSlice z0 = axis_slice(2, 0.0), empty = axis_slice(0, 0.3), empty2 = oblique_slice();
  z0.regions.push_back(world_region(1, z0, axis_rect(2, 0.0, -1.0, 1.0, -1.0, 1.0)));
  set.slices = {z0, empty, empty2};
  const BuiltField field(set, kBox);
  expect_valid_everywhere(field, 47);
  EXPECT_NEAR(field(Vec3(0.3 + 1e-9, 0.5, 0.5))[0], 1.0, 1e-6);
  // Only empty slices: the outside label everywhere.
  SliceSet none;
  none.bounds = kBox;
  none.labels = {{1, "inside"}};
  none.slices = {empty, empty2};
  const BuiltField outside(none, kBox);
  std::mt19937_64 rng(3);
  for (int k = 0; k < 100; ++k) {
    const std::vector<double> f = outside(random_point(rng, -1.999, 1.999));
    EXPECT_EQ(f[0], 1.0);
    EXPECT_EQ(f[1], -1.0);
  }
}

}  // namespace
}  // namespace sonoshape::recon::field_test
