#pragma once
// Checks of option values that CLI11 does not have.
#include <CLI/CLI.hpp>
#include <charconv>
#include <cmath>
#include <string>

namespace sonoshape::apps {

/// A finite number: CLI11's range checks let "nan" through (every comparison with NaN is
/// false), and "inf" where the range is open.
inline const CLI::Validator kFiniteNumber(
    [](std::string& value) -> std::string {
      double number = 0.0;
      const char* begin = value.data() + (!value.empty() && value[0] == '+');  // from_chars: no '+'
      const char* end = value.data() + value.size();
      const auto [at, ec] = std::from_chars(begin, end, number);
      if (ec != std::errc() || at != end || !std::isfinite(number))
        return "'" + value + "' is not a finite number";
      return {};
    },
    "FINITE");

}  // namespace sonoshape::apps
