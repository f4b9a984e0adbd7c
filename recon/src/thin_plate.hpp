#pragma once
// The thin-plate field (issue 38), beside the paper's mean-value field: per material, the slices'
// in-plane signed distance to that material's true boundaries (truncated, and tightened by the
// bounds that the other slices give on the distance to the surface) as data where each
// plane crosses the grid's edges, and a biharmonic fill of the space between planes that
// minimises sum (L f)^2 + sum w (f(sample) - d)^2 on a regular grid over the box (L: the 7-point
// graph Laplacian, f(sample) the linear interpolation along the crossed edge).
// A slice's signed distance is constant along its extrusion, and a biharmonic fill keeps that
// detail between planes where a harmonic (mean-value) blend of a +-1 indicator sags into beads.
// Where the slices say nothing, weak priors: the outside at the box's faces (the closing), or,
// along an axis the slices do not sample (nearly coplanar slices), their extrusion.
// Solved by conjugate gradients preconditioned with a geometric multigrid V-cycle (Chebyshev
// smoothing); an added slice changes only the data (its own, and those it tightens), and the next
// solve starts from the last solution.
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "cell_field.hpp"
#include "sonoshape/core/geometry.hpp"

namespace sonoshape::recon {

struct ThinPlateOptions {
  /// Each material's signed distances are clamped to +-this fraction of its extent (the
  /// diagonal of the box of its contours, rounded up by truncation_extent; at least two
  /// solve-grid spacings), so that far contours do not weigh in. Relative to the organ, not the
  /// box: a small organ in a large scan volume needs the same reach as a large one filling its box.
  double truncation = 0.1;
  /// Weight of a data sample (one per grid spacing squared of plane), relative to the
  /// bi-Laplacian's diagonal (42 inside the grid): large, so the field interpolates the data.
  double data_weight = 300.0;
  /// Weight of the closing condition (f = -truncation at and beyond the box's faces across the
  /// axes the slices sample): weak, it only decides where an object ends beyond its last slice.
  double closing_weight = 0.3;
  /// Weight of the extrusion prior: along an axis that the slices do not sample (their spread
  /// along it is less than the box's reach beyond them), the nodes beyond the slices are pulled
  /// towards the outermost slice's values on their line of nodes, so that an organ goes on as
  /// the slices' extrusion. About 1/14 of the bi-Laplacian's diagonal: a thin section a few
  /// grid cells across keeps most of its area over the box's padding (the rib of `rock-perfect`:
  /// 0.940 IoU with 3, 0.955 with 7, where 1 let it sag), while an organ whose sections shrink
  /// within the box (its cheburashka) still ends a little beyond the slices instead of going on
  /// as their full extrusion (0.310 with 3, 0.308 with 7; the baseline's 0.309): the weakest
  /// pull that keeps both at or above the nearest-slice baseline.
  double extrusion_weight = 3.0;
  /// The solve grid is the octree's finest grid coarsened this many times (0: the finest).
  int coarsening = 1;
  /// A small organ in a large volume gets a grid of its own at the octree's finest cell (see
  /// ThinPlateField's constructor from material boxes): the default scan's cheburashka, whose
  /// ears are 2 mm shells, is no longer solved on 1.6 mm cells of the whole scan volume.
  bool own_grids = true;
  /// Conjugate gradients stop when an iteration moves no grid value by more than this fraction
  /// of the grid spacing (the field is in mm of signed distance): a hundredth of a cell moves
  /// the surface by about that, far below what the grid resolves.
  double tolerance = 1e-2;
  /// An online update's solve (from the field's last solution) stops at this looser tolerance
  /// and tests only the nodes near each material's zero set (online_band): those are what the
  /// mesh reads, and a live update is a preview (a scan's final meshes are solved again at
  /// once). Its result agrees with a one-shot solve's to about this fraction of the grid
  /// spacing (docs/engine.md, section 8).
  double online_tolerance = 5e-2;
  /// The nodes an online update's stopping test looks at: those whose value, before or after
  /// an iteration, lies within this fraction of the material's truncation of zero (the field
  /// is a signed distance there). The rest converge more slowly but keep their sign.
  double online_band = 0.25;
  int max_iterations = 200;
  /// What evaluate() interpolates is the solution as last sampled, per block of 4^3 nodes: a
  /// block takes the solution again when one of its nodes moved by more than this fraction of
  /// the grid spacing since, so every node is within that of the solution and the interpolated
  /// values within 1.25^3 times that (the Catmull-Rom weights' absolute sum). An online engine
  /// samples again only the points that read a block that changed (changed_at). A quarter of
  /// the solver's tolerance: the blocks a solve changes are mostly those where the solution
  /// really moves, which a larger tolerance would not keep.
  double resample_tolerance = 2.5e-3;
  /// The solver's grid kernels in AVX2 where the CPU has it; false: the baseline x86-64 ones.
  /// The same bits either way (for tests that check it).
  bool simd = true;
  /// Per material 1..K (index m - 1; missing: false): it casts an acoustic shadow
  /// (LabelInfo::casts_shadow), so its edges along the slices' unknown regions are its true
  /// boundaries (where its labeller ended it), not bounds from below as for other materials.
  /// Edges along a field of view's edge stay where the slice stops seeing.
  std::vector<bool> shadow_casters;
};

/// What one solve did.
struct ThinPlateSolveStats {
  double solve_s = 0.0;   ///< conjugate gradients, every material
  int iterations = 0;     ///< summed over materials
  std::size_t nodes = 0;  ///< solve grid nodes
  /// Materials not solved again: their data added since the last solve lie within the online
  /// tolerance of the field, and nothing else changed.
  int unchanged_materials = 0;
};

/// The thin-plate field of K materials over a box. Not thread-safe; evaluate() may be called
/// concurrently once solve() returned.
class ThinPlateField {
 public:
  /// `finest_cell_mm`: the octree's finest cell size; the solve grid's spacing is that times
  /// 2^options.coarsening. `materials`: K (function 0 is the outside). `extents_mm`: per
  /// material, the extent the truncation is a fraction of (box_extents of material_boxes).
  /// Every material is solved on the one grid over `box`.
  ThinPlateField(const Box3& box, double finest_cell_mm, int materials, ThinPlateOptions options,
                 std::vector<double> extents_mm);
  /// The same, from each material's box (material_boxes; extents: their diagonals), with
  /// options.own_grids: a small material (own_grid_boxes says which) gets a grid of its own at
  /// the finest cell over its box, padded as a reconstruction box is and rounded out to 8
  /// finest cells. Beyond that box the material is outside (-truncation).
  ThinPlateField(const Box3& box, double finest_cell_mm, int materials, ThinPlateOptions options,
                 const std::vector<Box3>& material_boxes);
  ~ThinPlateField();
  ThinPlateField(ThinPlateField&&) noexcept;
  ThinPlateField& operator=(ThinPlateField&&) noexcept;

  /// Adds slices' data, computed in parallel and summed in slice order. The slices are kept
  /// (slices()).
  void add_slices(std::vector<PreparedSlice> slices);
  /// Starts the next solve from `other`'s solution when both have the same grid and materials
  /// (a rebuild: the data changed, the field mostly not), and keeps `other`'s sampled solution
  /// and generation, so that what `other` evaluated stays current where the solve moves
  /// nothing by more than the resample tolerance. Returns whether it did.
  bool start_from(const ThinPlateField& other);
  /// The materials' extents grew to `extents_mm` (same count): the data of every slice held
  /// become those computed with the new truncations (only the samples an old truncation clamped
  /// change), and the next solve starts from the last solution with its plateaus moved. False,
  /// and nothing changed, where a truncation would shrink (a rebuild's case).
  bool grow_extents(const std::vector<double>& extents_mm);
  /// The materials' boxes grew to `material_boxes` (same count; a field built from boxes):
  /// grow_extents with their diagonals, and a grid of its own whose box they change is built
  /// again over its new box from the slices held (the other grids go on). False, and nothing
  /// changed, where a truncation would shrink or another choice of own grids follows (a
  /// rebuild's case).
  bool grow_boxes(const std::vector<Box3>& material_boxes);
  /// Solves for every material from the last solution (-truncation at first), except, after
  /// this field's first solve, the materials whose added data the field fits to the solver's
  /// tolerance already (ThinPlateSolveStats::unchanged_materials).
  ThinPlateSolveStats solve();
  /// Values of the K + 1 functions at `points` (world mm), function_count() per point, in
  /// parallel: f_m interpolated from the solve grid's sampled solution (tricubic Catmull-Rom;
  /// see ThinPlateOptions::resample_tolerance), f_0 = -max_m f_m.
  void evaluate(const std::vector<Vec3>& points, double* values) const;
  /// The count of solves so far (1 after the first; start_from carries it on): a value that
  /// evaluate() gave after solve number `generation()` is still what it gives while
  /// changed_at(point) <= that number.
  std::uint32_t generation() const;
  /// The last solve that changed a node which evaluate(point) reads.
  std::uint32_t changed_at(const Vec3& point) const;
  int function_count() const;
  /// Per material: the extent the field was set up with (mm).
  const std::vector<double>& extents() const;
  const std::vector<PreparedSlice>& slices() const;
  /// Every slice's samples' values (materials per sample, slices in order) and positions
  /// (world mm) on the grid over the box: exposed for tests.
  std::vector<double> sample_values() const;
  std::vector<std::vector<Vec3>> sample_points() const;
  /// Node counts of the grid over the box.
  std::array<int, 3> node_counts() const;
  /// Per material: the box of its own grid (empty, min > max, where it is solved on the grid
  /// over the box).
  std::vector<Box3> own_boxes() const;

 private:
  struct Grid;  // one regular grid and the materials solved on it
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Per material, the box of the grid of its own that ThinPlateField gives it (empty where it
/// has none; see its constructor from material boxes): its box made a reconstruction box,
/// rounded out to multiples of 8 finest cells from `box.min` and cut to `box`, when its box's
/// diagonal spans fewer than 32 cells of the grid over `box`, that needs no more nodes at
/// `finest_cell_mm` than `box` at its solve spacing, and the boxes together sample every axis
/// of `box` (ThinPlateOptions::extrusion_weight's test: nearly coplanar slices keep the one
/// grid, whose padding the extrusion fills).
std::vector<Box3> own_grid_boxes(const Box3& box, double finest_cell_mm,
                                 const std::vector<Box3>& material_boxes,
                                 const ThinPlateOptions& options);

/// Per material 1..K (index m - 1), the box of its contour points in `slices` (world mm; empty,
/// min > max, where it does not occur).
std::vector<Box3> material_boxes(const std::vector<PreparedSlice>& slices, int materials);
/// The extent a truncation is set from: `extent_mm` rounded up to a power of 2^(1/4) (0 for 0).
/// An online engine rebuilds the field when this changes, so that its truncations are those a
/// one-shot reconstruction of the same slices computes, and rebuilds at most four times per
/// doubling of an organ's extent.
double truncation_extent(double extent_mm);

/// The diagonals of `boxes` (0 for an empty box): the extents ThinPlateField takes.
std::vector<double> box_extents(const std::vector<Box3>& boxes);

/// The signed distances of one slice at in-plane points, per material (K per point, clamped to
/// +-truncation; NaN where the point is unknown), `shadow_casters` as ThinPlateOptions has them:
/// exposed for tests.
std::vector<double> slice_signed_distances(const PreparedSlice& slice, int materials,
                                           double truncation, const std::vector<Vec2>& points,
                                           const std::vector<bool>& shadow_casters = {});

}  // namespace sonoshape::recon
