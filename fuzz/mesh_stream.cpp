// Fuzz target: the mesh-stream decoder that `listen` runs on every received message
// (docs/formats/mesh-stream.md). The input is a sequence of frames, each a 4-byte little-endian
// length and that many bytes; the last frame takes what is left when its length runs past the
// end, so any input is some message.
#include "sonoshape/publish/mesh_stream.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::publish::Frames frames;
  std::size_t at = 0;
  while (at + 4 <= size) {
    const std::size_t length = std::size_t{data[at]} | std::size_t{data[at + 1]} << 8 |
                               std::size_t{data[at + 2]} << 16 | std::size_t{data[at + 3]} << 24;
    at += 4;
    const std::size_t n = std::min(length, size - at);
    frames.push_back(sonoshape::fuzz::as_string(data + at, n));
    at += n;
  }
  auto message = sonoshape::publish::decode_message(frames);
  // What decodes must encode again (the publisher's checks are the decoder's, mirrored).
  if (message) (void)sonoshape::publish::encode_message(*message);
  return 0;
}
