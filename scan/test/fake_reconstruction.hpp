#pragma once
// A reconstruction stage for the scan's tests: it keeps the slices and makes one triangle per
// slice, so a lost or altered slice shows in the meshes; each update may sleep `update_ms` (a
// slow engine) and records how many slices it took (the pipeline's batching). With `settles`,
// settle() adds a second triangle per slice, as a field whose final solve differs would.
#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "sonoshape/scan/stages.hpp"

namespace sonoshape::scan::test {

class FakeReconstruction final : public ReconstructionStage {
 public:
  explicit FakeReconstruction(int update_ms = 0, bool settles = false)
      : update_ms_(update_ms), settles_(settles) {}
  int add_slice(LabeledSlice slice) override {
    pending_.push_back(std::move(slice));
    return next_id_++;
  }
  recon::UpdateStats update() override {
    std::this_thread::sleep_for(std::chrono::milliseconds(update_ms_));
    recon::UpdateStats stats;
    stats.slices_added = pending_.size();
    {
      std::lock_guard lock(mutex_);
      batches_.push_back(pending_.size());
    }
    for (LabeledSlice& s : pending_) slices_.slices.push_back(std::move(s));
    pending_.clear();
    meshes_.meshes.assign(1, MeshSet::Entry{1, "organ", {}});
    TriangleMesh& mesh = meshes_.meshes[0].mesh;
    for (std::size_t k = 0; k < slices_.slices.size(); ++k) {
      const auto base = static_cast<std::uint32_t>(mesh.vertices.size());
      mesh.vertices.push_back(slices_.slices[k].origin_mm);
      mesh.vertices.push_back(slices_.slices[k].origin_mm + Vec3::UnitX());
      mesh.vertices.push_back(slices_.slices[k].origin_mm + Vec3::UnitY());
      mesh.triangles.push_back({base, base + 1, base + 2});
    }
    stats.step.slices = slices_.slices.size();
    return stats;
  }
  const MeshSet& meshes() const override { return meshes_; }
  SliceSet slice_set() const override { return slices_; }
  std::size_t slice_count() const override { return slices_.slices.size(); }
  std::optional<recon::UpdateStats> settle() override {
    if (!settles_ || meshes_.meshes.empty()) return std::nullopt;
    TriangleMesh& mesh = meshes_.meshes[0].mesh;
    const std::size_t triangles = mesh.triangles.size();
    for (std::size_t t = 0; t < triangles; ++t) {
      const auto [a, b, c] = mesh.triangles[t];
      mesh.triangles.push_back({a, c, b});
    }
    recon::UpdateStats stats;
    stats.step.slices = slices_.slices.size();
    return stats;
  }

  std::vector<std::size_t> batches() const {
    std::lock_guard lock(mutex_);
    return batches_;
  }

 private:
  int update_ms_;
  bool settles_;
  std::vector<LabeledSlice> pending_;
  SliceSet slices_;
  MeshSet meshes_;
  int next_id_ = 0;
  mutable std::mutex mutex_;
  std::vector<std::size_t> batches_;
};

}  // namespace sonoshape::scan::test
