#pragma once
// The reconstruction engine's options, shared by `reconstruct` and `scan`: one name, one meaning
// and one range in both (the online engine of a scan is the same engine).
#include <CLI/CLI.hpp>
#include <string>

#include "commands.hpp"
#include "option_checks.hpp"

namespace sonoshape::apps {

/// Where the engine's options are stored (ReconstructionOptions and the command's strings).
struct EngineOptionTargets {
  int& depth;           ///< -1: finest cells about 1/128 of the box diagonal
  int& smoothing;       ///< -1: the field's default
  std::string& field;   ///< "mean-value" / "thin-plate"
  std::string& device;  ///< empty: $SONOSHAPE_DEVICE, else cpu
};

/// Registers --depth, --smoothing (old spelling --smooth), --field and --device on `app`.
inline void add_engine_options(CLI::App& app, const EngineOptionTargets& to) {
  app.add_option("--depth", to.depth,
                 "Octree depth, 1 to 11 (finest cells = largest box side / 2^depth); default: "
                 "finest cells about 1/128 of the box diagonal")
      ->check(number_in(1, 11));
  app.add_option("--smoothing,--smooth", to.smoothing, kSmoothingHelp)->check(number_in(0, 1000));
  app.add_option("--field", to.field, kFieldHelp)
      ->check(CLI::IsMember({"mean-value", "thin-plate"}))
      ->capture_default_str();
  app.add_option("--device", to.device, kDeviceHelp);
}

}  // namespace sonoshape::apps
