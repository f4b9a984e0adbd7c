#pragma once
// A virtual patient: labelled closed meshes in the reference frame (mm) with the acoustic
// properties of each tissue and of the background. Organs may lie inside other organs (the
// slicer nests them); they must not cross each other.
#include <Eigen/Geometry>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/mesh_slicer.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::simulator {

/// Acoustic properties of a tissue, as the B-mode synthesis uses them.
struct Tissue {
  std::string name = "soft tissue";
  /// Mean backscatter amplitude relative to the default background (1): 0.3 reads about 10 dB
  /// darker (hypoechoic), 3 about 10 dB brighter (hyperechoic), 0 anechoic (fluid).
  double echogenicity = 1.0;
  /// Acoustic impedance (MRayl): boundaries reflect ((Z2 - Z1) / (Z2 + Z1)) of the amplitude,
  /// so bone (7.8) against soft tissue (1.6) is a strong reflector that shadows what lies behind.
  double impedance_mrayl = 1.6;
  /// Attenuation (dB per cm per MHz, one way): soft tissue about 0.5, bone about 20.
  double attenuation_db_per_cm_mhz = 0.5;
};

/// Presets: "background", "hypoechoic", "hyperechoic", "isoechoic", "cyst", "bone".
/// Throws std::invalid_argument for other names.
Tissue tissue_preset(const std::string& name);
/// The tissue a label gets when none is given: label 1 hypoechoic, 2 hyperechoic, then
/// alternating with slightly different brightness so neighbouring labels stay distinguishable.
Tissue default_tissue(int label);

/// Labelled closed meshes placed in the reference frame, with their tissues.
struct Phantom {
  std::vector<LabeledMesh> meshes;  ///< reference frame, mm, outward-oriented
  std::map<int, Tissue> tissues;    ///< by label; labels without an entry use default_tissue
  Tissue background = tissue_preset("background");

  /// Adds `mesh` (in its own coordinates) placed by T_reference_mesh (a similarity: scale and
  /// rigid motion); the second form also sets the tissue of the label. Throws GeometryError for
  /// labels outside 1..254 (label images are 8-bit).
  void add(int label, std::string name, const TriangleMesh& mesh,
           const Eigen::Affine3d& T_reference_mesh = Eigen::Affine3d::Identity());
  void add(int label, std::string name, const TriangleMesh& mesh,
           const Eigen::Affine3d& T_reference_mesh, const Tissue& tissue);

  /// The tissue of a label (tissues[label], else default_tissue(label)).
  Tissue tissue(int label) const;
  /// Sorted distinct labels of the meshes.
  std::vector<int> labels() const;
  /// The box of all mesh vertices; throws GeometryError when the phantom is empty.
  Box3 bounds() const;
  /// One mesh per label (meshes sharing a label merged), for `--truth` and `evaluate`.
  MeshSet mesh_set() const;
};

/// Scales meshes by one common factor (keeping nested meshes nested) so that the diagonal of
/// their union box is `size_mm`, centred at the origin: the transform to pass to Phantom::add.
Eigen::Affine3d fit_to_size(const std::vector<TriangleMesh>& meshes, double size_mm);

/// The built-in demo patient: `spot.obj` (label 1, hypoechoic) and a smaller
/// `cheburashka.obj` beside it (label 2, hyperechoic), scaled together so the diagonal of their
/// box is `size_mm` and centred at the origin, with a rib (label 3, bone) along z above spot
/// that shadows part of it. Reference axes: x across, y down into the body (the probe looks
/// along +y from above, y < bounds.min.y), z along the body. Fails when a model cannot be read.
Result<Phantom> make_default_phantom(const std::filesystem::path& models_dir,
                                     double size_mm = 120.0);

/// A closed cylinder (a rib, a vessel) along z from -length/2 to length/2, outward-oriented.
TriangleMesh make_cylinder(double radius_mm, double length_mm, int segments = 48);
/// A closed UV sphere centred at the origin, outward-oriented.
TriangleMesh make_sphere(double radius_mm, int segments = 64, int rings = 32);

}  // namespace sonoshape::simulator
