// IDA on large sparse scenes (docs/ida.md, "Linear algebra"): CPU time per internal step on the
// crowd (docs/crowd-motion.md) of N = 100, 1000 and 10^4 agents (2N states, about 12 N
// complementarity pairs), stored sparse and factorized by KLU (the automatic choice).
//
//  - BM_IdaCrowdFree: the horizon [0, 0.5], before any contact (the first is made at t = 1.5):
//    steps of the whole system (every pair's derivatives, the full KLU refactorization)
//    without events.
//  - BM_IdaCrowdContacts: the horizon [0, 2], in which the first contacts form (agents reach
//    the jambs and each other): events, status decisions, projections and KLU analyses of new
//    patterns included.
//
// Time per step: thread CPU time between the first and the last internal step (IDA's progress
// callback, once per step) over the steps in between, so that the set-up (lowering, sparsity
// detection and colouring of the derivatives) and the first decision are not counted.
//
//   build/release/bench/ida_bench
//   scripts/bench-ida   (runs it and prints time per step against N and the log-log slope)
#include <benchmark/benchmark.h>

#include "moreau/core/clock.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/scenes/crowd.hpp"

namespace {

// Horizons: before the first contact (t = 1.5, a front agent reaches a jamb), and after it.
constexpr double kFreeHorizon = 0.5;
constexpr double kContactHorizon = 2.0;

void IdaCrowd(benchmark::State& state, double horizon) {
  moreau::CrowdOptions crowd;
  crowd.agents = static_cast<int>(state.range(0));
  crowd.final_time = horizon;
  const moreau::Scene scene = moreau::MakeCrowdScene(crowd);
  moreau::IdaOptions options;
  options.record_steps = false;  // the trajectory would hold 12 N values per step
  double stepping_seconds = 0.0, setup_seconds = 0.0;
  long timed_steps = 0;
  moreau::IdaStats stats;
  for (auto _ : state) {
    long calls = 0;
    const double start = moreau::ThreadCpuSeconds();
    double first = start, last = start;
    const moreau::IdaResult result = moreau::SimulateIda(scene, options, [&](double) {
      const double now = moreau::ThreadCpuSeconds();
      if (calls++ == 0) first = now;
      last = now;
    });
    if (result.status != moreau::IdaStatus::kSuccess) {
      state.SkipWithError(result.message.c_str());
      break;
    }
    stepping_seconds += last - first;
    setup_seconds += first - start;
    timed_steps += calls - 1;
    stats = result.stats;
  }
  const double runs = static_cast<double>(state.iterations());
  state.counters["agents"] = crowd.agents;
  const moreau::CrowdLayout layout = moreau::MakeCrowdLayout(crowd);
  state.counters["pairs"] = static_cast<double>(layout.pairs.size() + layout.walls.size());
  state.counters["steps"] = static_cast<double>(stats.num_steps);
  state.counters["events"] = static_cast<double>(stats.num_events);
  state.counters["jacobians"] = static_cast<double>(stats.num_jacobian_evaluations);
  state.counters["residuals"] = static_cast<double>(stats.num_residual_evaluations);
  state.counters["klu_analyses"] = static_cast<double>(stats.num_symbolic_analyses);
  state.counters["ms_per_step"] =
      timed_steps > 0 ? 1e3 * stepping_seconds / static_cast<double>(timed_steps) : 0.0;
  state.counters["setup_s"] = setup_seconds / runs;
}
void BM_IdaCrowdFree(benchmark::State& state) { IdaCrowd(state, kFreeHorizon); }
void BM_IdaCrowdContacts(benchmark::State& state) { IdaCrowd(state, kContactHorizon); }

BENCHMARK(BM_IdaCrowdFree)
    ->ArgName("N")
    ->Arg(100)
    ->Arg(1000)
    ->Arg(10000)
    ->Iterations(1)
    ->Unit(benchmark::kSecond);
// N = 10^4 to t = 2 is the long one (scripts/bench-ida runs it only with --large).
BENCHMARK(BM_IdaCrowdContacts)
    ->ArgName("N")
    ->Arg(100)
    ->Arg(1000)
    ->Arg(10000)
    ->Iterations(1)
    ->Unit(benchmark::kSecond);

}  // namespace

BENCHMARK_MAIN();
