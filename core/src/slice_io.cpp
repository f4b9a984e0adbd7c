// Reading and writing slice sets by extension: `.csl` (csl_io.cpp) or JSON (slice_json.cpp).
#include "sonoshape/core/slice_io.hpp"

#include <algorithm>
#include <cctype>

#include "text_io.hpp"

namespace sonoshape {
namespace {

std::string lower_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

}  // namespace

Result<SliceSet> read_slice_set(const std::filesystem::path& path, const ReadOptions& options) {
  Result<std::string> text = detail::read_text_file(path);
  if (!text) return text.status();
  if (lower_extension(path) == ".csl") return parse_csl(*text, path.string(), options);
  return parse_slice_set_json(*text, path.string(), options);
}

Status write_slice_set(const SliceSet& set, const std::filesystem::path& path) {
  if (lower_extension(path) == ".csl") return write_csl(set, path);
  return write_slice_set_json(set, path);
}

}  // namespace sonoshape
