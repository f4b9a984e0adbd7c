#pragma once
// Reading a JSON file a command wrote (scan.json, summary.json, reports) in the tests.
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

namespace sonoshape::testing {

/// The parsed file; throws nlohmann::json::parse_error (the test fails naming it) when the file
/// is missing or not JSON.
inline nlohmann::json read_json(const std::filesystem::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

}  // namespace sonoshape::testing
