// The `sonoshape` command: parses options and dispatches to one subcommand.
#include <CLI/CLI.hpp>
#include <csignal>
#include <exception>
#include <iostream>

#include "commands.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::apps {
namespace {
std::vector<std::string> g_command_line;
}
const std::vector<std::string>& command_line() { return g_command_line; }
}  // namespace sonoshape::apps

int main(int argc, char** argv) {
  sonoshape::apps::g_command_line.assign(argv, argv + argc);
  // A file-size limit (ulimit -f) must fail a write like a full disk, with the writer's message
  // naming the file, instead of killing the command without a word.
  std::signal(SIGXFSZ, SIG_IGN);
  CLI::App app{"sonoshape: reconstruction of 3D surfaces from arbitrary cross-sections"};
  app.require_subcommand(1);
  app.fallthrough();  // global flags may follow the subcommand
  bool verbose = false;
  bool quiet = false;
  app.add_flag("-v,--verbose", verbose, "Print progress details on stderr");
  app.add_flag("-q,--quiet", quiet, "Print errors only");

  struct Entry {
    CLI::App* sub;
    sonoshape::apps::CommandRunner run;
  };
  std::vector<Entry> commands;
  auto add = [&](const char* name, const char* help, auto adder) {
    CLI::App* sub = app.add_subcommand(name, help);
    commands.push_back({sub, adder(*sub)});
  };
  add("reconstruct", "Reconstruct closed surfaces from a slice set (.slices.json or .csl)",
      sonoshape::apps::add_reconstruct_command);
  add("slice", "Cut closed meshes with planes into a slice set (ground truth for tests)",
      sonoshape::apps::add_slice_command);
  add("evaluate", "Score reconstructed meshes against ground-truth meshes",
      sonoshape::apps::add_evaluate_command);
  add("simulate", "Simulate a tracked freehand ultrasound sweep of a virtual patient (.igs.mha)",
      sonoshape::apps::add_simulate_command);
  add("segment", "Segment a tracked sweep (.igs.mha) into a slice set (one slice per frame)",
      sonoshape::apps::add_segment_command);
  add("scan", "Live scan: frames and poses from a source, reconstructed as they come",
      sonoshape::apps::add_scan_command);
  add("listen", "Receive a live mesh stream, check it against the format and record it",
      sonoshape::apps::add_listen_command);
  add("view", "Show a live mesh stream in the browser: serves a page and relays the stream to it",
      sonoshape::apps::add_view_command);
  add("keys", "Make a CURVE key pair (NAME.key, NAME.pub) that encrypts a mesh stream",
      sonoshape::apps::add_keys_command);
  add("devices",
      "List the frame grabbers, trackers and OpenCL devices attached, each as the option to paste",
      sonoshape::apps::add_devices_command);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  sonoshape::set_log_level(quiet     ? sonoshape::LogLevel::kQuiet
                           : verbose ? sonoshape::LogLevel::kDebug
                                     : sonoshape::LogLevel::kInfo);
  try {
    for (const Entry& c : commands)
      if (c.sub->parsed()) return c.run();
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << '\n';
    return 1;
  }
  return 1;
}
