#pragma once
// Minimal logging to stderr and a progress line for work that takes more than a second.
#include <chrono>
#include <string>

namespace sonoshape {

enum class LogLevel { kQuiet = 0, kWarning = 1, kInfo = 2, kDebug = 3 };

void set_log_level(LogLevel level);
LogLevel log_level();
void log_warning(const std::string& message);
void log_info(const std::string& message);
void log_debug(const std::string& message);

/// Prints "label: done/total" on stderr at most a few times a second, only once the work has run
/// for more than a second (so quick runs stay silent). Thread-compatible, not thread-safe.
class Progress {
 public:
  Progress(std::string label, std::size_t total);
  ~Progress();
  void update(std::size_t done);
  void finish();

 private:
  std::string label_;
  std::size_t total_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_print_;
  bool printed_ = false;
  bool finished_ = false;
};

/// Wall-clock stopwatch in seconds.
class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  void reset() { start_ = std::chrono::steady_clock::now(); }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// Peak resident set size of this process in MiB (Linux: VmHWM), or 0 when unknown.
double peak_rss_mb();

}  // namespace sonoshape
