#include "mesh_text.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>

#include "sonoshape/core/errors.hpp"

namespace sonoshape::mesh_io {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const std::size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

bool parse_double(std::string_view word, double& value) {
  // from_chars for double rejects a leading '+', which some exporters write.
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), value);
  return ec == std::errc() && end == word.data() + word.size() && std::isfinite(value);
}

bool parse_long(std::string_view word, long long& value) {
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), value);
  return ec == std::errc() && end == word.data() + word.size();
}

bool LineReader::next(std::string_view& line) {
  if (pos_ >= text_.size()) return false;
  std::size_t end = text_.find('\n', pos_);
  if (end == std::string_view::npos) end = text_.size();
  line = text_.substr(pos_, end - pos_);
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  pos_ = end < text_.size() ? end + 1 : end;  // a last line without '\n' ends at the end
  ++number_;
  return true;
}

void add_polygon(TriangleMesh& mesh, const std::vector<long long>& polygon,
                 std::size_t vertex_count, const std::string& where) {
  if (polygon.size() < 3)
    throw InputError(where,
                     "a face needs at least 3 vertices, got " + std::to_string(polygon.size()));
  for (long long index : polygon)
    if (index < 0 || static_cast<std::size_t>(index) >= vertex_count)
      throw InputError(where, "vertex index " + std::to_string(index) +
                                  " out of range (the file has " + std::to_string(vertex_count) +
                                  " vertices so far)");
  for (std::size_t k = 1; k + 1 < polygon.size(); ++k)
    mesh.triangles.push_back({static_cast<std::uint32_t>(polygon[0]),
                              static_cast<std::uint32_t>(polygon[k]),
                              static_cast<std::uint32_t>(polygon[k + 1])});
}

void append_number(std::string& out, double value) {
  std::array<char, 32> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  out.append(buffer.data(), ec == std::errc() ? end : buffer.data());
}

}  // namespace sonoshape::mesh_io
