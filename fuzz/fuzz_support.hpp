#pragma once
// Shared by the fuzz targets: readers that take a path get the input through a scratch file.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "sonoshape/core/log.hpp"

namespace sonoshape::fuzz {

/// The input as a string (every reader under test parses text or bytes held in a string).
inline std::string as_string(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

/// Writes `bytes` to one scratch file per process and extension in the temp directory, so that
/// fuzzers run side by side do not share files; returns its path. The extension matters: the
/// readers choose the format by it.
inline std::filesystem::path write_scratch_file(std::string_view bytes,
                                                std::string_view extension) {
  const auto path = std::filesystem::temp_directory_path() /
                    ("sonoshape-fuzz-" + std::to_string(::getpid()) + std::string(extension));
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return path;
}

/// With SONOSHAPE_FUZZ_EXPLAIN set, a target prints what its reader made of each input (accepted,
/// or the error), to check that seeds reach the code behind the format checks.
inline void explain(const std::string& what) {
  static const bool on = std::getenv("SONOSHAPE_FUZZ_EXPLAIN") != nullptr;
  if (on) std::fprintf(stderr, "  %s\n", what.c_str());
}

/// Repairs print warnings on stderr; millions of inputs would drown libFuzzer's own report.
inline void quiet_logs() {
  static const bool done = [] {
    set_log_level(LogLevel::kQuiet);
    return true;
  }();
  (void)done;
}

}  // namespace sonoshape::fuzz
