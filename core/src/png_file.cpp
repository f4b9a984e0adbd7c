#include "sonoshape/core/png_file.hpp"

#include <png.h>

#include <string>

namespace sonoshape {

Status write_png(const std::filesystem::path& path, PngPixels pixels, int width_px, int height_px,
                 const std::uint8_t* first_row, std::ptrdiff_t row_bytes) {
  if (width_px <= 0 || height_px <= 0 || first_row == nullptr)
    return Status::error("PNG " + path.string() + ": the picture is empty (" +
                         std::to_string(width_px) + "x" + std::to_string(height_px) + ")");
  // libpng's simplified API: it frees its own state on success and on failure alike.
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width_px);
  image.height = static_cast<png_uint_32>(height_px);
  image.format = pixels == PngPixels::kGrey ? PNG_FORMAT_GRAY : PNG_FORMAT_BGR;
  // The row stride counts components, which are bytes at 8 bits per channel.
  if (png_image_write_to_file(&image, path.c_str(), 0, first_row,
                              static_cast<png_int_32>(row_bytes), nullptr) == 0)
    return Status::error("cannot write PNG " + path.string() + ": " + image.message +
                         " (check that the directory exists, is writable and has space)");
  return Status::ok();
}

}  // namespace sonoshape
