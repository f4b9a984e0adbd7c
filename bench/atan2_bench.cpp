// fast_atan2 against std::atan2 (recon/src/atan2.hpp states the speed-up): both over the same
// 4096 pairs of random magnitudes and signs, the mix the mean-value edge terms see.
//
//   build/bench/sonoshape_atan2_bench
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "atan2.hpp"

namespace {

struct Pairs {
  std::vector<double> y, x;
  Pairs() {
    std::mt19937_64 rng(1);
    std::normal_distribution<double> normal(0.0, 1.0);
    std::uniform_real_distribution<double> exponent(-6.0, 6.0);
    for (int i = 0; i < 4096; ++i) {
      y.push_back(normal(rng) * std::pow(10.0, exponent(rng)));
      x.push_back(normal(rng) * std::pow(10.0, exponent(rng)));
    }
  }
};

const Pairs& pairs() {
  static const Pairs p;
  return p;
}

template <double (*Atan2)(double, double)>
void run(benchmark::State& state) {
  const Pairs& p = pairs();
  for (auto _ : state) {
    double sum = 0.0;
    for (std::size_t i = 0; i < p.y.size(); ++i) sum += Atan2(p.y[i], p.x[i]);
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(p.y.size()));
}

double library_atan2(double y, double x) { return std::atan2(y, x); }

BENCHMARK(run<library_atan2>)->Name("std::atan2");
BENCHMARK(run<sonoshape::recon::fast_atan2>)->Name("fast_atan2");

}  // namespace

BENCHMARK_MAIN();
