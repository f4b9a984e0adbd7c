#include "sonoshape/acquisition/frame_source.hpp"

#include <utility>

namespace sonoshape::acquisition {

ReplayFrames::ReplayFrames(std::shared_ptr<const SequenceFile> file, std::string name,
                           std::size_t first_frame)
    : file_(std::move(file)), name_(std::move(name)), first_frame_(first_frame) {}

Status ReplayFrames::open() {
  if (!file_ || file_->frame_count() == 0)
    return Status::error(describe() +
                         ": the sequence has no frames; record or choose another file");
  next_ = first_frame_;
  return Status::ok();
}

Result<Polled> ReplayFrames::poll(Frame& frame) {
  while (next_ < file_->frame_count()) {
    const std::size_t k = next_++;
    // PLUS marks frames it could not grab with ImageStatus = INVALID: their pixels mean nothing.
    const auto image_status = file_->frame_field(k, "ImageStatus");
    if (image_status && *image_status != "OK") {
      count_lost(1);
      continue;
    }
    frame = file_->frame(k);
    return Polled::kItem;
  }
  return Polled::kEnd;
}

double first_timestamp_s(const SequenceFile& file) {
  for (std::size_t k = 0; k < file.frame_count(); ++k)
    if (const auto t = file.timestamp_s(k)) return *t;
  return 0.0;
}

}  // namespace sonoshape::acquisition
