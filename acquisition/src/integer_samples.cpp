#include "integer_samples.hpp"

namespace sonoshape::acquisition::detail {

std::int64_t integer_sample(const std::uint8_t* data, std::size_t k, const IntegerSamples& type) {
  const int bytes = type.bytes;
  const std::uint8_t* p = data + k * static_cast<std::size_t>(bytes);
  std::uint64_t value = 0;
  for (int b = 0; b < bytes; ++b)
    value |= std::uint64_t(p[type.big_endian ? b : bytes - 1 - b]) << (8 * (bytes - 1 - b));
  if (type.is_signed && bytes < 8 && (value >> (8 * bytes - 1)) != 0)
    value |= ~std::uint64_t{0} << (8 * bytes);
  return static_cast<std::int64_t>(value);
}

std::optional<std::size_t> narrow_to_8_bits(const std::uint8_t* data, std::size_t count,
                                            const IntegerSamples& type, std::uint8_t* out) {
  for (std::size_t k = 0; k < count; ++k) {
    const std::int64_t value = integer_sample(data, k, type);
    if (value < 0 || value > 255) return k;
    out[k] = static_cast<std::uint8_t>(value);
  }
  return std::nullopt;
}

}  // namespace sonoshape::acquisition::detail
