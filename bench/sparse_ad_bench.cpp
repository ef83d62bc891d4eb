// Sparse exact derivatives against problem size (docs/sparse-derivatives.md): a crowd-like
// constraint function |q_i - q_j|^2 - 1 over the pairs of neighbouring agents in the plane
// (N agents, 2N inputs, about 4N outputs), its SparseJacobian and SparseWeightedHessian for
// N = 10^2 .. 10^4, the first call (detection and colouring), a 1% active subset, and the dense
// AD at small N.
//
//   build/release/bench/sparse_ad_bench
//   scripts/bench-sparse-ad      (runs it and prints the log-log slopes of time against N)
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include "moreau/core/smooth_function.hpp"

namespace {

using moreau::Matrix;
using moreau::SmoothFunction;
using moreau::SparseMatrix;
using moreau::Vector;
using moreau::Wrt;

// Agents on a jittered unit grid; a pair of agents closer than kReach is a constraint.
constexpr double kReach = 1.6;

struct Crowd {
  Vector q;  // positions (x_0, y_0, x_1, y_1, ...)
  SmoothFunction constraints;
};

Crowd MakeCrowd(int agents) {
  const int side = static_cast<int>(std::ceil(std::sqrt(agents)));
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> jitter(-0.1, 0.1);
  Crowd crowd;
  crowd.q.resize(2 * agents);
  for (int i = 0; i < agents; ++i) {
    crowd.q[2 * i] = i % side + jitter(rng);
    crowd.q[2 * i + 1] = i / side + jitter(rng);
  }
  // Neighbours among the grid cells around each agent (O(N) pairs and setup).
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < agents; ++i) {
    const int row = i / side, column = i % side;
    for (int dr = 0; dr <= 2; ++dr) {
      for (int dc = -2; dc <= 2; ++dc) {
        const int j = (row + dr) * side + column + dc;
        if ((dr == 0 && dc <= 0) || column + dc < 0 || column + dc >= side || j >= agents) continue;
        const double dx = crowd.q[2 * i] - crowd.q[2 * j];
        const double dy = crowd.q[2 * i + 1] - crowd.q[2 * j + 1];
        if (dx * dx + dy * dy < kReach * kReach) pairs.emplace_back(i, j);
      }
    }
  }
  crowd.constraints = moreau::MakeSmoothFunction(
      "crowd.c", static_cast<int>(pairs.size()),
      [pairs](const auto& q, const auto&, const auto&, const auto&, auto& out) {
        for (std::size_t k = 0; k < pairs.size(); ++k) {
          const auto [i, j] = pairs[k];
          const auto dx = q[2 * i] - q[2 * j];
          const auto dy = q[2 * i + 1] - q[2 * j + 1];
          out[static_cast<int>(k)] = dx * dx + dy * dy - 1.0;
        }
      });
  return crowd;
}

void SetCounters(benchmark::State& state, const Crowd& crowd, const SparseMatrix& matrix,
                 const SmoothFunction* called = nullptr) {
  const moreau::SparseDerivativeStats stats =
      (called ? *called : crowd.constraints).sparse_derivative_stats();
  state.counters["inputs"] = static_cast<double>(crowd.q.size());
  state.counters["outputs"] = crowd.constraints.num_outputs();
  state.counters["nnz"] = static_cast<double>(matrix.nonZeros());
  state.counters["jac_colors"] = stats.jacobian_colors;
  state.counters["jac_passes"] = stats.jacobian_passes;
  state.counters["hess_colors"] = stats.hessian_colors;
  state.counters["hess_passes"] = stats.hessian_passes;
  state.counters["workspace_MB"] = static_cast<double>(stats.workspace_bytes) / 1e6;
}

const Vector kNone;

void BM_SparseJacobian(benchmark::State& state) {
  const Crowd crowd = MakeCrowd(static_cast<int>(state.range(0)));
  Vector value;
  SparseMatrix jac;
  crowd.constraints.SparseJacobian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), &value, &jac);
  for (auto _ : state) {
    crowd.constraints.SparseJacobian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), &value, &jac);
    benchmark::DoNotOptimize(jac.valuePtr());
  }
  SetCounters(state, crowd, jac);
}

void BM_SparseHessian(benchmark::State& state) {
  const Crowd crowd = MakeCrowd(static_cast<int>(state.range(0)));
  const int m = crowd.constraints.num_outputs();
  const Vector weights = Vector::LinSpaced(m, 0.5, 1.5);
  SparseMatrix hess;
  crowd.constraints.SparseWeightedHessian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), weights, &hess);
  for (auto _ : state) {
    crowd.constraints.SparseWeightedHessian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), weights, &hess);
    benchmark::DoNotOptimize(hess.valuePtr());
  }
  SetCounters(state, crowd, hess);
}

// An active set: every 100th constraint in `rows` with a nonzero weight (the others are not
// assembled), as the near-active filter of the integrators would pass.
void BM_SparseHessianActiveSubset(benchmark::State& state) {
  const Crowd crowd = MakeCrowd(static_cast<int>(state.range(0)));
  const int m = crowd.constraints.num_outputs();
  std::vector<int> rows;
  for (int k = 0; k < m; k += 100) rows.push_back(k);
  const Vector weights = Vector::Ones(m);
  SparseMatrix hess;
  crowd.constraints.SparseWeightedHessian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), weights, &hess,
                                          &rows);
  for (auto _ : state) {
    crowd.constraints.SparseWeightedHessian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), weights, &hess,
                                            &rows);
    benchmark::DoNotOptimize(hess.valuePtr());
  }
  SetCounters(state, crowd, hess);
  state.counters["rows"] = static_cast<double>(rows.size());
}

// The first sparse call of a fresh copy: tracing, pattern analysis, ColPack colourings, plans.
void BM_FirstSparseCall(benchmark::State& state) {
  const Crowd crowd = MakeCrowd(static_cast<int>(state.range(0)));
  const Vector weights = Vector::Ones(crowd.constraints.num_outputs());
  Vector value;
  SparseMatrix jac, hess;
  SmoothFunction fresh;
  for (auto _ : state) {
    state.PauseTiming();
    fresh = crowd.constraints;
    state.ResumeTiming();
    fresh.SparseJacobian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), &value, &jac);
    fresh.SparseWeightedHessian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), weights, &hess);
  }
  SetCounters(state, crowd, jac, &fresh);
}

// The dense forward-mode AD of the same function (every input a direction).
void BM_DenseJacobian(benchmark::State& state) {
  const Crowd crowd = MakeCrowd(static_cast<int>(state.range(0)));
  Vector value;
  Matrix jac;
  for (auto _ : state) {
    crowd.constraints.Jacobian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), &value, &jac);
    benchmark::DoNotOptimize(jac.data());
  }
  state.counters["inputs"] = static_cast<double>(crowd.q.size());
  state.counters["outputs"] = crowd.constraints.num_outputs();
}

void BM_DenseHessian(benchmark::State& state) {
  const Crowd crowd = MakeCrowd(static_cast<int>(state.range(0)));
  const Vector weights = Vector::LinSpaced(crowd.constraints.num_outputs(), 0.5, 1.5);
  Matrix hess;
  for (auto _ : state) {
    crowd.constraints.WeightedHessian(crowd.q, kNone, 0.0, kNone, Wrt::XT(), weights, &hess);
    benchmark::DoNotOptimize(hess.data());
  }
  state.counters["inputs"] = static_cast<double>(crowd.q.size());
  state.counters["outputs"] = crowd.constraints.num_outputs();
}

void Sizes(benchmark::internal::Benchmark* b) {
  for (int n : {100, 316, 1000, 3162, 10000}) b->Arg(n);
  b->Unit(benchmark::kMicrosecond);
}

BENCHMARK(BM_SparseJacobian)->Apply(Sizes);
BENCHMARK(BM_SparseHessian)->Apply(Sizes);
BENCHMARK(BM_SparseHessianActiveSubset)->Apply(Sizes);
BENCHMARK(BM_FirstSparseCall)->Apply(Sizes);
BENCHMARK(BM_DenseJacobian)->Arg(100)->Arg(316)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_DenseHessian)->Arg(100)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
