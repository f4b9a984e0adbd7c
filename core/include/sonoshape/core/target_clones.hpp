#pragma once
// SONOSHAPE_AVX2_CLONES before a function definition: GCC compiles it twice, for AVX2 and for
// the baseline, and picks one at load time through an ifunc resolver.
//
// Not in ThreadSanitizer builds: the dynamic loader runs ifunc resolvers while it relocates the
// program, before the TSan runtime is initialised, and GCC instruments the resolver too, so
// every program linking such a function crashed before main (found by `scripts/test --sanitize
// thread`). There the baseline version is the only one.
#if defined(__SANITIZE_THREAD__)
#define SONOSHAPE_AVX2_CLONES
#else
#define SONOSHAPE_AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#endif
