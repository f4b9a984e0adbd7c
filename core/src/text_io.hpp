#pragma once
// Text helpers shared by the slice-set readers and writers (JSON, .csl): whole files, numbers and
// labels as messages and files write them.
#include <filesystem>
#include <string>

#include "sonoshape/core/status.hpp"

namespace sonoshape::detail {

/// The largest coordinate a slice file may give, in mm. Lengths beyond 1e12 mm (1000 km) are no
/// anatomy: their squares in the geometry overflow and the polygon then reads as "fewer than 3
/// distinct points", which blames the wrong thing.
inline constexpr double kMaxCoordinateMm = 1e12;

/// "unknown" or the id as text.
std::string label_text(int label);

/// Whole-file helpers: read text (errors name the path) and write text.
Result<std::string> read_text_file(const std::filesystem::path& path);
Status write_text_file(const std::filesystem::path& path, const std::string& text);

/// Shortest decimal text that reads back as the same double.
std::string format_double(double value);

/// `value` to 7 significant digits, for places and areas in messages ("56028.62").
std::string format_short(double value);

}  // namespace sonoshape::detail
