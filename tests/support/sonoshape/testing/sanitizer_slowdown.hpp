#pragma once
// Whether this build runs under a sanitizer (scripts/test --sanitize), and how many times slower
// code runs then. Sanitizer builds instrument every memory access, and reserve terabytes of
// address space for their shadow memory: a test that bounds a wall time to tell "fast" from
// "blocked" multiplies its bound by kSanitizerSlowdown, and a test that limits a child's address
// space limits its allocations through the sanitizer's allocator instead.

namespace sonoshape::testing {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr bool kSanitizerBuild = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
inline constexpr bool kSanitizerBuild = true;
#else
inline constexpr bool kSanitizerBuild = false;
#endif
#else
inline constexpr bool kSanitizerBuild = false;
#endif

inline constexpr double kSanitizerSlowdown = kSanitizerBuild ? 10.0 : 1.0;

}  // namespace sonoshape::testing
