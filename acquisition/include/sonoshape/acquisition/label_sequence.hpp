#pragma once
// A site's own label maps ("bring your own labels", `segment`/`scan --labels`): a label-map
// sequence aligned frame by frame to a recording (a 3D Slicer segmentation sequence `.seq.nrrd`,
// a PLUS `.mha`), or single label maps from a network (OpenIGTLink IMAGE messages), brought to
// the label pixels sonoshape's own segmenter produces.
//
// The values of a label map: 0 is background (inside the field of view, no organ), 1..254 are
// organ labels (sonoshape's label ids, unchanged), and one value marks unknown pixels (a shadow,
// what the site's method could not judge): 255 by default, another with `--labels-unknown`.
#include <filesystem>
#include <map>
#include <optional>
#include <string>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/image.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition {

/// The label-map value for unknown pixels unless told otherwise (sonoshape's kLabelPixelUnknown).
constexpr int kDefaultUnknownLabelValue = 255;
/// How far apart (s) the times of a label frame and its recording frame may be (also the
/// pairing tolerance of label maps received over OpenIGTLink): 1 ms, well below any frame
/// interval, above the rounding of times written as text.
constexpr double kLabelTimeToleranceS = 1e-3;

/// Brings a site's label map to sonoshape's label pixels in place: 0 and 1..254 stay as they
/// are, `unknown_value` (1..255) becomes kLabelPixelUnknown. Fails, naming `where` (file and
/// frame, or the device), the pixel and the fix, when a pixel holds 255 while `unknown_value` is
/// another value: 255 is sonoshape's own unknown and cannot be an organ.
Status to_label_pixels(LabelImage& labels, int unknown_value, const std::string& where);

/// The organ names a label-map header gives, by label value: 3D Slicer's segmentation keys
/// `Segment<i>_Name` with `Segment<i>_LabelValue` (absent: i + 1, as older Slicer files imply),
/// else `SonoshapeLabels` ("1:liver 2:kidney", as `sonoshape simulate` writes). Empty when the
/// header names none. Fails naming `path` and the key when a label value is not an integer in
/// 1..254, two segments share one, or a segment lies on another layer than the first (Slicer's
/// overlapping segments, which one label map cannot hold).
Result<std::map<int, std::string>> label_names(const FieldList& fields,
                                               const std::filesystem::path& path);

/// A label-map sequence read for a recording.
struct LabelSequence {
  /// One label map per frame of the recording, as sonoshape's label pixels, in the recording's
  /// pixel order after reorient_to_mf.
  SequenceFile maps;
  std::map<int, std::string> names;  ///< label_names of its header
  /// How its frames were matched to the recording's in time, for the log: "times agree",
  /// "times agree up to an offset of X s", or why they were not compared.
  std::string timing;
};

/// Reads the label maps of `recording` (read from `recording_path`, before reorient_to_mf and
/// fill_missing_timestamps) from `path`: any sequence read_sequence_file reads (a 3D Slicer
/// `.seq.nrrd`, 8- or 16-bit with values 0..255; a PLUS `.mha`/`.igs.mha`/`.nrrd`). Frame k of
/// the file is the label map of frame k of the recording; checked: the frame counts, every
/// frame's size (the recording's W x H), and where both files give times, that they agree
/// within kLabelTimeToleranceS (or all differ by one offset: another clock origin). A file
/// without its own `UltrasoundImageOrientation` is taken in the recording's stored one; both are
/// brought to MF as the recording is. Pixel values as to_label_pixels. Fails naming the file,
/// the frame and the fix.
Result<LabelSequence> read_label_sequence(const std::filesystem::path& path,
                                          const SequenceFile& recording,
                                          const std::filesystem::path& recording_path,
                                          int unknown_value = kDefaultUnknownLabelValue);

}  // namespace sonoshape::acquisition
