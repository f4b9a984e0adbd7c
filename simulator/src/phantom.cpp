#include "sonoshape/simulator/phantom.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <set>
#include <stdexcept>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/mesh_io.hpp"

namespace sonoshape::simulator {

Tissue tissue_preset(const std::string& name) {
  // Impedances and attenuations: textbook soft-tissue values (Szabo, Diagnostic Ultrasound
  // Imaging); echogenicities chosen for clearly separable grey levels.
  if (name == "background") return {"background", 1.0, 1.54, 0.5};
  if (name == "hypoechoic") return {"hypoechoic", 0.3, 1.60, 0.5};
  if (name == "hyperechoic") return {"hyperechoic", 3.0, 1.68, 0.6};
  if (name == "isoechoic") return {"isoechoic", 1.0, 1.62, 0.5};
  if (name == "cyst") return {"cyst", 0.02, 1.52, 0.05};
  if (name == "bone") return {"bone", 1.5, 7.8, 20.0};
  throw std::invalid_argument("unknown tissue preset '" + name +
                              "' (use background, hypoechoic, hyperechoic, isoechoic, cyst, bone)");
}

Tissue default_tissue(int label) {
  if (label == 1) return tissue_preset("hypoechoic");
  if (label == 2) return tissue_preset("hyperechoic");
  Tissue t = tissue_preset(label % 2 == 1 ? "hypoechoic" : "hyperechoic");
  // Spread further labels over distinct brightness steps (about 3 dB apart).
  t.echogenicity *= std::pow(1.4, ((label - 1) / 2) % 3) * (label % 2 == 1 ? 1.0 : 0.7);
  return t;
}

void Phantom::add(int label, std::string name, const TriangleMesh& mesh,
                  const Eigen::Affine3d& T_reference_mesh) {
  if (label < 1 || label > kMaxPixelLabel)
    throw GeometryError("phantom: label " + std::to_string(label) + " is outside 1.." +
                        std::to_string(kMaxPixelLabel) + " (label images are 8-bit)");
  LabeledMesh placed{label, std::move(name), mesh};
  for (Vec3& p : placed.mesh.vertices) p = T_reference_mesh * p;
  // A mirroring placement turns the mesh inside out.
  if (T_reference_mesh.linear().determinant() < 0.0)
    for (auto& t : placed.mesh.triangles) std::swap(t[1], t[2]);
  meshes.push_back(std::move(placed));
}

void Phantom::add(int label, std::string name, const TriangleMesh& mesh,
                  const Eigen::Affine3d& T_reference_mesh, const Tissue& tissue) {
  add(label, std::move(name), mesh, T_reference_mesh);
  tissues[label] = tissue;
}

Tissue Phantom::tissue(int label) const {
  if (const auto it = tissues.find(label); it != tissues.end()) return it->second;
  return default_tissue(label);
}

std::vector<int> Phantom::labels() const {
  std::set<int> labels;
  for (const auto& m : meshes) labels.insert(m.label);
  return {labels.begin(), labels.end()};
}

Box3 Phantom::bounds() const {
  if (meshes.empty()) throw GeometryError("phantom: no meshes");
  Box3 box{Vec3::Constant(std::numeric_limits<double>::infinity()),
           Vec3::Constant(-std::numeric_limits<double>::infinity())};
  for (const auto& m : meshes)
    for (const Vec3& p : m.mesh.vertices) {
      box.min = box.min.cwiseMin(p);
      box.max = box.max.cwiseMax(p);
    }
  return box;
}

MeshSet Phantom::mesh_set() const {
  MeshSet set;
  for (const int label : labels()) {
    MeshSet::Entry entry;
    entry.label = label;
    for (const auto& m : meshes) {
      if (m.label != label) continue;
      if (entry.name.empty()) entry.name = m.name;
      const auto offset = static_cast<std::uint32_t>(entry.mesh.vertices.size());
      entry.mesh.vertices.insert(entry.mesh.vertices.end(), m.mesh.vertices.begin(),
                                 m.mesh.vertices.end());
      for (const auto& t : m.mesh.triangles)
        entry.mesh.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
    }
    set.meshes.push_back(std::move(entry));
  }
  return set;
}

Eigen::Affine3d fit_to_size(const std::vector<TriangleMesh>& meshes, double size_mm) {
  Box3 box{Vec3::Constant(std::numeric_limits<double>::infinity()),
           Vec3::Constant(-std::numeric_limits<double>::infinity())};
  for (const auto& mesh : meshes)
    for (const Vec3& p : mesh.vertices) {
      box.min = box.min.cwiseMin(p);
      box.max = box.max.cwiseMax(p);
    }
  if (!(box.diagonal() > 0.0) || !(size_mm > 0.0))
    throw GeometryError("fit_to_size: empty meshes or non-positive size");
  const double scale = size_mm / box.diagonal();
  Eigen::Affine3d T = Eigen::Affine3d::Identity();
  T.linear() *= scale;
  T.translation() = -scale * 0.5 * (box.min + box.max);
  return T;
}

Result<Phantom> make_default_phantom(const std::filesystem::path& models_dir, double size_mm) {
  auto spot = read_mesh(models_dir / "spot.obj");
  if (!spot) return spot.status();
  auto small = read_mesh(models_dir / "cheburashka.obj");
  if (!small) return small.status();
  orient_outward(*spot);
  orient_outward(*small);
  // Unit-size layout first: spot upside down (its back towards the probe, y points into the
  // body), the small organ beside it at 40% of spot's size with a gap, turned so its longest
  // side runs along z and many frames of a sweep cut it.
  for (Vec3& p : small->vertices) p = Vec3(p.z(), p.y(), -p.x());
  orient_outward(*small);
  const Box3 spot_box = spot->bounds(), small_box = small->bounds();
  Eigen::Affine3d spot_place = Eigen::Affine3d::Identity();
  spot_place.rotate(Eigen::AngleAxisd(std::numbers::pi, Vec3::UnitZ()));
  spot_place.scale(1.0 / spot_box.diagonal());
  spot_place.translate(-0.5 * (spot_box.min + spot_box.max));
  const double small_scale = 0.4 / small_box.diagonal();
  Eigen::Affine3d small_place = Eigen::Affine3d::Identity();
  small_place.translate(Vec3(0.5 * spot_box.size().x() / spot_box.diagonal() +
                                 0.5 * small_scale * small_box.size().x() + 0.04,
                             0.1, 0.0));
  small_place.scale(small_scale);
  small_place.translate(-0.5 * (small_box.min + small_box.max));
  TriangleMesh placed_spot = *spot, placed_small = *small;
  for (Vec3& p : placed_spot.vertices) p = spot_place * p;
  for (Vec3& p : placed_small.vertices) p = small_place * p;
  const Eigen::Affine3d fit = fit_to_size({placed_spot, placed_small}, size_mm);
  Phantom phantom;
  phantom.add(1, "spot", placed_spot, fit, tissue_preset("hypoechoic"));
  phantom.add(2, "cheburashka", placed_small, fit, tissue_preset("hyperechoic"));
  // The rib: above spot, off its centre line, as long as the organs (a sweep over the organs
  // then stays over the phantom).
  const Box3 organs = phantom.bounds();
  const Box3 spot_mm = phantom.meshes[0].mesh.bounds();
  const double rib_radius = 0.04 * size_mm;
  Eigen::Affine3d rib = Eigen::Affine3d::Identity();
  rib.translation() =
      Vec3(spot_mm.min.x() + 0.35 * spot_mm.size().x(), organs.min.y() - 2.0 * rib_radius,
           0.5 * (organs.min.z() + organs.max.z()));
  phantom.add(3, "rib", make_cylinder(rib_radius, organs.size().z()), rib, tissue_preset("bone"));
  return phantom;
}

TriangleMesh make_cylinder(double radius_mm, double length_mm, int segments) {
  TriangleMesh mesh;
  const double h = 0.5 * length_mm;
  for (int s = 0; s < segments; ++s) {
    const double a = 2.0 * std::numbers::pi * s / segments;
    mesh.vertices.emplace_back(radius_mm * std::cos(a), radius_mm * std::sin(a), -h);
    mesh.vertices.emplace_back(radius_mm * std::cos(a), radius_mm * std::sin(a), h);
  }
  const auto bottom = static_cast<std::uint32_t>(mesh.vertices.size());
  mesh.vertices.emplace_back(0.0, 0.0, -h);
  mesh.vertices.emplace_back(0.0, 0.0, h);
  const std::uint32_t top = bottom + 1;
  for (int s = 0; s < segments; ++s) {
    const auto b0 = static_cast<std::uint32_t>(2 * s), t0 = b0 + 1;
    const auto b1 = static_cast<std::uint32_t>(2 * ((s + 1) % segments)), t1 = b1 + 1;
    mesh.triangles.push_back({b0, b1, t1});
    mesh.triangles.push_back({b0, t1, t0});
    mesh.triangles.push_back({bottom, b1, b0});
    mesh.triangles.push_back({top, t0, t1});
  }
  return mesh;
}

TriangleMesh make_sphere(double radius_mm, int segments, int rings) {
  TriangleMesh mesh;
  mesh.vertices.emplace_back(0.0, 0.0, radius_mm);
  for (int r = 1; r < rings; ++r) {
    const double theta = std::numbers::pi * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2.0 * std::numbers::pi * s / segments;
      mesh.vertices.push_back(radius_mm * Vec3(std::sin(theta) * std::cos(phi),
                                               std::sin(theta) * std::sin(phi), std::cos(theta)));
    }
  }
  mesh.vertices.emplace_back(0.0, 0.0, -radius_mm);
  const auto south = static_cast<std::uint32_t>(mesh.vertices.size() - 1);
  auto at = [&](int r, int s) {
    return static_cast<std::uint32_t>(1 + (r - 1) * segments + (s % segments));
  };
  for (int s = 0; s < segments; ++s) mesh.triangles.push_back({0, at(1, s), at(1, s + 1)});
  for (int r = 1; r + 1 < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      mesh.triangles.push_back({at(r, s), at(r + 1, s), at(r + 1, s + 1)});
      mesh.triangles.push_back({at(r, s), at(r + 1, s + 1), at(r, s + 1)});
    }
  for (int s = 0; s < segments; ++s)
    mesh.triangles.push_back({at(rings - 1, s), south, at(rings - 1, s + 1)});
  return mesh;
}

}  // namespace sonoshape::simulator
