#pragma once
// The sequence-file targets: read the scratch file, then use what a caller would (frames,
// timestamps, transforms and the checks `segment` runs), so the fields' parsers are reached too.
#include <cstddef>
#include <string_view>

#include "fuzz_support.hpp"
#include "sonoshape/acquisition/pose_chain.hpp"
#include "sonoshape/acquisition/sequence_file.hpp"

namespace sonoshape::fuzz {

inline void read_sequence(std::string_view bytes, std::string_view extension) {
  quiet_logs();
  const auto path = write_scratch_file(bytes, extension);
  auto file = acquisition::read_sequence_file(path);
  if (!file) return;
  for (std::size_t k = 0; k < file->frame_count(); ++k) {
    (void)file->timestamp_s(k);
    (void)file->frame(k);
    for (const auto& name : file->transform_names()) {
      (void)file->transform(name, k);
      (void)file->transform_status(name, k);
    }
  }
  (void)acquisition::require_tracking(*file, path);
  (void)acquisition::check_tracked_sweep(*file, path);
  // What `segment` and `replay:` do next: the pose chain, the crop, the orientation, the timing.
  if (const auto chain = acquisition::find_pose_chain(*file, path); chain) {
    for (std::size_t k = 0; k < file->frame_count(); ++k) (void)chain->pose(*file, k);
    (void)acquisition::check_tracked_sweep(*file, path, chain->per_frame_names());
  }
  (void)acquisition::image_to_cropped_image(*file, path);
  (void)acquisition::reorient_to_mf(*file, path);
  (void)acquisition::fill_missing_timestamps(*file);
}

}  // namespace sonoshape::fuzz
