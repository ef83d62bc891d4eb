// The linear solve of every Newton iteration: factorization and solve with the dense LU
// (Eigen) and the sparse LU (KLU) on the Newton matrix of one Radau IIA step (s = 3) of the
// 1-D heat equation with n points, I - h (A kron J) of size 3n, over problem sizes.
#include <benchmark/benchmark.h>

#include <memory>

#include "moreau/integrators/radau_tableau.hpp"
#include "moreau/linalg/linear_solver.hpp"

namespace moreau::bench {
namespace {

constexpr int kStages = 3;
constexpr double kStep = 1e-3;

// J: second differences on (0, 1) with zero boundary values, n interior points.
SparseMatrix Laplacian(int n) {
  const double scale = (n + 1.0) * (n + 1.0);
  std::vector<Eigen::Triplet<double, int>> entries;
  for (int i = 0; i < n; ++i) {
    if (i > 0) entries.emplace_back(i, i - 1, scale);
    entries.emplace_back(i, i, -2.0 * scale);
    if (i + 1 < n) entries.emplace_back(i, i + 1, scale);
  }
  SparseMatrix j(n, n);
  j.setFromTriplets(entries.begin(), entries.end());
  return j;
}

void AssembleNewtonMatrix(int n, bool sparse, SystemMatrix* m) {
  const RadauTableau& tableau = RadauIIA(kStages);
  const SparseMatrix j = Laplacian(n);
  const Matrix j_dense = Matrix(j);
  m->Reset(kStages * n, sparse);
  for (int a = 0; a < kStages; ++a) {
    m->AddDiagonal(a * n, a * n, n, 1.0);
    for (int b = 0; b < kStages; ++b) {
      if (sparse) {
        m->AddSparseBlock(a * n, b * n, j, -kStep * tableau.a(a, b));
      } else {
        m->AddBlock(a * n, b * n, j_dense, -kStep * tableau.a(a, b));
      }
    }
  }
  m->Finalize();
}

LinearSolverKind Kind(const benchmark::State& state) {
  return state.range(0) == 0 ? LinearSolverKind::kDenseLu : LinearSolverKind::kSparseLu;
}

void BM_LinearSolverFactorize(benchmark::State& state) {
  const int n = static_cast<int>(state.range(1));
  const std::unique_ptr<LinearSolver> solver =
      MakeLinearSolver(Kind(state), kStages * n, 3.0 * kStages * kStages * n);
  SystemMatrix m;
  AssembleNewtonMatrix(n, solver->wants_sparse(), &m);
  for (auto _ : state) {
    if (solver->Factorize(m) != FactorizationStatus::kSuccess) {
      state.SkipWithError("factorization failed");
      break;
    }
  }
  state.SetLabel(ToString(Kind(state)));
  state.counters["unknowns"] = kStages * n;
}

void BM_LinearSolverSolve(benchmark::State& state) {
  const int n = static_cast<int>(state.range(1));
  const std::unique_ptr<LinearSolver> solver =
      MakeLinearSolver(Kind(state), kStages * n, 3.0 * kStages * kStages * n);
  SystemMatrix m;
  AssembleNewtonMatrix(n, solver->wants_sparse(), &m);
  if (solver->Factorize(m) != FactorizationStatus::kSuccess) {
    state.SkipWithError("factorization failed");
    return;
  }
  const Vector rhs = Vector::LinSpaced(kStages * n, -1.0, 1.0);
  Vector x(kStages * n);
  for (auto _ : state) {
    x = rhs;
    solver->Solve(x);
    benchmark::DoNotOptimize(x.data());
  }
  state.SetLabel(ToString(Kind(state)));
  state.counters["unknowns"] = kStages * n;
}

// Dense LU up to 768 unknowns (beyond, O(n^3) makes it pointless here); KLU up to 6144.
void Sizes(benchmark::internal::Benchmark* b) {
  for (int n : {8, 32, 128, 256}) b->Args({0, n});
  for (int n : {8, 32, 128, 512, 2048}) b->Args({1, n});
  b->ArgNames({"sparse", "n"});
}
BENCHMARK(BM_LinearSolverFactorize)->Apply(Sizes);
BENCHMARK(BM_LinearSolverSolve)->Apply(Sizes);

}  // namespace
}  // namespace moreau::bench
