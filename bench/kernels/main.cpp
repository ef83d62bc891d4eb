// Per-step kernels over problem sizes (README "Benchmarks"): lowered-system evaluation,
// linear solves, one semismooth Newton iteration, one SQP iteration of the alpha step.
//   build/release/bench/kernels_bench [--benchmark_filter=Newton]
#include <benchmark/benchmark.h>

BENCHMARK_MAIN();
