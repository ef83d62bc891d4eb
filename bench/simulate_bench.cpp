// Cost of the one entry point (moreau::Simulate) against the integrator's own function, on a
// 1-element FESD run of S3 (h = tf = 0.05, N_fe = 1): the C++ side of the Python calling-
// overhead comparison (scripts/bench-python runs this and bench/python_overhead.py).
//
//   build/release/bench/simulate_bench --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/catalog.hpp"

namespace {

// The scene and settings bench/python_overhead.py uses.
moreau::Scene OneElementScene() {
  moreau::Scene scene = moreau::MakeScene("S3");
  moreau::SetSceneValue(&scene, "tf", 0.05);
  return scene;
}

void BM_FesdOneElementDirect(benchmark::State& state) {
  const moreau::Scene scene = OneElementScene();
  moreau::FesdOptions options;
  options.step_size = 0.05;
  options.finite_elements = 1;
  for (auto _ : state) {
    const moreau::FesdResult result = moreau::SimulateFesd(scene, options);
    if (result.status != moreau::FesdStatus::kSuccess) state.SkipWithError(result.message.c_str());
    benchmark::DoNotOptimize(result.final_state.data());
  }
}
BENCHMARK(BM_FesdOneElementDirect)->Unit(benchmark::kMicrosecond);

void BM_FesdOneElementSimulate(benchmark::State& state) {
  const moreau::Scene scene = OneElementScene();
  const moreau::SimulationSettings settings{"fesd", {{"h", 0.05}, {"fe", 1L}}};
  for (auto _ : state) {
    const moreau::SimulationResult result = moreau::Simulate(scene, settings);
    if (!result.success) state.SkipWithError(result.message.c_str());
    benchmark::DoNotOptimize(result.final_state.data());
  }
}
BENCHMARK(BM_FesdOneElementSimulate)->Unit(benchmark::kMicrosecond);

void BM_FesdOneElementSimulator(benchmark::State& state) {
  moreau::Simulator simulator(OneElementScene(), {"fesd", {{"h", 0.05}, {"fe", 1L}}});
  for (auto _ : state) {
    const moreau::SimulationResult result = simulator.Run();
    if (!result.success) state.SkipWithError(result.message.c_str());
    benchmark::DoNotOptimize(result.final_state.data());
  }
}
BENCHMARK(BM_FesdOneElementSimulator)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
