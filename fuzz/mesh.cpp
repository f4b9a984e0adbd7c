// Fuzz target: the mesh reader (PLY ascii/binary, OBJ, OFF, STL ascii/binary). The reader picks
// the format by extension, so the first input byte picks it ('0' PLY, '1' OBJ, '2' OFF, '3' STL,
// any byte by its value modulo 4) and the rest is the file.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "fuzz_support.hpp"
#include "sonoshape/core/mesh_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  sonoshape::fuzz::quiet_logs();
  constexpr std::array<std::string_view, 4> kExtensions = {".ply", ".obj", ".off", ".stl"};
  const auto path = sonoshape::fuzz::write_scratch_file(
      sonoshape::fuzz::as_string(data + 1, size - 1), kExtensions[data[0] % 4]);
  if (auto mesh = sonoshape::read_mesh(path, /*allow_empty=*/true)) {
    sonoshape::orient_outward(*mesh);
  }
  return 0;
}
