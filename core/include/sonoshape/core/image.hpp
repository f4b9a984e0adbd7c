#pragma once
// 8-bit images as plain values: B-mode frames and label maps (no OpenCV in public headers).
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace sonoshape {

/// A single-channel 8-bit image, row-major: pixel (column i, row j) is pixels[j * width + i].
/// Row 0 is the top of the image (for ultrasound: the transducer side).
struct ImageU8 {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  ///< width * height values

  ImageU8() = default;
  /// A width x height image filled with `value`. Throws std::invalid_argument on negative sizes.
  ImageU8(int width_px, int height_px, std::uint8_t value = 0)
      : width(width_px), height(height_px) {
    if (width_px < 0 || height_px < 0) throw std::invalid_argument("ImageU8: negative size");
    pixels.assign(static_cast<std::size_t>(width_px) * static_cast<std::size_t>(height_px), value);
  }

  bool empty() const { return pixels.empty(); }
  std::size_t size() const { return pixels.size(); }
  std::uint8_t& at(int i, int j) { return pixels[static_cast<std::size_t>(j) * width + i]; }
  std::uint8_t at(int i, int j) const { return pixels[static_cast<std::size_t>(j) * width + i]; }
  bool operator==(const ImageU8&) const = default;
};

/// Grey levels of a B-mode image (0 black .. 255 white).
using GreyImage = ImageU8;

/// Per-pixel material labels: kLabelPixelOutside, material ids 1..254, or kLabelPixelUnknown.
using LabelImage = ImageU8;

/// Label-image value of pixels outside every material (the null material, slice.hpp's
/// kOutsideLabel).
constexpr std::uint8_t kLabelPixelOutside = 0;
/// Label-image value of pixels whose content is not known: outside the sector, in a shadow
/// (slice.hpp's kUnknownLabel).
constexpr std::uint8_t kLabelPixelUnknown = 255;
/// Largest material id a label image can hold.
constexpr int kMaxPixelLabel = 254;

}  // namespace sonoshape
