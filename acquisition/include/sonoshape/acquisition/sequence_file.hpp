#pragma once
// Tracked-frame sequence files, read into one model whatever the format:
// - PLUS MetaImage (.igs.mha, .seq.mha, .mha): a text header with global fields and per-frame
//   `Seq_FrameNNNN_<Name> = value` fields, then W x H x N 8-bit pixels, zlib-compressed (one
//   stream for all frames) or raw. Every field is kept, unknown ones too, in file order, so a
//   file read and written again keeps all of them.
// - NRRD (.igs.nrrd from PLUS, .seq.nrrd from 3D Slicer's Sequences module, .nrrd, .nhdr):
//   see read_sequence_file. Sequences are written as MetaImage only.
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

namespace sonoshape::acquisition {

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
    acquisition::set_field(fields_, key, std::move(value));
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
    acquisition::set_field(frame_fields_.at(k), name, std::move(value));
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

/// Reads a sequence file; the content picks the format: a first line `NRRD0001`..`NRRD0005` is
/// NRRD, anything else is read as MetaImage.
///
/// MetaImage: NDims 2 (one frame) or 3, ElementType MET_UCHAR with one channel, compressed
/// (zlib) or raw, after the header (`ElementDataFile = LOCAL`) or in one file beside it (a .mhd's
/// `ElementDataFile = sweep.raw`: a plain name in the header's folder; paths, `..`, LIST and
/// patterns are refused).
///
/// NRRD (docs/formats/sequences.md has the details):
/// - axes: two image axes (kind `domain`/`space`, the first two longer than one sample; a third
///   spatial axis must have size 1) and at most one frame axis (kind `list` or `time`, first or
///   last); other kinds only with size 1. PLUS: `kinds: domain domain list`; Slicer:
///   `kinds: domain domain domain list` with sizes `W H 1 N` (or the older `list domain domain
///   domain`). Without a frame axis the file is one frame.
/// - samples: type uint8 (all spellings), or 8/16-bit signed/unsigned when every value is in
///   0..255 (16-bit needs `endian`); encoding raw, gzip/gz or text; attached after the blank
///   line or in one detached `data file` (relative to the header), with `line skip` and, for
///   raw, `byte skip` (-1 too).
/// - PLUS key/values `Seq_FrameNNNN_<Name>:=value` become the frame's fields (PLUS's NRRD
///   `Status` is renamed `ImageStatus`, its MetaImage name); `ultrasound image orientation` and
///   `ultrasound image type` become UltrasoundImageOrientation / UltrasoundImageType.
/// - Slicer: `axis <A> index values` of the frame axis give each frame's `Timestamp` (seconds)
///   when the index type is numeric (or absent), else a `SequenceIndexValue` field (URL-decoded);
///   `axis <A> item <I> <Name>:=value` becomes field <Name> of frame I. With a 3D space,
///   `space directions` and `space origin` give the global field `ImageToReferenceTransform`
///   (pixel (i, j, 0) to the file's space, e.g. LPS mm): one geometry for every frame, since a
///   .seq.nrrd holds one. Slicer's separate transform sequences (tracking) are not read.
/// - every other field and key/value is kept as a global field under its own name; the layout
///   fields (dimension, type, sizes, encoding, endian, kinds, data file, byte/line skip) are
///   consumed.
///
/// Fails with the file, the header line or field or frame, and what to do on: unreadable
/// files, malformed lines, missing or invalid layout fields, unsupported types or encodings
/// (bzip2, hex, float, RGB), 3D volumes per frame, several data files, per-frame fields of
/// frames that do not exist, index values that do not match the frame count, truncated or
/// corrupt data.
Result<SequenceFile> read_sequence_file(const std::filesystem::path& path);

/// Succeeds when some frame of `file` (read from `path`) has a `<probe_transform>Transform`
/// field, the per-frame tracking that `segment` and `scan --source replay:` need. Fails
/// naming the file and the transforms it has; for an image-only Slicer sequence (global
/// ImageToReferenceTransform, no per-frame tracking) the message says so and how to get a
/// tracked recording.
Status require_tracking(const SequenceFile& file, const std::filesystem::path& path,
                        std::string_view probe_transform = "ProbeToTracker");

/// Checks what `segment` takes from a tracked sweep before it is used: an
/// `UltrasoundImageOrientation` that is MF/MFA (a PLUS code sonoshape does not implement, or
/// one that is no PLUS code such as XYZ, is an error), every frame's `Timestamp` a finite
/// number, and every valid `<probe_transform>` / `ReferenceToTracker` pose rigid (rotation to
/// 1e-3, last row 0 0 0 1). Fails naming the file, the frame and the field, with the fix.
Status check_tracked_sweep(const SequenceFile& file, const std::filesystem::path& path,
                           std::string_view probe_transform = "ProbeToTracker");
/// The same for the per-frame transforms a pose chain reads (PoseChain::per_frame_names): each
/// valid one must be rigid. Frames of another orientation are flipped to MF first by
/// reorient_to_mf (pose_chain.hpp).
Status check_tracked_sweep(const SequenceFile& file, const std::filesystem::path& path,
                           const std::vector<std::string>& pose_transforms);

struct SequenceWriteOptions {
  bool compress = true;       ///< zlib stream (CompressedData = True) or raw pixels
  int compression_level = 1;  ///< zlib level 1..9; speckle barely compresses, so fast wins
};

/// Writes `file` as PLUS does: global fields, the layout fields, per-frame fields as
/// Seq_Frame%04d_<Name>, `ElementDataFile = LOCAL`, then the pixels. Fails on I/O errors and
/// on a sequence without frames (MetaImage cannot express DimSize 0).
Status write_sequence_file(const SequenceFile& file, const std::filesystem::path& path,
                           const SequenceWriteOptions& options = {});

}  // namespace sonoshape::acquisition
