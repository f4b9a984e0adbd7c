#include "sonoshape/simulator/plane_generator.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

#include "sonoshape/core/errors.hpp"

namespace sonoshape::simulator {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;
// Offsets in units of the plane spacing that keep planes off the box centre and its corners.
constexpr double kSpacingOffset = 0.0137;
constexpr double kSpacingJitter = 0.02;

// The plane frame of axis `k` (u x v = e_k), turned by `rotation`.
SlicePlane axis_plane(int k, const Eigen::Matrix3d& rotation, const Vec3& origin) {
  const Vec3 axes[3] = {Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ()};
  SlicePlane plane;
  plane.origin_mm = origin;
  plane.u = rotation * axes[(k + 1) % 3];
  plane.v = rotation * axes[(k + 2) % 3];
  return plane;
}

// Orthonormal u, v with u x v = normal, turned by `angle` about the normal.
SlicePlane normal_plane(const Vec3& normal, double angle, const Vec3& origin) {
  const Vec3 n = normal.normalized();
  Vec3 reference = Vec3::UnitX();
  if (std::abs(n.x()) > 0.9) reference = Vec3::UnitY();
  const Vec3 u0 = reference.cross(n).normalized();
  const Eigen::AngleAxisd spin(angle, n);
  SlicePlane plane;
  plane.origin_mm = origin;
  plane.u = (spin * u0).normalized();
  plane.v = n.cross(plane.u).normalized();
  return plane;
}

// `count` evenly spaced offsets strictly inside [lo, hi], nudged off symmetric positions.
std::vector<double> spaced(double lo, double hi, int count, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> jitter(-kSpacingJitter, kSpacingJitter);
  const double spacing = (hi - lo) / (count + 1);
  std::vector<double> offsets;
  for (int i = 0; i < count; ++i)
    offsets.push_back(lo + (i + 1 + kSpacingOffset + jitter(rng)) * spacing);
  return offsets;
}

}  // namespace

PlaneFamily parse_plane_family(const std::string& name) {
  if (name == "parallel") return PlaneFamily::kParallel;
  if (name == "orthogonal") return PlaneFamily::kOrthogonal;
  if (name == "random") return PlaneFamily::kRandom;
  if (name == "sweep") return PlaneFamily::kSweep;
  throw std::invalid_argument("unknown plane family '" + name +
                              "' (use parallel, orthogonal, random or sweep)");
}

namespace {

// Slightly tilted z, like a stack that is not quite aligned with the scanner axes.
std::vector<SlicePlane> parallel_planes(int count, const Box3& box, std::mt19937_64& rng) {
  const Vec3 centre = 0.5 * (box.min + box.max);
  const Eigen::Matrix3d tilt = (Eigen::AngleAxisd(3.0 * kDegree, Vec3::UnitX()) *
                                Eigen::AngleAxisd(2.0 * kDegree, Vec3::UnitY()))
                                   .toRotationMatrix();
  const Vec3 n = tilt * Vec3::UnitZ();
  // The z extent around the centre, so that even the end planes cut through the middle of the
  // object rather than grazing a corner.
  const double middle = centre.dot(n);
  const double half = 0.5 * box.size().z();
  std::vector<SlicePlane> planes;
  for (double offset : spaced(middle - half, middle + half, count, rng))
    planes.push_back(axis_plane(2, tilt, centre + (offset - centre.dot(n)) * n));
  return planes;
}

// A third of the planes normal to each axis.
std::vector<SlicePlane> orthogonal_planes(int count, const Box3& box, std::mt19937_64& rng) {
  const Vec3 centre = 0.5 * (box.min + box.max);
  std::vector<SlicePlane> planes;
  for (int k = 0; k < 3; ++k) {
    const int axis_count = count / 3 + (k < count % 3 ? 1 : 0);
    for (double offset : spaced(box.min[k], box.max[k], axis_count, rng)) {
      Vec3 origin = centre;
      origin[k] = offset;
      planes.push_back(axis_plane(k, Eigen::Matrix3d::Identity(), origin));
    }
  }
  return planes;
}

// Uniformly random normals, through points in the middle 80 % of the box.
std::vector<SlicePlane> random_planes(int count, const Box3& box, std::mt19937_64& rng) {
  const Vec3 size = box.size();
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::vector<SlicePlane> planes;
  for (int i = 0; i < count; ++i) {
    Vec3 n;
    do n = Vec3(gauss(rng), gauss(rng), gauss(rng));
    while (n.norm() < 1e-6);
    Vec3 origin;
    for (int k = 0; k < 3; ++k) origin[k] = box.min[k] + (0.1 + 0.8 * unit(rng)) * size[k];
    planes.push_back(normal_plane(n, 2.0 * std::numbers::pi * unit(rng), origin));
  }
  return planes;
}

// A probe moved along the longest axis, rocking slowly (up to ~20 degrees) with a small hand
// tremor, like a freehand ultrasound sweep.
std::vector<SlicePlane> sweep_planes(int count, const Box3& box, std::mt19937_64& rng) {
  const Vec3 size = box.size();
  const Vec3 centre = 0.5 * (box.min + box.max);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int k = 0;
  size.maxCoeff(&k);
  const int k1 = (k + 1) % 3;
  const int k2 = (k + 2) % 3;
  const Vec3 axes[3] = {Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ()};
  const double phase1 = 2.0 * std::numbers::pi * unit(rng);
  const double phase2 = 2.0 * std::numbers::pi * unit(rng);
  std::uniform_real_distribution<double> tremor(-1.0, 1.0);
  const double spacing = 0.8 * size[k] / count;
  std::vector<SlicePlane> planes;
  for (int i = 0; i < count; ++i) {
    const double t = (i + 0.5) / count;
    const double tilt1 =
        (12.0 * std::sin(2.0 * std::numbers::pi * 0.7 * t + phase1) + tremor(rng)) * kDegree;
    const double tilt2 =
        (12.0 * std::sin(2.0 * std::numbers::pi * 0.45 * t + phase2) + tremor(rng)) * kDegree;
    const Eigen::Matrix3d rotation =
        (Eigen::AngleAxisd(tilt1, axes[k1]) * Eigen::AngleAxisd(tilt2, axes[k2]))
            .toRotationMatrix();
    Vec3 origin = centre;
    origin[k] =
        box.min[k] + (0.1 + 0.8 * t) * size[k] + (kSpacingOffset + 0.1 * tremor(rng)) * spacing;
    origin[k1] +=
        0.03 * size[k1] * std::sin(2.0 * std::numbers::pi * t + phase2) + kSpacingOffset * size[k1];
    origin[k2] +=
        0.03 * size[k2] * std::cos(2.0 * std::numbers::pi * t + phase1) + kSpacingOffset * size[k2];
    planes.push_back(axis_plane(k, rotation, origin));
  }
  return planes;
}

}  // namespace

std::vector<SlicePlane> generate_planes(PlaneFamily family, int count, const Box3& object_box,
                                        std::uint64_t seed) {
  if (count <= 0) return {};
  const Vec3 size = object_box.size();
  if (!size.allFinite() || (size.array() <= 0.0).any())
    throw GeometryError("generate_planes: the object box must have a positive size on every axis");
  std::mt19937_64 rng(seed);
  switch (family) {
    case PlaneFamily::kParallel:
      return parallel_planes(count, object_box, rng);
    case PlaneFamily::kOrthogonal:
      return orthogonal_planes(count, object_box, rng);
    case PlaneFamily::kRandom:
      return random_planes(count, object_box, rng);
    case PlaneFamily::kSweep:
      return sweep_planes(count, object_box, rng);
  }
  return {};
}

}  // namespace sonoshape::simulator
