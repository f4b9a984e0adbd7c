#include "sonoshape/acquisition/label_sequence.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <sstream>
#include <vector>

#include "sonoshape/acquisition/pose_chain.hpp"

namespace sonoshape::acquisition {
namespace {

std::optional<int> to_int(const std::string& text) {
  int value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

std::string seconds(double s) {
  std::ostringstream out;
  out.precision(6);
  out << s;
  return out.str();
}

// "1:liver 2:kidney" (as `sonoshape simulate` writes SonoshapeLabels); malformed items skipped.
std::map<int, std::string> sonoshape_labels(const std::string& text) {
  std::map<int, std::string> names;
  std::istringstream in(text);
  std::string item;
  while (in >> item) {
    const std::size_t colon = item.find(':');
    if (colon == std::string::npos) continue;
    if (const auto value = to_int(item.substr(0, colon));
        value && *value >= 1 && *value <= kMaxPixelLabel)
      names[*value] = item.substr(colon + 1);
  }
  return names;
}

// Slicer's Segment<i>_* keys, i = 0, 1, ... until one has no name.
Result<std::map<int, std::string>> slicer_segments(const FieldList& fields,
                                                   const std::filesystem::path& path) {
  std::map<int, std::string> names;
  std::optional<std::string> first_layer;
  for (int i = 0;; ++i) {
    const std::string key = "Segment" + std::to_string(i) + "_";
    const auto name = find_field(fields, key + "Name");
    if (!name) break;
    const std::string value_text =
        find_field(fields, key + "LabelValue").value_or(std::to_string(i + 1));
    const auto value = to_int(value_text);
    if (!value || *value < 1 || *value > kMaxPixelLabel)
      return Status::error(path.string() + ": " + key + "LabelValue = " + value_text +
                           " is not a label value sonoshape can hold (an integer 1.." +
                           std::to_string(kMaxPixelLabel) +
                           "); renumber the segment (Slicer: Segment Editor, segment's "
                           "label value) or export the label map with values 1.." +
                           std::to_string(kMaxPixelLabel));
    if (names.count(*value))
      return Status::error(path.string() + ": " + key + "LabelValue = " + value_text +
                           " is also the label value of '" + names[*value] +
                           "'; give each segment its own value (one label map holds one label "
                           "per pixel)");
    const std::string layer = find_field(fields, key + "Layer").value_or("0");
    if (!first_layer) first_layer = layer;
    if (layer != *first_layer)
      return Status::error(path.string() + ": segment '" + *name + "' (" + key +
                           "Layer = " + layer +
                           ") lies on another layer than the first segment: the "
                           "segments overlap, which one label map cannot hold; in Slicer make "
                           "them not overlap (Segment Editor masking) and save again");
    names[*value] = *name;
  }
  return names;
}

// Frame counts and sizes of the label file against the recording.
Status check_shape(const SequenceFile& maps, const std::filesystem::path& path,
                   const SequenceFile& recording, const std::filesystem::path& recording_path) {
  const std::string fix =
      ": give one label map per frame of the recording, in its order (Slicer: a segmentation "
      "sequence over the recording's browser; a network: one output per frame)";
  if (maps.frame_count() != recording.frame_count())
    return Status::error(path.string() + " has " + std::to_string(maps.frame_count()) +
                         " label maps but " + recording_path.string() + " has " +
                         std::to_string(recording.frame_count()) + " frames" + fix);
  for (std::size_t k = 0; k < maps.frame_count(); ++k) {
    const GreyImage& label = maps.image(k);
    const GreyImage& frame = recording.image(k);
    if (label.width != frame.width || label.height != frame.height)
      return Status::error(
          path.string() + ", frame " + std::to_string(k) + ": the label map is " +
          std::to_string(label.width) + "x" + std::to_string(label.height) + " pixels but frame " +
          std::to_string(k) + " of " + recording_path.string() + " is " +
          std::to_string(frame.width) + "x" + std::to_string(frame.height) +
          "; export the label maps on the recording's own pixel grid (Slicer: Export to "
          "label map with the B-mode volume as reference geometry, not cropped to the "
          "segments)");
  }
  return Status::ok();
}

// Times of the label frames against the recording's: equal within the tolerance, or all
// shifted by one offset (another clock origin). Returns the note for the log.
Result<std::string> check_times(const SequenceFile& maps, const std::filesystem::path& path,
                                const SequenceFile& recording,
                                const std::filesystem::path& recording_path) {
  const std::size_t n = maps.frame_count();
  std::vector<double> label_s(n), frame_s(n);
  bool labels_timed = n > 0, frames_timed = n > 0;
  for (std::size_t k = 0; k < n; ++k) {
    const auto l = maps.timestamp_s(k);
    const auto f = recording.timestamp_s(k);
    labels_timed = labels_timed && l.has_value();
    frames_timed = frames_timed && f.has_value();
    label_s[k] = l.value_or(0.0);
    frame_s[k] = f.value_or(0.0);
  }
  if (!labels_timed || !frames_timed)
    return std::string(!labels_timed && !frames_timed ? "neither file has frame times"
                       : !labels_timed                ? "the label maps have no times"
                                                      : "the recording has no frame times") +
           ": frames paired by index only";
  bool equal = true;
  for (std::size_t k = 0; k < n && equal; ++k)
    equal = std::abs(label_s[k] - frame_s[k]) <= kLabelTimeToleranceS;
  if (equal) return std::string("times agree");
  const double offset_s = label_s[0] - frame_s[0];
  for (std::size_t k = 0; k < n; ++k)
    if (std::abs(label_s[k] - frame_s[k] - offset_s) > kLabelTimeToleranceS)
      return Status::error(
          path.string() + ", frame " + std::to_string(k) + ": the label map is at " +
          seconds(label_s[k]) + " s but frame " + std::to_string(k) + " of " +
          recording_path.string() + " is at " + seconds(frame_s[k]) +
          " s, and the frames before differ by " + seconds(offset_s) +
          " s: the label maps are not one per frame in the recording's order (a frame "
          "missing or repeated?); give one label map per frame, in order, with the "
          "recording's times");
  return "times agree up to an offset of " + seconds(offset_s) + " s (another clock origin)";
}

}  // namespace

Status to_label_pixels(LabelImage& labels, int unknown_value, const std::string& where) {
  if (unknown_value < 1 || unknown_value > 255)
    return Status::error(where + ": the unknown label value " + std::to_string(unknown_value) +
                         " is not in 1..255");
  if (unknown_value == kLabelPixelUnknown) return Status::ok();
  for (std::size_t p = 0; p < labels.pixels.size(); ++p) {
    std::uint8_t& v = labels.pixels[p];
    if (v == kLabelPixelUnknown) {
      const std::size_t w = static_cast<std::size_t>(std::max(labels.width, 1));
      return Status::error(where + ": pixel (" + std::to_string(p % w) + ", " +
                           std::to_string(p / w) +
                           ") is 255, which is sonoshape's unknown, "
                           "while unknown pixels are " +
                           std::to_string(unknown_value) +
                           " (--labels-unknown); give that organ another value (1..254) or "
                           "mark unknown pixels with 255");
    }
    if (v == unknown_value) v = kLabelPixelUnknown;
  }
  return Status::ok();
}

Result<std::map<int, std::string>> label_names(const FieldList& fields,
                                               const std::filesystem::path& path) {
  auto slicer = slicer_segments(fields, path);
  if (!slicer || !slicer->empty()) return slicer;
  return sonoshape_labels(find_field(fields, "SonoshapeLabels").value_or(""));
}

Result<LabelSequence> read_label_sequence(const std::filesystem::path& path,
                                          const SequenceFile& recording,
                                          const std::filesystem::path& recording_path,
                                          int unknown_value) {
  auto read = read_sequence_file(path);
  if (!read) return Status::error("--labels: " + read.message());
  LabelSequence out;
  out.maps = std::move(*read);
  // Names first: a segmentation on several layers reads as frames, and says so here.
  auto names = label_names(out.maps.fields(), path);
  if (!names) return names.status();
  out.names = std::move(*names);
  if (const Status shape = check_shape(out.maps, path, recording, recording_path); !shape)
    return shape;
  auto timing = check_times(out.maps, path, recording, recording_path);
  if (!timing) return timing.status();
  out.timing = std::move(*timing);
  for (std::size_t k = 0; k < out.maps.frame_count(); ++k)
    if (const Status mapped = to_label_pixels(out.maps.image(k), unknown_value,
                                              path.string() + ", frame " + std::to_string(k));
        !mapped)
      return mapped;
  // Label maps drawn on the stored frames share their orientation unless they say their own.
  if (!out.maps.field("UltrasoundImageOrientation"))
    if (const auto stored = recording.field("UltrasoundImageOrientation"))
      out.maps.set_field("UltrasoundImageOrientation", *stored);
  if (auto flipped = reorient_to_mf(out.maps, path); !flipped) return flipped.status();
  return out;
}

}  // namespace sonoshape::acquisition
