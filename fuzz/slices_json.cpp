// Fuzz target: the slice-set JSON reader (docs/formats/slices.md), in memory.
#include <cstddef>
#include <cstdint>

#include "fuzz_support.hpp"
#include "sonoshape/core/slice_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::quiet_logs();
  const auto text = sonoshape::fuzz::as_string(data, size);
  // The lenient reader repairs what it can; the strict one refuses instead: both paths.
  (void)sonoshape::parse_slice_set_json(text, "fuzz.slices.json");
  (void)sonoshape::parse_slice_set_json(text, "fuzz.slices.json", sonoshape::ReadOptions{true});
  return 0;
}
