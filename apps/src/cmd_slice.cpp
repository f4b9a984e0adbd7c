#include <CLI/CLI.hpp>
#include <iostream>
#include "commands.hpp"
namespace sonoshape::apps {
CommandRunner add_slice_command(CLI::App& app) {
  (void)app;
  return [] { std::cerr << "slice: not implemented yet\n"; return 1; };
}
}  // namespace sonoshape::apps
