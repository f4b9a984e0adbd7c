// Fuzz target: the OpenIGTLink decoders that `scan --source igtl:` runs on every message a
// server sends (decode_igtl_image, decode_igtl_transform, decode_igtl_tracking_data).
//
// Input: byte 0 picks the message type (IMAGE, TRANSFORM, TDATA) and whether the header is
// taken from the input as it is (bit 7; the next 58 bytes, then the body) or made for the body
// (the rest of the input) with the right body size and CRC-64, so that mutations reach the
// decoders behind the CRC check instead of stopping at it.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_support.hpp"
#include "igtl_header.h"
#include "igtl_util.h"
#include "sonoshape/acquisition/igtl_client.hpp"

namespace {

using sonoshape::acquisition::IgtlMessage;

constexpr std::array<const char*, 3> kTypes = {"IMAGE", "TRANSFORM", "TDATA"};

void put_u64(std::vector<std::uint8_t>& out, std::size_t at, std::uint64_t value) {
  for (int i = 7; i >= 0; --i)
    out[at + 7 - static_cast<std::size_t>(i)] = (value >> (8 * i)) & 0xFF;
}

// A header as the OpenIGTLink library writes it: version 1, type, device "fuzz", no timestamp,
// the body's size and CRC-64 (big-endian).
std::vector<std::uint8_t> made_message(const char* type, const std::uint8_t* body,
                                       std::size_t size) {
  std::vector<std::uint8_t> bytes(IGTL_HEADER_SIZE, 0);
  bytes[1] = 1;
  for (std::size_t i = 0; type[i]; ++i) bytes[2 + i] = static_cast<std::uint8_t>(type[i]);
  const std::string device = "fuzz";
  for (std::size_t i = 0; i < device.size(); ++i)
    bytes[14 + i] = static_cast<std::uint8_t>(device[i]);
  put_u64(bytes, 42, size);
  bytes.insert(bytes.end(), body, body + size);
  put_u64(bytes, 50, ::crc64(bytes.data() + IGTL_HEADER_SIZE, size, 0));
  return bytes;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::quiet_logs();
  if (size < 1) return 0;
  const std::uint8_t mode = data[0];
  const char* type = kTypes[(mode & 0x7F) % kTypes.size()];
  IgtlMessage message;
  message.type = type;
  message.device = "fuzz";
  if (mode & 0x80)
    message.bytes.assign(data + 1, data + size);  // the header as the input has it
  else
    message.bytes = made_message(type, data + 1, size - 1);
  sonoshape::acquisition::IgtlDrop why{};
  if (message.type == "IMAGE") {
    auto image = sonoshape::acquisition::decode_igtl_image(message, &why);
    // A decoded image holds exactly the pixels it declares.
    if (image && image->image.pixels.size() !=
                     static_cast<std::size_t>(image->image.width) * image->image.height)
      __builtin_trap();
    sonoshape::fuzz::explain(image ? "IMAGE " + std::to_string(image->image.width) + "x" +
                                         std::to_string(image->image.height)
                                   : image.message());
  } else if (message.type == "TRANSFORM") {
    auto matrix = sonoshape::acquisition::decode_igtl_transform(message);
    sonoshape::fuzz::explain(matrix ? "TRANSFORM" : matrix.message());
  } else {
    auto matrix = sonoshape::acquisition::decode_igtl_tracking_data(message, "Probe");
    sonoshape::fuzz::explain(!matrix   ? matrix.message()
                             : *matrix ? "TDATA with Probe"
                                       : "TDATA without Probe");
  }
  return 0;
}
