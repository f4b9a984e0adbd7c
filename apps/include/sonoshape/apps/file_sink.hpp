#pragma once
// The scan's files: meshes, slices and summary in a directory (`scan --out`).
#include <cstddef>
#include <filesystem>

#include "sonoshape/scan/sink.hpp"

namespace sonoshape::apps {

/// Writes the meshes to a directory (`label_<id>.ply`, write_mesh_set) every
/// `save_every` slices and at the end, with the slices (`slices.json`) and the summary
/// (`scan.json`) at the end. Files are written under a temporary name and renamed, so a reader
/// never sees half a mesh.
class FileSink final : public scan::ScanSink {
 public:
  /// Writes into `directory` (created when needed); `save_every` = 0: at the end only.
  FileSink(std::filesystem::path directory, std::size_t save_every = 0);

  Status on_slice(const LabeledSlice& slice, std::size_t index) override;
  Status on_meshes(const MeshSet& meshes, const scan::MeshUpdateInfo& info) override;
  Status on_status(const scan::ScanStatus& status) override;
  Status on_finish(const MeshSet& meshes, const SliceSet& slices,
                   const scan::ScanSummary& summary) override;

  /// How many times meshes were written (intermediate and final).
  std::size_t saves() const { return saves_; }

 private:
  Status write_meshes(const MeshSet& meshes);
  /// `status` the first time saving fails after a success; ok for the repeats.
  Status reported(Status status);
  std::filesystem::path directory_;
  std::size_t save_every_;
  std::size_t saved_at_slices_ = 0;
  std::size_t saves_ = 0;
  std::size_t failures_ = 0;  // saves failed since the last one that worked
};

}  // namespace sonoshape::apps
