#include "sonoshape/core/log.hpp"

#include <atomic>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <mutex>

namespace sonoshape {
namespace {
std::atomic<LogLevel> g_level{LogLevel::kWarning};
std::mutex g_mutex;
void emit(const char* prefix, const std::string& message) {
  std::lock_guard<std::mutex> lock(g_mutex);
  std::cerr << prefix << message << '\n';
}
}  // namespace

void set_log_level(LogLevel level) { g_level = level; }
LogLevel log_level() { return g_level; }
void log_warning(const std::string& m) {
  if (g_level >= LogLevel::kWarning) emit("warning: ", m);
}
void log_info(const std::string& m) {
  if (g_level >= LogLevel::kInfo) emit("", m);
}
void log_debug(const std::string& m) {
  if (g_level >= LogLevel::kDebug) emit("debug: ", m);
}

Progress::Progress(std::string label, std::size_t total)
    : label_(std::move(label)),
      total_(total),
      start_(std::chrono::steady_clock::now()),
      last_print_(start_) {}

Progress::~Progress() { finish(); }

void Progress::update(std::size_t done) {
  if (g_level == LogLevel::kQuiet) return;
  const auto now = std::chrono::steady_clock::now();
  if (now - start_ < std::chrono::seconds(1)) return;
  if (printed_ && now - last_print_ < std::chrono::milliseconds(250)) return;
  last_print_ = now;
  printed_ = true;
  std::lock_guard<std::mutex> lock(g_mutex);
  std::fprintf(stderr, "\r%s: %zu/%zu", label_.c_str(), done, total_);
  std::fflush(stderr);
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  if (printed_) {
    std::lock_guard<std::mutex> lock(g_mutex);
    std::fprintf(stderr, "\r%s: %zu/%zu done in %.1f s\n", label_.c_str(), total_, total_,
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
  }
}

double peak_rss_mb() {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == "VmHWM:") {
      double kib = 0.0;
      status >> kib;
      return kib / 1024.0;
    }
    std::string rest;
    std::getline(status, rest);
  }
  return 0.0;
}

}  // namespace sonoshape
