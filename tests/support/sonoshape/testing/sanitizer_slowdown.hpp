#pragma once
// How many times slower code runs in this build. Sanitizer builds (scripts/test --sanitize)
// instrument every memory access; a test that bounds a wall time to tell "fast" from "blocked"
// multiplies its bound by this, so that the bound still separates the two.

namespace sonoshape::testing {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr double kSanitizerSlowdown = 10.0;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
inline constexpr double kSanitizerSlowdown = 10.0;
#else
inline constexpr double kSanitizerSlowdown = 1.0;
#endif
#else
inline constexpr double kSanitizerSlowdown = 1.0;
#endif

}  // namespace sonoshape::testing
