#pragma once
// PNG pictures (libpng): the segmentation overlays and the documentation's images.
#include <cstddef>
#include <cstdint>
#include <filesystem>

#include "sonoshape/core/status.hpp"

namespace sonoshape {

/// How a picture's 8-bit pixels are laid out: one grey level, or blue, green, red (OpenCV's order).
enum class PngPixels { kGrey, kBgr };

/// Writes a picture of width_px × height_px pixels as a PNG file at `path`. Row j starts at
/// first_row + j × row_bytes. The error names the file and libpng's reason (a missing directory,
/// a full disk).
Status write_png(const std::filesystem::path& path, PngPixels pixels, int width_px, int height_px,
                 const std::uint8_t* first_row, std::ptrdiff_t row_bytes);

}  // namespace sonoshape
