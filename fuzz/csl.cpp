// Fuzz target: the `.csl` contour-slice reader (docs/formats/csl.md), in memory.
#include <cstddef>
#include <cstdint>

#include "fuzz_support.hpp"
#include "sonoshape/core/slice_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::quiet_logs();
  const auto text = sonoshape::fuzz::as_string(data, size);
  (void)sonoshape::parse_csl(text, "fuzz.csl");
  (void)sonoshape::parse_csl(text, "fuzz.csl", sonoshape::ReadOptions{true});
  return 0;
}
