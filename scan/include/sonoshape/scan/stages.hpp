#pragma once
// The two heavy stages of the scan pipeline behind small interfaces: segmentation (tracked
// frame -> slice) and reconstruction (slices -> meshes), so that the pipeline can be tested
// with fakes and the engines swapped without touching the threads.
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/frame.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/repairs.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/recon/reconstructor.hpp"
#include "sonoshape/scan/setup.hpp"
#include "sonoshape/segmentation/labeller.hpp"
#include "sonoshape/segmentation/scoring.hpp"
#include "sonoshape/segmentation/sector_share.hpp"

namespace sonoshape::scan {

/// Tracked frame -> labelled slice. Called from the pipeline's segmentation thread only.
class SegmentationStage {
 public:
  virtual ~SegmentationStage() = default;
  /// The slice of `frame` in the reference frame (fov = the sector, timestamp = the frame's),
  /// or why there is none. May throw; the pipeline counts that as a failed frame.
  virtual Result<LabeledSlice> segment(const TrackedFrame& frame) = 0;
  /// What the last segment() repaired to make the slice valid (dropped regions), handed over
  /// once; none by default.
  virtual std::vector<Repair> take_repairs() { return {}; }
  /// The meshes of the reconstruction's latest update, for a stage that lets them guide the next
  /// frames. Called from the reconstruction thread: implementations must be thread-safe with
  /// segment(). Ignored by default.
  virtual void on_meshes(const MeshSet& /*meshes*/) {}
  /// The segmentation's label maps against the truth so far (simulated sources), summed over
  /// the scored frames; none when nothing was scored. Called after the stage has stopped.
  virtual std::optional<segmentation::LabelComparison> scores() const { return std::nullopt; }
};

/// The segmentation of segmentation/ (segmentation::segment_frame + segmentation::make_slice), as
/// `sonoshape segment` does it frame by frame (with its warning, once, when one label fills
/// nearly all of most sectors after its first 10 frames). With the graph-cut method, the meshes of
/// the latest reconstruction update, cut by each new frame's plane, are the cut's prior.
class SegmenterStage final : public SegmentationStage {
 public:
  /// Throws std::invalid_argument for a setup whose configuration or geometry is invalid.
  explicit SegmenterStage(ScanSetup setup);
  ~SegmenterStage() override;
  /// Fails for frames whose size differs from the setup's geometry.
  Result<LabeledSlice> segment(const TrackedFrame& frame) override;
  std::vector<Repair> take_repairs() override;
  void on_meshes(const MeshSet& meshes) override;
  /// Scores every label map against the truth this gives for its frame (simulated sources).
  void score_against(std::function<std::optional<LabelImage>(std::int64_t)> truth_of_frame);
  std::optional<segmentation::LabelComparison> scores() const override;

 private:
  std::map<int, std::string> label_names() const;

  std::function<std::optional<LabelImage>(std::int64_t)> truth_of_frame_;
  segmentation::LabelComparison scores_;
  std::size_t scored_frames_ = 0;
  ScanSetup setup_;
  std::vector<Repair> repairs_;                               // of the last segment()
  std::unique_ptr<segmentation::GraphCutLabeller> labeller_;  // with the graph-cut method
  segmentation::SectorShareCheck
      shares_;  // one label filling nearly all of most sectors: warned once
  bool shares_warned_ = false;
  std::mutex meshes_mutex_;
  std::shared_ptr<const MeshSet> meshes_;  // of the latest update, for the prior
};

/// Slices -> meshes, incrementally. Called from the pipeline's reconstruction thread only.
class ReconstructionStage {
 public:
  virtual ~ReconstructionStage() = default;
  /// Queues a slice for the next update() and returns its id. Throws (std::invalid_argument)
  /// for a slice it refuses; the state is then unchanged.
  virtual int add_slice(LabeledSlice slice) = 0;
  /// Applies the queued slices and refreshes the meshes. Throws when the update fails; the
  /// queued slices are then dropped and the previous meshes kept.
  virtual recon::UpdateStats update() = 0;
  /// The meshes of the last update().
  virtual const MeshSet& meshes() const = 0;
  /// The slices of the last update() (with labels and box).
  virtual SliceSet slice_set() const = 0;
  /// Slices in the reconstruction after the last update().
  virtual std::size_t slice_count() const = 0;
  /// At the end of a scan: makes meshes() those of the one-shot reconstruction of slice_set()
  /// (what `reconstruct slices.json` gives), where the online updates reach it only to a
  /// tolerance, so that a scan's final meshes depend on its slices alone, not on how its
  /// updates happened to batch them. None when the meshes already are that (nothing was done).
  virtual std::optional<recon::UpdateStats> settle() { return std::nullopt; }
};

/// recon::Reconstructor as a reconstruction stage.
std::unique_ptr<ReconstructionStage> make_reconstructor_stage(
    const recon::ReconstructorOptions& options);

}  // namespace sonoshape::scan
