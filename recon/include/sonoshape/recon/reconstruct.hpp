#pragma once
// Offline reconstruction of closed surfaces from labelled cross-sections (Bermano, Vaxman &
// Gotsman 2011): arrangement of the slice planes, mean-value interpolation of each label's
// indicator inside every convex cell, argmax over labels, octree sampling with bi-Laplacian
// smoothing, and one closed manifold mesh per material.
#include <cstddef>
#include <map>
#include <optional>
#include <string>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::recon {

/// Which interpolant fills the space between the slices.
enum class FieldKind {
  /// The paper's: a mean-value blend of each label's +-1 indicator inside every arrangement cell.
  mean_value,
  /// A biharmonic (thin-plate) fill of each label's in-plane signed distance, solved on a grid
  /// over the box (docs/engine.md): keeps thin structures crossed by far-apart slices whole.
  thin_plate,
};

/// "mean-value" / "thin-plate".
const char* field_name(FieldKind field);
/// The field named `name` ("mean-value" or "thin-plate"); none for any other name.
std::optional<FieldKind> parse_field_name(const std::string& name);

/// The mean-value field's default bi-Laplacian smoothing iterations.
inline constexpr int kMeanValueSmoothing = 8;

struct ReconstructionOptions {
  FieldKind field = FieldKind::mean_value;  ///< the interpolant (the others are ignored by it
                                            ///< where they say so)
  int max_depth = -1;  ///< octree depth; -1: finest cells about 1/128 of the diagonal
  /// Bi-Laplacian smoothing iterations of the octree's samples (0: off); -1: the field's own
  /// default, kMeanValueSmoothing for mean-value and 0 for thin-plate (that field already
  /// minimises the bi-Laplacian energy, and smoothing its samples moves no IoU by 0.002 on the
  /// field table while costing about a seventh of an online update).
  int smoothing_iterations = -1;
  int threads = 0;  ///< threads for every stage; 0: all cores
  /// Where the field is evaluated: "cpu" (native), "opencl" (the first fp64 OpenCL device, a GPU
  /// if any), "opencl:PLATFORM:DEVICE", "auto" (an fp64 GPU if present, else cpu). The values
  /// agree to 1e-9 (the kernels repeat the CPU's rounding). Errors: sonoshape::Error.
  /// The thin-plate field runs on the CPU whatever this says.
  std::string device = "cpu";
  /// Build the arrangement's cells and face images only where the field is evaluated (issue
  /// 24): the cost follows the surface instead of the cube of the slice count, with the same
  /// field. An update's new plane reopens only the built cells it crosses (their values are
  /// evaluated again in the cells they split into); the others keep their cells, faces, images
  /// and values. With unknown regions or fields of view, the cells that meet the unknown sets
  /// are built first, every update (the completion reads the faces around them); with a sector
  /// on every slice that is nearly the whole arrangement. false: the whole arrangement, built
  /// plane by plane (the reference the invariant tests compare with; `reconstruct
  /// --whole-arrangement`).
  bool cells_on_demand = true;
  /// Thin-plate field: a small organ in a large volume is solved on a grid of its own at the
  /// octree's finest cell (docs/engine.md, section 8). An organ that grows in a sweep outgrows
  /// it every few millimetres (a rebuild of that grid, up to a few hundred milliseconds), so a
  /// live scan's updates leave it off (their meshes are previews) and its settled meshes have
  /// it. false: every organ on the one grid over the box (`reconstruct --one-grid`).
  bool own_grids = true;
};

/// Per-stage wall time in seconds and counts of one reconstruction.
/// With cells built on demand (reconstruct()), the cells and images are built when the octree
/// first evaluates a point in them: arrangement_s and face_images_s are then parts of field_s and
/// smoothing_s, and `cells` / `faces` count those built.
struct ReconstructionStats {
  double arrangement_s = 0, face_images_s = 0, field_s = 0, smoothing_s = 0, mesh_s = 0,
         total_s = 0;
  std::size_t slices = 0, cells = 0, faces = 0, field_evaluations = 0;
  std::size_t snapped_vertices = 0;  ///< grid vertices given a thin region's label
  std::size_t unknown_triangles = 0, cell_groups = 0;  ///< unknown-region completion
  std::size_t completed_slices = 0;  ///< slices whose unknown regions were (re)completed
  double completion_s = 0;           ///< part of face_images_s spent completing unknown regions
  /// Part of arrangement_s (cells on demand) outside the parallel refinement and placement of
  /// regions: grouping the points by region, numbering, and sharing the new faces (link).
  double arrangement_serial_s = 0;
  /// Thin-plate field: seconds of the new slices' data and of the solve, conjugate-gradient
  /// iterations (summed over materials) and the solve grid's nodes.
  double data_s = 0, solve_s = 0;
  std::size_t solve_iterations = 0, solve_nodes = 0;
  /// Part of field_s and smoothing_s spent evaluating the field at grid vertices (the rest: the
  /// octree, band and smoothing passes).
  double evaluation_s = 0;
  int depth = 0;
  std::map<int, std::size_t> triangles;  ///< per material label
};

/// Reconstructs one closed, manifold, outward-oriented mesh per material of `slices`.
/// Unknown regions and fields of view are completed from the known data (Section 5).
/// Throws GeometryError for inputs the engine cannot use (coincident slices that disagree, ...).
MeshSet reconstruct(const SliceSet& slices, const ReconstructionOptions& options = {},
                    ReconstructionStats* stats = nullptr);

}  // namespace sonoshape::recon
