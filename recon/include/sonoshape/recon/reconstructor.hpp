#pragma once
// Online reconstruction (Bermano, Vaxman & Gotsman 2011, Section 7): slices arrive one by one;
// each update splits only the arrangement cells the new plane crosses and re-evaluates the field
// only where cells (or their unknown-region completion) changed, then smooths and meshes.
//
// Invariant (tested): after any sequence of add_slice / remove_slice and update(), the sampled
// field and the meshes equal those of the one-shot reconstruct() of slice_set().
#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/recon/reconstruct.hpp"

namespace sonoshape::recon {

/// What a Reconstructor is set up with.
struct ReconstructorOptions {
  ReconstructionOptions engine;
  /// Reconstruction box (mm). None: the box of the slices seen so far (SliceSet::effective_bounds),
  /// which forces a full rebuild whenever a new slice reaches outside it; give the scan volume
  /// for a live scan so that never happens.
  std::optional<Box3> bounds;
  /// Materials known up front (ids and names); materials first seen in a slice are added.
  std::vector<LabelInfo> labels;
  /// Thin-plate field: every update moves its meshes' vertices onto the field's zero set and
  /// splits their edges where the surface bends (docs/engine.md, section 6), which costs about
  /// as much as the marching tetrahedra and the octree's evaluations together. A live scan's
  /// updates leave it off (their meshes are previews); its settled meshes have it.
  bool refine_meshes = true;
};

/// What one update() did.
struct UpdateStats {
  ReconstructionStats step;        ///< per-stage seconds of this update; counts of the result
  std::size_t slices_added = 0;    ///< pending additions applied
  std::size_t slices_removed = 0;  ///< pending removals applied
  std::size_t cells_changed = 0;   ///< cells whose field was invalidated (created, split, or
                                   ///< with a changed face image or completion)
  bool full_rebuild = false;       ///< everything was recomputed (box grew, material added, ...)
};

/// Stateful reconstruction. Thread-compatible: const members may be called concurrently; calls
/// that modify it need external synchronisation.
class Reconstructor {
 public:
  explicit Reconstructor(ReconstructorOptions options = {});
  ~Reconstructor();
  Reconstructor(Reconstructor&&) noexcept;
  Reconstructor& operator=(Reconstructor&&) noexcept;

  /// Queues a slice for the next update() and returns its id (0, 1, 2, ... in call order).
  /// Throws std::invalid_argument, naming the problem, for a slice that fails the checks of the
  /// slice-set format (degenerate frame, bad rings) or whose plane coincides with a slice
  /// already in (or queued) with different content; the state is then unchanged. A slice
  /// identical to one already in is accepted and ignored by the reconstruction.
  int add_slice(LabeledSlice slice);

  /// Queues the removal of slice `id` (undo a bad frame). Returns false when no such slice is
  /// in (or queued).
  bool remove_slice(int id);

  /// Applies the queued additions and removals and refreshes the meshes. Cheap when nothing is
  /// queued. Throws GeometryError for slices the engine cannot use; the queued changes are then
  /// dropped and the previous state and meshes are kept. Throws sonoshape::Error, changing
  /// nothing, when the first update cannot open the field's device (ReconstructionOptions::device).
  UpdateStats update();

  /// The meshes of the last update(): one per material (empty before the first update).
  const MeshSet& mesh() const;
  /// Ids of the slices in the reconstruction (after the last update), in insertion order.
  std::vector<int> slice_ids() const;
  /// The slices of the last update() with labels and the box, as reconstruct() would take them.
  SliceSet slice_set() const;
  /// Number of slices in the reconstruction after the last update().
  std::size_t slice_count() const;
  /// Totals over every update so far (seconds summed, counts of the current state).
  const ReconstructionStats& totals() const;

  /// The sampled field of the last update at every evaluated grid vertex, for the invariant
  /// tests: (position, values of functions 0..K) sorted by grid key.
  std::vector<std::pair<Vec3, std::vector<double>>> sampled_field() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace sonoshape::recon
