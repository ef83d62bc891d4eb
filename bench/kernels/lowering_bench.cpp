// Residual and Jacobian assembly of the lowered system (LoweredSystem::Evaluate), the kernel
// every collocation stage of every step calls, over problem sizes.
#include <benchmark/benchmark.h>

#include "family.hpp"
#include "moreau/model/lowered_system.hpp"

namespace moreau::bench {
namespace {

// One evaluation of F, G, A, B at a point with half of the multipliers positive; with
// derivatives (Derivatives::kStates: F_y, F_z, A_y, ..., including the second derivatives of
// the gradient form) or values only.
void Evaluate(benchmark::State& state, Derivatives derivatives) {
  const int n = static_cast<int>(state.range(0));
  const LoweredSystem system(MovingIntervals(n));
  Vector y = system.InitialState();
  y[system.clock_index()] = 0.3;
  Vector z = Vector::Zero(system.num_algebraic());
  for (int k = 0; k < z.size(); k += 2) z[k] = 0.1;
  PointEvaluation out;
  for (auto _ : state) {
    system.Evaluate(y, z, derivatives, &out);
    benchmark::DoNotOptimize(out.F.data());
  }
  state.counters["states"] = system.num_states();
  state.counters["algebraic"] = system.num_algebraic();
}

void BM_LoweredEvaluateWithJacobian(benchmark::State& state) {
  Evaluate(state, Derivatives::kStates);
}
void BM_LoweredEvaluateValues(benchmark::State& state) { Evaluate(state, Derivatives::kNone); }

BENCHMARK(BM_LoweredEvaluateWithJacobian)->RangeMultiplier(4)->Range(1, 256)->ArgName("n");
BENCHMARK(BM_LoweredEvaluateValues)->RangeMultiplier(4)->Range(1, 256)->ArgName("n");

}  // namespace
}  // namespace moreau::bench
