// One semismooth Newton iteration (SemismoothNewton with max_iterations = 1: residual,
// generalized Jacobian, factorization, solve and line search) on two systems over sizes:
//  - LCP(M, q) with the tridiagonal P-matrix M = tridiag(-1, 4, -1), the complementarity
//    kernel of include/moreau/complementarity/lcp.hpp, from z = 0;
//  - one implicit Euler step with complementarity at the stage (the time-stepping baseline's
//    s = 1 step system, re-assembled here from LoweredSystem::Evaluate) of the n moving
//    intervals of family.hpp: unknowns (Z = y1 - y0, lambda), 3n + 1 of them.
#include <benchmark/benchmark.h>

#include <cmath>

#include "family.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau::bench {
namespace {

class TridiagonalLcp : public MixedComplementaritySystem {
 public:
  explicit TridiagonalLcp(int n) : n_(n), q_(n) {
    std::vector<Eigen::Triplet<double, int>> entries;
    for (int i = 0; i < n; ++i) {
      if (i > 0) entries.emplace_back(i, i - 1, -1.0);
      entries.emplace_back(i, i, 4.0);
      if (i + 1 < n) entries.emplace_back(i, i + 1, -1.0);
      q_[i] = std::sin(1.0 + i);  // about half of the z_i end up positive
    }
    m_.resize(n, n);
    m_.setFromTriplets(entries.begin(), entries.end());
  }
  int num_unknowns() const override { return n_; }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return n_; }
  bool Evaluate(const Vector& w, bool, Vector* r, Vector* a, Vector* b) override {
    r->resize(0);
    *a = w;
    *b = m_ * w + q_;
    return true;
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    for (int k = 0; k < n_; ++k) jacobian->AddEntry(k, k, da[k]);
    for (int col = 0; col < m_.outerSize(); ++col) {
      for (SparseMatrix::InnerIterator it(m_, col); it; ++it) {
        jacobian->AddEntry(it.row(), col, db[it.row()] * it.value());
      }
    }
  }
  double EstimatedJacobianNonzeros() const override { return 3.0 * n_; }

 private:
  int n_;
  SparseMatrix m_;
  Vector q_;
};

class ImplicitEulerStep : public MixedComplementaritySystem {
 public:
  ImplicitEulerStep(const LoweredSystem& system, const Vector& y0, double h)
      : system_(system), y0_(y0), h_(h), ny_(system.num_states()), nz_(system.num_algebraic()) {}
  int num_unknowns() const override { return ny_ + nz_; }
  int num_equations() const override { return ny_ + system_.num_equations(); }
  int num_pairs() const override { return system_.num_pairs(); }
  bool Evaluate(const Vector& w, bool with_jacobian, Vector* r, Vector* a, Vector* b) override {
    const Vector y = y0_ + w.head(ny_);
    system_.Evaluate(y, w.tail(nz_), with_jacobian ? Derivatives::kStates : Derivatives::kNone,
                     &point_);
    r->resize(num_equations());
    r->head(ny_) = w.head(ny_) - h_ * point_.F;  // implicit Euler collocation
    r->tail(system_.num_equations()) = point_.G;
    *a = point_.A;
    *b = point_.B;
    return point_.F.allFinite();
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    const int ng = system_.num_equations();
    jacobian->AddDiagonal(0, 0, ny_, 1.0);
    jacobian->AddDerivative(0, 0, point_.F_y, -h_);
    jacobian->AddDerivative(0, ny_, point_.F_z, -h_);
    if (ng > 0) {
      jacobian->AddDerivative(ny_, 0, point_.G_y);
      jacobian->AddDerivative(ny_, ny_, point_.G_z);
    }
    jacobian->AddWeightedRows(ny_ + ng, 0, da, point_.A_y);
    jacobian->AddWeightedRows(ny_ + ng, 0, db, point_.B_y);
    jacobian->AddWeightedRows(ny_ + ng, ny_, da, point_.A_z);
    jacobian->AddWeightedRows(ny_ + ng, ny_, db, point_.B_z);
  }

 private:
  const LoweredSystem& system_;
  Vector y0_;
  double h_;
  int ny_, nz_;
  PointEvaluation point_;
};

SemismoothNewtonOptions OneIteration() {
  SemismoothNewtonOptions options;
  options.max_iterations = 1;
  return options;
}

void BM_NewtonIterationLcp(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  TridiagonalLcp lcp(n);
  SemismoothNewton newton(OneIteration());
  const Vector z0 = Vector::Zero(n);
  double reduction = 0.0;
  for (auto _ : state) {
    const SemismoothNewtonResult result = newton.Solve(lcp, z0);
    reduction = result.residual_history.back() / result.residual_history.front();
  }
  state.counters["unknowns"] = n;
  state.counters["residual_reduction"] = reduction;
}
BENCHMARK(BM_NewtonIterationLcp)->RangeMultiplier(4)->Range(4, 4096)->ArgName("n");

void BM_NewtonIterationImplicitEulerStep(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const LoweredSystem system(MovingIntervals(n));
  Vector y0 = system.InitialState();
  ImplicitEulerStep step(system, y0, 0.01);
  SemismoothNewton newton(OneIteration());
  const Vector w0 = Vector::Zero(step.num_unknowns());
  double reduction = 0.0;
  for (auto _ : state) {
    const SemismoothNewtonResult result = newton.Solve(step, w0);
    reduction = result.residual_history.back() / result.residual_history.front();
  }
  state.counters["unknowns"] = step.num_unknowns();
  state.counters["residual_reduction"] = reduction;
}
BENCHMARK(BM_NewtonIterationImplicitEulerStep)->RangeMultiplier(4)->Range(1, 256)->ArgName("n");

}  // namespace
}  // namespace moreau::bench
