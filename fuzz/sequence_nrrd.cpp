// Fuzz target: NRRD sequence files (`.seq.nrrd`, `.igs.nrrd`; docs/formats/sequences.md).
#include <cstddef>
#include <cstdint>

#include "sequence_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::read_sequence(sonoshape::fuzz::as_string(data, size), ".seq.nrrd");
  return 0;
}
