#pragma once
// Helpers shared by the MetaImage and NRRD sequence readers (private to acquisition/).
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::acquisition::detail {

/// The suffix of a frame field that holds a transform ("ProbeToTrackerTransform").
inline constexpr std::string_view kTransformSuffix = "Transform";

inline std::string_view trim(std::string_view s) {
  const auto first = s.find_first_not_of(" \t\r\n");
  if (first == std::string_view::npos) return {};
  const auto last = s.find_last_not_of(" \t\r\n");
  return s.substr(first, last - first + 1);
}

inline std::vector<std::string_view> split_words(std::string_view s) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    const std::size_t start = i;
    while (i < s.size() && s[i] != ' ' && s[i] != '\t') ++i;
    if (i > start) words.push_back(s.substr(start, i - start));
  }
  return words;
}

template <typename T>
std::optional<T> parse_number(std::string_view s) {
  s = trim(s);
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  T value{};
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  if (ec != std::errc() || end != s.data() + s.size() || s.empty()) return std::nullopt;
  if constexpr (std::is_floating_point_v<T>)
    if (!std::isfinite(value)) return std::nullopt;
  return value;
}

/// Prefix of PLUS's per-frame fields ("Seq_Frame0012_ProbeToTrackerTransform").
constexpr std::string_view kFramePrefix = "Seq_Frame";

/// "Seq_Frame0012_ProbeToTrackerTransform" -> (12, "ProbeToTrackerTransform"); none for other keys.
inline std::optional<std::pair<std::size_t, std::string>> split_frame_key(std::string_view key) {
  if (key.substr(0, kFramePrefix.size()) != kFramePrefix) return std::nullopt;
  const std::string_view rest = key.substr(kFramePrefix.size());
  const std::size_t underscore = rest.find('_');
  if (underscore == 0 || underscore == std::string_view::npos || underscore + 1 == rest.size())
    return std::nullopt;
  const auto index = parse_number<std::size_t>(rest.substr(0, underscore));
  if (!index) return std::nullopt;
  return std::make_pair(*index, std::string(rest.substr(underscore + 1)));
}

/// "sequence file <path>: <what>; <fix>".
inline Status fail(const std::filesystem::path& path, const std::string& what,
                   const std::string& fix) {
  return Status::error("sequence file " + path.string() + ": " + what + (fix.empty() ? "" : "; ") +
                       fix);
}

/// What inflate_buffer did: zlib's last return code and the bytes written.
struct InflateResult {
  int rc = 0;
  std::size_t produced = 0;
};

/// Inflates `in` into `out` (`out_size` bytes of room). `window_bits` as zlib's inflateInit2:
/// 15 for a zlib stream (MetaImage), 15 + 32 to accept zlib or gzip (NRRD); with gzip,
/// concatenated members are read one after the other. rc is Z_STREAM_END when the data ended
/// cleanly, Z_BUF_ERROR when the input ran out or `out` is full, another zlib code on corrupt
/// data.
InflateResult inflate_buffer(const std::uint8_t* in, std::size_t in_size, std::uint8_t* out,
                             std::size_t out_size, int window_bits);

/// The bytes of a MetaImage header's `ElementDataFile = name`: a plain file name in the header's
/// folder (no path, no list or pattern). Fails naming the header, the field and the fix.
Result<std::string> read_element_data_file(const std::filesystem::path& header,
                                           const std::string& name);

/// The NRRD reader behind read_sequence_file: `data` is the whole file at `path`, beginning with
/// "NRRD000". See sequence_file.hpp for what it reads.
Result<SequenceFile> read_nrrd_sequence(const std::filesystem::path& path, const std::string& data);

}  // namespace sonoshape::acquisition::detail
