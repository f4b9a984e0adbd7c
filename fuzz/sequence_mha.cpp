// Fuzz target: MetaImage sequence files (`.mha`, `.igs.mha`; docs/formats/sequences.md).
#include <cstddef>
#include <cstdint>

#include "sequence_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::read_sequence(sonoshape::fuzz::as_string(data, size), ".igs.mha");
  return 0;
}
