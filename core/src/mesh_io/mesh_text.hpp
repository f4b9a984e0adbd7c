#pragma once
// Text scanning shared by the mesh readers (words, numbers, numbered lines, polygons) and the
// number format of the text writers.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "sonoshape/core/mesh.hpp"

namespace sonoshape::mesh_io {

std::string lower(std::string s);

/// The words of a line, split at white space.
std::vector<std::string_view> split_words(std::string_view line);

/// Whole-word parses (a leading '+' is accepted, as some exporters write it); doubles must be
/// finite.
bool parse_double(std::string_view word, double& value);
bool parse_long(std::string_view word, long long& value);

/// Splits text into lines, keeping 1-based line numbers for messages.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : text_(text) {}
  bool next(std::string_view& line);
  int number() const { return number_; }
  std::size_t position() const { return pos_; }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  int number_ = 0;
};

/// Appends a polygon as a triangle fan after checking its indices; throws InputError at `where`.
void add_polygon(TriangleMesh& mesh, const std::vector<long long>& polygon,
                 std::size_t vertex_count, const std::string& where);

/// Shortest text that reads back as the same double.
void append_number(std::string& out, double value);

}  // namespace sonoshape::mesh_io
