// Model code that reads like maths (dual.hpp, sparsity_tracer.hpp): the elementary functions
// compile on moreau's scalar types whether called as `std::sin(x)`, `sin(x)` or after
// `using std::sin;`, and give exact derivatives. (The nonsmooth calls that must NOT compile are
// tested by tests/compile_fail/, which checks the compiler's message.)
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "moreau/core/smooth_function.hpp"

// Outside namespace moreau on purpose: user model code lives in its own namespace, where only
// argument-dependent lookup (bare calls) and the declarations in namespace std (std:: calls)
// can find moreau's overloads.
namespace user_model {

// f(x) = (sin x0 cos x1 + exp(x0 x1) + pow(x1, 3) + sqrt(x0),  atan2(x1, x0) + log(1 + x0^2)),
// written three ways. Exact first and second derivatives are below (Analytic*).
moreau::SmoothFunction WithStdQualified() {
  return moreau::MakeSmoothFunction(
      "std_qualified", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = std::sin(x[0]) * std::cos(x[1]) + std::exp(x[0] * x[1]) + std::pow(x[1], 3) +
                 std::sqrt(x[0]);
        out[1] = std::atan2(x[1], x[0]) + std::log(1.0 + x[0] * x[0]);
      });
}
moreau::SmoothFunction WithBareCalls() {
  return moreau::MakeSmoothFunction(
      "bare", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = sin(x[0]) * cos(x[1]) + exp(x[0] * x[1]) + pow(x[1], 3) + sqrt(x[0]);
        out[1] = atan2(x[1], x[0]) + log(1.0 + x[0] * x[0]);
      });
}
moreau::SmoothFunction WithUsingDeclarations() {
  return moreau::MakeSmoothFunction(
      "using_std", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        using std::atan2;
        using std::cos;
        using std::exp;
        using std::log;
        using std::pow;
        using std::sin;
        using std::sqrt;
        out[0] = sin(x[0]) * cos(x[1]) + exp(x[0] * x[1]) + pow(x[1], 3) + sqrt(x[0]);
        out[1] = atan2(x[1], x[0]) + log(1.0 + x[0] * x[0]);
      });
}

}  // namespace user_model

namespace moreau {
namespace {

// Derivatives are exact: they differ from the closed forms by rounding only (a few ulps of
// the O(1..10) terms).
constexpr double kExact = 1e-13;

Vector AnalyticValue(double a, double b) {
  return Vector{{std::sin(a) * std::cos(b) + std::exp(a * b) + b * b * b + std::sqrt(a),
                 std::atan2(b, a) + std::log(1.0 + a * a)}};
}
Matrix AnalyticJacobian(double a, double b) {
  const double e = std::exp(a * b), r2 = a * a + b * b;
  Matrix j(2, 2);
  j << std::cos(a) * std::cos(b) + b * e + 0.5 / std::sqrt(a),
      -std::sin(a) * std::sin(b) + a * e + 3.0 * b * b,  //
      -b / r2 + 2.0 * a / (1.0 + a * a), a / r2;
  return j;
}
// Hessian of w0 f0 + w1 f1.
Matrix AnalyticWeightedHessian(double a, double b, double w0, double w1) {
  const double e = std::exp(a * b), r2 = a * a + b * b;
  Matrix h0(2, 2), h1(2, 2);
  h0 << -std::sin(a) * std::cos(b) + b * b * e - 0.25 / (a * std::sqrt(a)),
      -std::cos(a) * std::sin(b) + e + a * b * e,  //
      -std::cos(a) * std::sin(b) + e + a * b * e, -std::sin(a) * std::cos(b) + a * a * e + 6.0 * b;
  const double q = 1.0 + a * a;
  h1 << 2.0 * a * b / (r2 * r2) + (2.0 * q - 4.0 * a * a) / (q * q),
      (b * b - a * a) / (r2 * r2),  //
      (b * b - a * a) / (r2 * r2), -2.0 * a * b / (r2 * r2);
  return w0 * h0 + w1 * h1;
}

TEST(ModelMathTest, StdQualifiedBareAndUsingCallsGiveTheSameExactDerivatives) {
  const std::vector<SmoothFunction> functions = {user_model::WithStdQualified(),
                                                 user_model::WithBareCalls(),
                                                 user_model::WithUsingDeclarations()};
  const Vector u, p;
  const Vector weights{{0.7, -1.3}};
  for (const SmoothFunction& f : functions) {
    for (const auto& [a, b] : std::vector<std::pair<double, double>>{{0.4, 1.1}, {2.3, -0.6}}) {
      const Vector x{{a, b}};
      Vector value;
      Matrix jac, hess;
      f.Jacobian(x, u, 0.0, p, Wrt::X(), &value, &jac);
      f.WeightedHessian(x, u, 0.0, p, Wrt::X(), weights, &hess);
      EXPECT_LE((value - AnalyticValue(a, b)).lpNorm<Eigen::Infinity>(), kExact) << f.name();
      EXPECT_LE((jac - AnalyticJacobian(a, b)).lpNorm<Eigen::Infinity>(), kExact) << f.name();
      EXPECT_LE(
          (hess - AnalyticWeightedHessian(a, b, weights[0], weights[1])).lpNorm<Eigen::Infinity>(),
          kExact)
          << f.name() << " at (" << a << ", " << b << ")";
      // The sparse path (traced pattern, SparsityTracer overloads through std::) agrees.
      SparseMatrix sparse_jac;
      f.SparseJacobian(x, u, 0.0, p, Wrt::X(), &value, &sparse_jac);
      EXPECT_LE((Matrix(sparse_jac) - jac).lpNorm<Eigen::Infinity>(), kExact) << f.name();
    }
  }
}

// The functions added for model code (exp2, expm1, log2, log10, log1p, cbrt, the inverse
// hyperbolic functions, erf, erfc) against their closed-form derivatives, first and second
// order, each called with std::.
struct UnaryCase {
  std::string name;
  std::function<double(double)> value, first, second;
  double x;
};

TEST(ModelMathTest, AddedElementaryFunctionsHaveExactFirstAndSecondDerivatives) {
  const double ln2 = std::log(2.0), ln10 = std::log(10.0), c = 2.0 / std::sqrt(M_PI);
  const std::vector<UnaryCase> cases = {
      {"exp2", [](double x) { return std::exp2(x); }, [=](double x) { return ln2 * std::exp2(x); },
       [=](double x) { return ln2 * ln2 * std::exp2(x); }, 0.7},
      {"expm1", [](double x) { return std::expm1(x); }, [](double x) { return std::exp(x); },
       [](double x) { return std::exp(x); }, -0.4},
      {"log2", [](double x) { return std::log2(x); }, [=](double x) { return 1.0 / (x * ln2); },
       [=](double x) { return -1.0 / (x * x * ln2); }, 1.7},
      {"log10", [](double x) { return std::log10(x); }, [=](double x) { return 1.0 / (x * ln10); },
       [=](double x) { return -1.0 / (x * x * ln10); }, 0.3},
      {"log1p", [](double x) { return std::log1p(x); }, [](double x) { return 1.0 / (1.0 + x); },
       [](double x) { return -1.0 / ((1.0 + x) * (1.0 + x)); }, 0.25},
      {"cbrt", [](double x) { return std::cbrt(x); },
       [](double x) { return 1.0 / (3.0 * std::cbrt(x * x)); },
       [](double x) { return -2.0 / (9.0 * x * std::cbrt(x * x)); }, 2.2},
      {"asinh", [](double x) { return std::asinh(x); },
       [](double x) { return 1.0 / std::sqrt(x * x + 1.0); },
       [](double x) { return -x / std::pow(x * x + 1.0, 1.5); }, -0.8},
      {"acosh", [](double x) { return std::acosh(x); },
       [](double x) { return 1.0 / std::sqrt(x * x - 1.0); },
       [](double x) { return -x / std::pow(x * x - 1.0, 1.5); }, 1.9},
      {"atanh", [](double x) { return std::atanh(x); }, [](double x) { return 1.0 / (1 - x * x); },
       [](double x) { return 2.0 * x / ((1 - x * x) * (1 - x * x)); }, 0.35},
      {"erf", [](double x) { return std::erf(x); }, [=](double x) { return c * std::exp(-x * x); },
       [=](double x) { return -2.0 * x * c * std::exp(-x * x); }, 0.6},
      {"erfc", [](double x) { return std::erfc(x); },
       [=](double x) { return -c * std::exp(-x * x); },
       [=](double x) { return 2.0 * x * c * std::exp(-x * x); }, -0.2},
  };
  // One function with one output per case, all written with std::.
  const SmoothFunction f =
      MakeSmoothFunction("added", static_cast<int>(cases.size()),
                         [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
                           out[0] = std::exp2(x[0]);
                           out[1] = std::expm1(x[1]);
                           out[2] = std::log2(x[2]);
                           out[3] = std::log10(x[3]);
                           out[4] = std::log1p(x[4]);
                           out[5] = std::cbrt(x[5]);
                           out[6] = std::asinh(x[6]);
                           out[7] = std::acosh(x[7]);
                           out[8] = std::atanh(x[8]);
                           out[9] = std::erf(x[9]);
                           out[10] = std::erfc(x[10]);
                         });
  const int n = static_cast<int>(cases.size());
  Vector x(n);
  for (int k = 0; k < n; ++k) x[k] = cases[static_cast<std::size_t>(k)].x;
  const Vector u, p;
  Vector value;
  Matrix jac;
  f.Jacobian(x, u, 0.0, p, Wrt::X(), &value, &jac);
  for (int k = 0; k < n; ++k) {
    const UnaryCase& c_k = cases[static_cast<std::size_t>(k)];
    EXPECT_NEAR(value[k], c_k.value(c_k.x), kExact) << c_k.name;
    EXPECT_NEAR(jac(k, k), c_k.first(c_k.x), kExact) << c_k.name;
    Vector weights = Vector::Zero(n);
    weights[k] = 1.0;
    Matrix hess;
    f.WeightedHessian(x, u, 0.0, p, Wrt::X(), weights, &hess);
    EXPECT_NEAR(hess(k, k), c_k.second(c_k.x), kExact) << c_k.name;
    EXPECT_EQ(hess.norm(), std::abs(hess(k, k))) << c_k.name << ": other entries must be zero";
  }
  // The traced pattern: each output depends on its own input, nonlinearly.
  SparseMatrix sparse_jac, sparse_hess;
  f.SparseJacobian(x, u, 0.0, p, Wrt::X(), &value, &sparse_jac);
  f.SparseWeightedHessian(x, u, 0.0, p, Wrt::X(), Vector::Ones(n), &sparse_hess);
  EXPECT_EQ(sparse_jac.nonZeros(), n);
  EXPECT_EQ(sparse_hess.nonZeros(), n);
}

// ValueOf is the explicit branch on a value (documented for branches that never change
// during a run); it compiles for every scalar type and the branch taken is differentiated.
TEST(ModelMathTest, ValueOfIsTheExplicitBranch) {
  const SmoothFunction f = MakeSmoothFunction(
      "guarded", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        if (ValueOf(x[0]) > 0.0) {
          out[0] = std::sqrt(x[0]);
        } else {
          out[0] = 0.0 * x[0];
        }
      });
  Vector value;
  Matrix jac;
  f.Jacobian(Vector{{4.0}}, Vector(), 0.0, Vector(), Wrt::X(), &value, &jac);
  EXPECT_EQ(value[0], 2.0);
  EXPECT_EQ(jac(0, 0), 0.25);
}

}  // namespace
}  // namespace moreau
