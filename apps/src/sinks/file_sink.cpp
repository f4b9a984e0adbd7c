#include "sonoshape/apps/file_sink.hpp"

#include <string>
#include <system_error>
#include <utility>

#include "sonoshape/core/log.hpp"
#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/slice_io.hpp"
#include "sonoshape/scan/journal.hpp"

namespace sonoshape::apps {
namespace {

namespace fs = std::filesystem;

Status ensure_directory(const fs::path& directory) {
  std::error_code ec;
  fs::create_directories(directory, ec);
  if (ec || !fs::is_directory(directory))
    return Status::error("cannot create the output directory " + directory.string() + ": " +
                         (ec ? ec.message() : std::string("a file of that name exists")) +
                         "; choose another --out");
  return Status::ok();
}

}  // namespace

FileSink::FileSink(fs::path directory, std::size_t save_every)
    : directory_(std::move(directory)), save_every_(save_every) {}

Status FileSink::on_slice(const LabeledSlice&, std::size_t) { return Status::ok(); }

Status FileSink::on_status(const scan::ScanStatus&) { return Status::ok(); }

// Writes under a temporary name in the same directory, then sync_and_rename: after a crash the
// final name holds the previous version or the new one, whole. A failed write leaves no
// temporary file behind (a full disk wants its space back).
Status FileSink::write_meshes(const MeshSet& meshes) {
  if (Status made = ensure_directory(directory_); !made) return made;
  for (const MeshSet::Entry& entry : meshes.meshes) {
    const std::string name = "label_" + std::to_string(entry.label) + ".ply";
    const fs::path partial = directory_ / (".partial-" + name);
    Status written = write_mesh(entry.mesh, partial);
    if (written) written = scan::sync_and_rename(partial, directory_ / name);
    if (!written) {
      std::error_code ignored;
      fs::remove(partial, ignored);
      return written;
    }
  }
  ++saves_;
  return Status::ok();
}

Status FileSink::reported(Status status) {
  if (status) {
    if (failures_ > 0)
      log_info("scan: writing to " + directory_.string() + " works again (" +
               std::to_string(failures_) + " saves had failed)");
    failures_ = 0;
    return status;
  }
  // Once per run of failures: a full disk fails every save, and one line says it.
  return failures_++ == 0 ? status : Status::ok();
}

Status FileSink::on_meshes(const MeshSet& meshes, const scan::MeshUpdateInfo& info) {
  if (save_every_ == 0 || info.slices < saved_at_slices_ + save_every_) return Status::ok();
  saved_at_slices_ = info.slices - info.slices % save_every_;
  return reported(write_meshes(meshes));
}

Status FileSink::on_finish(const MeshSet& meshes, const SliceSet& slices,
                           const scan::ScanSummary& summary) {
  // Each file on its own: a mesh that does not fit must not cost the summary.
  Status first = write_meshes(meshes);
  if (!slices.slices.empty()) {
    const fs::path partial = directory_ / ".partial-slices.json";
    Status written = write_slice_set_json(slices, partial);
    if (written) written = scan::sync_and_rename(partial, directory_ / "slices.json");
    if (!written) {
      std::error_code ignored;
      fs::remove(partial, ignored);
      if (first) first = written;
    }
  }
  if (Status written =
          scan::write_file_atomically(directory_ / "scan.json", scan::summary_json(summary) + '\n');
      !written && first)
    first = written;
  return first;
}

}  // namespace sonoshape::apps
