#pragma once
// PLUS tracked-frame sequence files (.igs.mha, .seq.mha, .mha): a MetaImage text header with
// global fields and per-frame `Seq_FrameNNNN_<Name> = value` fields, then W x H x N 8-bit
// pixels, zlib-compressed (one stream for all frames) or raw. Every field is kept, unknown ones
// too, in file order, so a file read and written again keeps all of them.
#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "sonoshape/core/frame.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acq {

/// Ordered `Key = value` fields (values without surrounding spaces).
using FieldList = std::vector<std::pair<std::string, std::string>>;

/// The value of `key` in `fields`, or none.
std::optional<std::string> find_field(const FieldList& fields, std::string_view key);
/// Replaces the value of `key`, or appends the field.
void set_field(FieldList& fields, std::string_view key, std::string value);

/// "16 numbers, row-major" as PLUS writes a 4x4 transform (6 significant digits are not
/// enough for mm-level positions far from the origin, so this writes 10).
std::string format_matrix(const Eigen::Matrix4d& matrix);
/// Parses 16 numbers (row-major); none if there are not exactly 16 finite numbers.
std::optional<Eigen::Matrix4d> parse_matrix(std::string_view text);

/// A sequence of equally sized 8-bit frames with their fields.
///
/// Global fields hold everything of the header except the per-frame fields, in file order.
/// The fields the layout depends on (NDims, DimSize, ElementType, BinaryData,
/// BinaryDataByteOrderMSB, CompressedData, CompressedDataSize, ElementDataFile) are rewritten
/// from the frames by write_sequence_file; the others are written back as they are.
class SequenceFile {
 public:
  int width() const { return width_; }
  int height() const { return height_; }
  std::size_t frame_count() const { return images_.size(); }

  const FieldList& fields() const { return fields_; }
  std::optional<std::string> field(std::string_view key) const { return find_field(fields_, key); }
  void set_field(std::string_view key, std::string value) {
    acq::set_field(fields_, key, std::move(value));
  }

  /// Appends a frame. The first frame fixes the size; throws std::invalid_argument when a later
  /// one differs or the image is empty or inconsistent (pixels.size() != width * height).
  void add_frame(GreyImage image, FieldList frame_fields = {});

  /// Frame k (0-based); throws std::out_of_range past the end.
  const GreyImage& image(std::size_t k) const { return images_.at(k); }
  GreyImage& image(std::size_t k) { return images_.at(k); }
  const FieldList& frame_fields(std::size_t k) const { return frame_fields_.at(k); }
  std::optional<std::string> frame_field(std::size_t k, std::string_view name) const {
    return find_field(frame_fields_.at(k), name);
  }
  void set_frame_field(std::size_t k, std::string_view name, std::string value) {
    acq::set_field(frame_fields_.at(k), name, std::move(value));
  }

  /// The frame's `Timestamp` field in seconds, or none when absent or not a number.
  std::optional<double> timestamp_s(std::size_t k) const;
  /// Frame k as a Frame value (timestamp 0 when the file has none).
  Frame frame(std::size_t k) const;

  /// The transform `<name>Transform` of frame k (e.g. name "ProbeToTracker"), row-major 4x4 as
  /// stored (PLUS maps From coordinates into To). Fails, naming the frame and field, when it is
  /// absent or not 16 numbers.
  Result<Eigen::Matrix4d> transform(std::string_view name, std::size_t k) const;
  /// `<name>TransformStatus` of frame k: "OK" is valid, anything else (INVALID, MISSING) is
  /// invalid; when the status field is absent, valid iff the transform is readable.
  TrackingStatus transform_status(std::string_view name, std::size_t k) const;
  /// Sets `<name>Transform` and `<name>TransformStatus` (OK / INVALID) of frame k.
  void set_transform(std::string_view name, std::size_t k, const Eigen::Matrix4d& matrix,
                     TrackingStatus status);
  /// Names of every `<name>Transform` field of any frame, in first-seen order.
  std::vector<std::string> transform_names() const;

 private:
  friend Result<SequenceFile> read_sequence_file(const std::filesystem::path& path);
  int width_ = 0;
  int height_ = 0;
  FieldList fields_;
  std::vector<GreyImage> images_;
  std::vector<FieldList> frame_fields_;
};

/// Reads a sequence file. Supports NDims 2 (one frame) or 3, ElementType MET_UCHAR with one
/// channel, `ElementDataFile = LOCAL`, compressed (zlib) or raw. Fails with the file, the header
/// line or frame, and what to do on: unreadable files, lines that are not `Key = value`, missing
/// or invalid DimSize / ElementType / NDims, per-frame fields of frames past DimSize, truncated
/// or corrupt pixel data.
Result<SequenceFile> read_sequence_file(const std::filesystem::path& path);

struct SequenceWriteOptions {
  bool compress = true;       ///< zlib stream (CompressedData = True) or raw pixels
  int compression_level = 1;  ///< zlib level 1..9; speckle barely compresses, so fast wins
};

/// Writes `file` as PLUS does: global fields, the layout fields, per-frame fields as
/// Seq_Frame%04d_<Name>, `ElementDataFile = LOCAL`, then the pixels. Fails on I/O errors and
/// on a sequence without frames (MetaImage cannot express DimSize 0).
Status write_sequence_file(const SequenceFile& file, const std::filesystem::path& path,
                           const SequenceWriteOptions& options = {});

}  // namespace sonoshape::acq
