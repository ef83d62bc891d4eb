// FESD cost per element on the reference scenes, beside smooth Radau IIA elements of the same
// size, and the overhead of FESD on a scene without effects.
//
//   build/release/bench/fesd_bench
//   build/release/bench/fesd_bench --benchmark_filter=Overhead --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <vector>

#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/scenes/catalog.hpp"

namespace {

// H1, H3: hysteresis by time-freezing (one and two relays).
const char* const kScenes[] = {"F1", "S2", "S3", "H1", "H3"};

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

// A whole FESD run of a reference scene (h = 0.1, N_fe = 2); counters per element.
void BM_FesdScene(benchmark::State& state) {
  const moreau::Scene scene = moreau::MakeScene(kScenes[state.range(0)]);
  moreau::FesdOptions options;
  options.stages = static_cast<int>(state.range(1));
  options.step_size = 0.1;
  options.finite_elements = 2;
  options.record_trajectory = false;
  std::vector<double> iterations;
  long elements = 0, switches = 0;
  for (auto _ : state) {
    const moreau::FesdResult result = moreau::SimulateFesd(scene, options);
    if (result.status != moreau::FesdStatus::kSuccess) {
      state.SkipWithError(result.message.c_str());
      break;
    }
    elements += result.stats.num_elements;
    switches = result.stats.num_switches;
    if (iterations.empty()) {
      for (const moreau::FesdElement& e : result.elements)
        iterations.push_back(e.newton_iterations);
    }
  }
  state.SetLabel(kScenes[state.range(0)]);
  state.counters["elements"] =
      static_cast<double>(elements) / static_cast<double>(state.iterations());
  state.counters["switches"] = static_cast<double>(switches);
  state.counters["time_per_element"] = benchmark::Counter(
      static_cast<double>(elements), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  if (!iterations.empty()) {
    state.counters["newton_per_element_median"] = Median(iterations);
    state.counters["newton_per_element_max"] =
        *std::max_element(iterations.begin(), iterations.end());
  }
}
BENCHMARK(BM_FesdScene)
    ->ArgsProduct({{0, 1, 2, 3, 4}, {2, 3}})
    ->ArgNames({"scene", "stages"})
    ->Unit(benchmark::kMillisecond);

// Smooth Radau IIA elements of the same size (two states plus the clock, h = 0.05) on the
// Hopf scene, for the time per element beside FESD's.
void BM_RadauElement(benchmark::State& state) {
  const moreau::Scene scene = moreau::MakeScene("hopf");
  moreau::RadauOptions options;
  options.stages = static_cast<int>(state.range(0));
  options.step_size = 0.05;
  options.record_trajectory = false;
  long steps = 0, iterations = 0;
  for (auto _ : state) {
    const moreau::RadauResult result = moreau::SimulateRadau(scene, options);
    steps += result.stats.num_steps;
    iterations += result.stats.num_newton_iterations;
  }
  state.counters["time_per_element"] = benchmark::Counter(
      static_cast<double>(steps), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["newton_per_element"] =
      static_cast<double>(iterations) / static_cast<double>(steps);
}
BENCHMARK(BM_RadauElement)->Arg(2)->Arg(3)->ArgName("stages")->Unit(benchmark::kMillisecond);

// FESD against smooth Radau IIA on a scene without effects, interleaved in one run (so that
// both see the same machine load); the counter is the median of the per-iteration time ratios.
// Acceptance: at most 1.1.
void BM_FesdOverheadWithoutEffects(benchmark::State& state) {
  const moreau::Scene scene = moreau::MakeScene("hopf");
  moreau::FesdOptions fesd;
  fesd.stages = static_cast<int>(state.range(0));
  fesd.step_size = 0.02;
  fesd.finite_elements = 1;
  fesd.record_trajectory = false;
  moreau::RadauOptions radau;
  radau.stages = fesd.stages;
  radau.step_size = fesd.step_size;
  radau.record_trajectory = false;
  std::vector<double> ratios, fesd_ms, radau_ms;
  using Clock = std::chrono::steady_clock;
  for (auto _ : state) {
    const auto t0 = Clock::now();
    benchmark::DoNotOptimize(moreau::SimulateFesd(scene, fesd).final_state.data());
    const auto t1 = Clock::now();
    benchmark::DoNotOptimize(moreau::SimulateRadau(scene, radau).final_state.data());
    const auto t2 = Clock::now();
    const double a = std::chrono::duration<double, std::milli>(t1 - t0).count();
    const double b = std::chrono::duration<double, std::milli>(t2 - t1).count();
    fesd_ms.push_back(a);
    radau_ms.push_back(b);
    ratios.push_back(a / b);
  }
  state.counters["fesd_ms"] = Median(fesd_ms);
  state.counters["radau_ms"] = Median(radau_ms);
  state.counters["ratio"] = Median(ratios);
}
BENCHMARK(BM_FesdOverheadWithoutEffects)
    ->Arg(2)
    ->Arg(3)
    ->ArgName("stages")
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
