#include "text_io.hpp"

#include <array>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <fstream>

#include "sonoshape/core/input_file.hpp"
#include "sonoshape/core/slice.hpp"

namespace sonoshape::detail {

std::string label_text(int label) {
  return label == kUnknownLabel ? std::string("unknown") : std::to_string(label);
}

std::string format_double(double value) {
  std::array<char, 64> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  if (ec != std::errc()) return "0";
  return std::string(buffer.data(), end);
}

std::string format_short(double value) {
  std::array<char, 64> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value,
                                       std::chars_format::general, 7);
  if (ec != std::errc()) return "0";
  return std::string(buffer.data(), end);
}

Result<std::string> read_text_file(const std::filesystem::path& path) {
  return read_input_file(path, "slice set");
}

Status write_text_file(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out)
    return Status::error("cannot write " + path.string() + ": " + std::strerror(errno) +
                         "; check that the folder exists and is writable");
  out << text;
  out.flush();
  // errno says which limit it was: ENOSPC (a full disk) or EFBIG (ulimit -f).
  if (!out)
    return Status::error("cannot write " + path.string() + ": " + std::strerror(errno) +
                         "; free disk space or raise the file-size limit, then run again");
  return Status::ok();
}

}  // namespace sonoshape::detail
