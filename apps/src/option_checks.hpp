#pragma once
// Checks of option values that CLI11 does not have.
#include <CLI/CLI.hpp>
#include <charconv>
#include <cmath>
#include <sstream>
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

namespace option_detail {

inline bool parse_finite(const std::string& value, double& number) {
  const char* begin = value.data() + (!value.empty() && value[0] == '+');  // from_chars: no '+'
  const char* end = value.data() + value.size();
  const auto [at, ec] = std::from_chars(begin, end, number);
  return ec == std::errc() && at == end && std::isfinite(number);
}

inline std::string shown(double number) {
  std::ostringstream text;
  text << number;
  return text.str();
}

}  // namespace option_detail

/// A finite number above `min` (`exclusive`) or from `min` on. CLI11's PositiveNumber and
/// NonNegativeNumber let "nan" through (every comparison with NaN is false) and print their open
/// bound as 309 digits; this says "'-1' is not a number >= 0".
inline CLI::Validator number_from(double min, bool exclusive) {
  const std::string bound = (exclusive ? "> " : ">= ") + option_detail::shown(min);
  return CLI::Validator(
      [min, exclusive, bound](std::string& value) -> std::string {
        double number = 0.0;
        if (!option_detail::parse_finite(value, number) || number < min ||
            (exclusive && number == min))
          return "'" + value + "' is not a number " + bound;
        return {};
      },
      min != 0.0  ? "NUMBER " + bound
      : exclusive ? "POSITIVE"
                  : "NONNEGATIVE");
}

/// A finite number from `min` to `max`: CLI11's Range lets "nan" through.
inline CLI::Validator number_in(double min, double max) {
  const std::string range = option_detail::shown(min) + " to " + option_detail::shown(max);
  return CLI::Validator(
      [min, max, range](std::string& value) -> std::string {
        double number = 0.0;
        if (!option_detail::parse_finite(value, number) || number < min || number > max)
          return "'" + value + "' is not a number from " + range;
        return {};
      },
      "in [" + range + "]");
}

inline const CLI::Validator kPositiveNumber = number_from(0.0, true);
inline const CLI::Validator kNonNegativeNumber = number_from(0.0, false);

}  // namespace sonoshape::apps
