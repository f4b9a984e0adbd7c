#pragma once
// What a live scan is doing: the pipeline's status reports and the mesh stream's `status`
// messages (docs/formats/mesh-stream.md) say it with the same words.
#include <string_view>

namespace sonoshape {

enum class ScanState {
  kScanning,  ///< frames are coming in
  kIdle,      ///< no source is delivering (ended); the meshes are final
  kError,     ///< something failed (see the message); the scan goes on with what it has
};

/// "scanning", "idle" or "error".
constexpr std::string_view to_string(ScanState state) {
  switch (state) {
    case ScanState::kScanning:
      return "scanning";
    case ScanState::kIdle:
      return "idle";
    case ScanState::kError:
      return "error";
  }
  return "error";
}

}  // namespace sonoshape
