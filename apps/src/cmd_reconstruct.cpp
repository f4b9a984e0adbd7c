#include <CLI/CLI.hpp>
#include <iostream>
#include "commands.hpp"
namespace sonoshape::apps {
CommandRunner add_reconstruct_command(CLI::App& app) {
  (void)app;
  return [] { std::cerr << "reconstruct: not implemented yet\n"; return 1; };
}
}  // namespace sonoshape::apps
