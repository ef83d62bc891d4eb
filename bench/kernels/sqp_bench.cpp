// One SQP iteration of the alpha-method step (integrators/alpha_dai/sqp.hpp, private: included
// by relative path as the tests do): linearization, the Goldfarb-Idnani QP, the l1-merit line
// search and the KKT certificate. The step problem is assembled here the way the stepper does
// it (eq. 2a with a_{n+1} eliminated, least-change objective, Hessian diag(1e-8 on x, 1 on u))
// for n states x_i' = u_i - x_i with n algebraic inputs and the path constraints
// phi_i = s_i - x_i <= 0, active for the even i (s_i = x_{n,i} = 1/2, which the free motion
// would leave) and inactive for the odd ones. Not included: the stepper's basis-matrix rank
// test (one SVD per QP working set).
#include <benchmark/benchmark.h>

#include <limits>

#include "../../integrators/alpha_dai/sqp.hpp"
#include "moreau/integrators/alpha_dai.hpp"

namespace moreau::bench {
namespace {

constexpr double kStep = 0.1;
constexpr double kRho = 0.5;
constexpr double kStateProximalWeight = 1e-8;  // as in integrators/alpha_dai/alpha_dai.cpp

void BM_SqpIterationAlphaStep(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const AlphaCoefficients co = AlphaCoefficients::FromRho(kRho);
  const double c = co.beta / co.gamma, h = kStep;
  const Vector x0 = Vector::Constant(n, 0.5), u0 = Vector::Zero(n);
  const Vector f0 = u0 - x0;
  const Vector a0 = -f0;  // df/dt = f_x f with u stationary
  const Vector known = x0 + (1.0 - c) * h * f0 + (0.5 - c) * h * h * a0;
  Vector s(n);
  for (int i = 0; i < n; ++i) s[i] = i % 2 == 0 ? 0.5 : -1.0;
  const double inf = std::numeric_limits<double>::infinity();

  internal::SqpProblem problem;
  problem.num_variables = 2 * n;
  problem.lower.resize(2 * n);
  problem.upper.resize(2 * n);
  problem.lower << Vector::Constant(n, -inf), Vector::Constant(n, -10.0);
  problem.upper << Vector::Constant(n, inf), Vector::Constant(n, 10.0);
  problem.objective_weights.resize(2 * n);
  problem.objective_weights << Vector::Zero(n), Vector::Ones(n);
  problem.reference.resize(2 * n);
  problem.reference << x0, u0;
  problem.hessian_diagonal.resize(2 * n);
  problem.hessian_diagonal << Vector::Constant(n, kStateProximalWeight), Vector::Ones(n);
  problem.equality_scales = (1.0 + x0.array().abs()).matrix();
  problem.evaluate = [&](const Vector& z, bool jacobians, internal::SqpEvaluation* out) {
    const Vector x = z.head(n), u = z.tail(n);
    out->equalities = x - known - c * h * (u - x);
    out->inequalities = s - x;
    if (jacobians) {
      out->equality_jacobian.resize(n, 2 * n);
      out->equality_jacobian << (1.0 + c * h) * Matrix::Identity(n, n),
          -c * h * Matrix::Identity(n, n);
      out->inequality_jacobian.resize(n, 2 * n);
      out->inequality_jacobian << -Matrix::Identity(n, n), Matrix::Zero(n, n);
    }
    return true;
  };
  internal::SqpOptions options;
  options.max_iterations = 1;
  Vector guess(2 * n);
  guess << x0 + h * f0, u0;  // the stepper's explicit predictor
  int qp_iterations = 0;
  for (auto _ : state) {
    const internal::SqpResult result = internal::SolveSqp(problem, guess, options);
    qp_iterations = result.qp_iterations;
    benchmark::DoNotOptimize(result.z.data());
  }
  state.counters["variables"] = 2 * n;
  state.counters["qp_iterations"] = qp_iterations;
}
BENCHMARK(BM_SqpIterationAlphaStep)->RangeMultiplier(4)->Range(2, 128)->ArgName("n");

}  // namespace
}  // namespace moreau::bench
