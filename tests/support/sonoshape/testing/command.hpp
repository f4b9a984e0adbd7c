#pragma once
// Running the `sonoshape` command (and peer programs) from a test.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

namespace sonoshape::testing {

/// The whole text of a file ("" when it cannot be read).
inline std::string file_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// Starts `command` in the background through sh (exec'd, so that signals reach the program
/// itself) with its stdout and stderr in `log`. Returns its pid.
inline pid_t spawn(const std::string& command, const std::filesystem::path& log) {
  const std::string line = "exec " + command + " > " + log.string() + " 2>&1";
  const pid_t pid = fork();
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", line.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

/// Waits up to `timeout_s` for `pid`, then sends `signal_on_timeout` and waits for it to end.
/// Returns its exit code, or -1 when a signal ended it.
inline int wait_exit(pid_t pid, double timeout_s, int signal_on_timeout = SIGKILL) {
  int status = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > end) {
      kill(pid, signal_on_timeout);
      waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

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
