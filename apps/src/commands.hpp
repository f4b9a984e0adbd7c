#pragma once
// Subcommands of the `sonoshape` command. Each registers its options on the CLI11 app and
// returns the callback that runs it (exit code 0 on success).
#include <functional>
#include <iostream>
#include <string>
#include <vector>

namespace CLI {
class App;
}

namespace sonoshape::apps {

using CommandRunner = std::function<int()>;

/// The command line as main() received it (argv[0] included), for a command that records how
/// it was started (`scan` in its journal).
const std::vector<std::string>& command_line();

/// Prints "error: MESSAGE" on stderr and returns a command's failure exit code (1).
inline int print_error(const std::string& message) {
  std::cerr << "error: " << message << '\n';
  return 1;
}

CommandRunner add_reconstruct_command(CLI::App& app);
CommandRunner add_slice_command(CLI::App& app);
CommandRunner add_evaluate_command(CLI::App& app);
CommandRunner add_simulate_command(CLI::App& app);
CommandRunner add_segment_command(CLI::App& app);
CommandRunner add_scan_command(CLI::App& app);
CommandRunner add_listen_command(CLI::App& app);
CommandRunner add_devices_command(CLI::App& app);
CommandRunner add_view_command(CLI::App& app);
CommandRunner add_keys_command(CLI::App& app);

/// The help text of --field (reconstruct, scan) and the field a command uses by default.
extern const char* const kFieldHelp;
extern const char* const kDefaultField;

/// The help text of --smooth (reconstruct) and --smoothing (scan).
extern const char* const kSmoothingHelp;

/// The help text of --device (reconstruct, scan).
extern const char* const kDeviceHelp;
/// The device the engine uses for `option` (--device; empty: SONOSHAPE_DEVICE, else cpu), as
/// ReconstructionOptions::device spells it: an OpenCL device is opened once here, so that a
/// missing device or one without fp64 is reported before any work ("auto" without a GPU is
/// "cpu"). Only the mean-value field has a device path: with `field` "thin-plate" an explicit
/// --device other than cpu is refused, and SONOSHAPE_DEVICE is noted and left aside. Throws
/// sonoshape::Error with the fix.
std::string resolve_device(const std::string& option, const std::string& field);

}  // namespace sonoshape::apps
