// Fuzz target: the segmentation configuration JSON (docs/segmentation.md), in memory.
#include <cstddef>
#include <cstdint>

#include "fuzz_support.hpp"
#include "sonoshape/segmentation/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::quiet_logs();
  auto config = sonoshape::segmentation::parse_segmentation_config(
      sonoshape::fuzz::as_string(data, size), "fuzz.json");
  if (config) {
    (void)config->validate();
    (void)config->effective_shadow_grey();
    // What is accepted must write back to JSON that reads again.
    (void)sonoshape::segmentation::parse_segmentation_config(
        sonoshape::segmentation::to_json(*config), "fuzz.json");
  }
  return 0;
}
