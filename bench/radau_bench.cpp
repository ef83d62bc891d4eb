// Cost of the smooth Radau IIA integrator per step, over stages and problem sizes.
#include <benchmark/benchmark.h>

#include "moreau/integrators/radau.hpp"
#include "moreau/scenes/catalog.hpp"

namespace {

// Whole fixed-step run on the Hopf scene (200 steps of h = 0.01); reports time per step.
void BM_RadauHopfFixedStep(benchmark::State& state) {
  const moreau::Scene scene = moreau::MakeScene("hopf");
  moreau::RadauOptions options;
  options.stages = static_cast<int>(state.range(0));
  options.step_size = 0.01;
  options.record_trajectory = false;
  long steps = 0, iterations = 0;
  for (auto _ : state) {
    const moreau::RadauResult result = moreau::SimulateRadau(scene, options);
    steps += result.stats.num_steps;
    iterations += result.stats.num_newton_iterations;
    benchmark::DoNotOptimize(result.final_state.data());
  }
  state.counters["steps"] = benchmark::Counter(
      static_cast<double>(steps), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["newton_per_step"] = static_cast<double>(iterations) / static_cast<double>(steps);
}
BENCHMARK(BM_RadauHopfFixedStep)->DenseRange(1, 5)->Unit(benchmark::kMillisecond);

// Sparse path: one step of the 2000-state heat equation.
void BM_RadauHeatSparseStep(benchmark::State& state) {
  moreau::Scene scene = moreau::MakeScene("heat");
  moreau::SetSceneValue(&scene, "tf", 1e-3);
  moreau::RadauOptions options;
  options.stages = static_cast<int>(state.range(0));
  options.step_size = 1e-3;
  options.record_trajectory = false;
  options.linear_solver = moreau::LinearSolverKind::kSparseLu;
  for (auto _ : state) {
    const moreau::RadauResult result = moreau::SimulateRadau(scene, options);
    benchmark::DoNotOptimize(result.final_state.data());
  }
}
BENCHMARK(BM_RadauHeatSparseStep)->DenseRange(1, 3)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
