#pragma once
// Integer samples wider than 8 bits, narrowed to 8 bits when every value lies in 0..255: an 8-bit
// image saved as `short` (NRRD sequences), a labelmap that 3D Slicer sends in its own scalar type
// over OpenIGTLink (private to acquisition/).
#include <cstddef>
#include <cstdint>
#include <optional>

namespace sonoshape::acquisition::detail {

/// How the samples are stored: 1, 2, 4 or 8 bytes each, signed or not, in either byte order.
struct IntegerSamples {
  int bytes = 1;
  bool is_signed = false;
  bool big_endian = false;
};

/// Sample k of `data`, sign-extended where signed.
std::int64_t integer_sample(const std::uint8_t* data, std::size_t k, const IntegerSamples& type);

/// Writes `count` samples of `data` into `out` as 8-bit values. Returns the index of the first
/// sample outside 0..255 (then `out` is incomplete), or nothing when all fit.
std::optional<std::size_t> narrow_to_8_bits(const std::uint8_t* data, std::size_t count,
                                            const IntegerSamples& type, std::uint8_t* out);

}  // namespace sonoshape::acquisition::detail
