// Fuzz target: PLUS configuration XML (<CoordinateDefinitions>, ImageToProbe).
#include "sonoshape/acquisition/plus_config.hpp"

#include <cstddef>
#include <cstdint>

#include "fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  sonoshape::fuzz::quiet_logs();
  const auto path =
      sonoshape::fuzz::write_scratch_file(sonoshape::fuzz::as_string(data, size), ".xml");
  if (auto config = sonoshape::acquisition::read_plus_config(path)) {
    for (const auto& t : config->transforms) (void)config->transform(t.to, t.from);
  }
  (void)sonoshape::acquisition::read_image_to_probe(path);
  return 0;
}
