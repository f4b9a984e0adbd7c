#pragma once
// Running the `sonoshape` command from a test.
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace sonoshape::testing {

struct CommandResult {
  int exit_code = -1;
  std::string output;  ///< stdout and stderr together
};

/// Runs `program arguments` through the shell with its output captured in `log` (a file path).
inline CommandResult run_command(const std::string& program, const std::string& arguments,
                                 const std::filesystem::path& log) {
  const std::string command = program + " " + arguments + " > " + log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  CommandResult result;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(log);
  std::stringstream text;
  text << in.rdbuf();
  result.output = text.str();
  return result;
}

}  // namespace sonoshape::testing
