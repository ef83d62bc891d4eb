#include "moreau/core/smooth_function.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "moreau/core/convergence.hpp"

namespace moreau {
namespace {

constexpr double kRoundOff = 1e-14;  // exact derivatives up to a few ulps of O(1) values

SmoothFunction MakeTestFunction() {
  // g(x, u, t, p) = (x0^2 u0 + sin(t) p0, x0 x1 exp(t) + p1 u0^2)
  return MakeSmoothFunction(
      "test.g", 2, [](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::exp;
        using std::sin;
        out[0] = x[0] * x[0] * u[0] + sin(t) * p[0];
        out[1] = x[0] * x[1] * exp(t) + p[1] * u[0] * u[0];
      });
}

TEST(SmoothFunctionTest, JacobianColumnsFollowTheSelection) {
  const SmoothFunction g = MakeTestFunction();
  const Vector x{{1.5, -2.0}}, u{{0.5}}, p{{3.0, 4.0}};
  const double t = 0.3;
  Vector value;
  Matrix jac;
  g.Jacobian(x, u, t, p, Wrt::All(), &value, &jac);
  ASSERT_EQ(jac.cols(), 2 + 1 + 1 + 2);
  const double e = std::exp(t);
  Matrix expected(2, 6);
  expected << 2 * 1.5 * 0.5, 0, 1.5 * 1.5, std::cos(t) * 3.0, std::sin(t), 0,  //
      -2.0 * e, 1.5 * e, 2 * 4.0 * 0.5, 1.5 * -2.0 * e, 0, 0.25;
  EXPECT_LE((jac - expected).lpNorm<Eigen::Infinity>(), kRoundOff);
  g.Jacobian(x, u, t, p, Wrt::XT(), &value, &jac);
  ASSERT_EQ(jac.cols(), 3);
  EXPECT_LE((jac.leftCols(2) - expected.leftCols(2)).lpNorm<Eigen::Infinity>(), kRoundOff);
  EXPECT_LE((jac.col(2) - expected.col(3)).lpNorm<Eigen::Infinity>(), kRoundOff);
}

// A function affine in the selected inputs keeps its Jacobian between calls, and one that does
// not depend on them at all (a circuit's constant input matrix, differentiated in x and t) also
// its values: both are keyed by the other inputs, so new values of those give new results, and
// the values must stay those of a fresh evaluation whatever the selected inputs do.
TEST(SmoothFunctionTest, KeptJacobiansAndValuesFollowTheOtherInputs) {
  // b does not depend on x or t; g is affine in them; h is not.
  const SmoothFunction b = MakeSmoothFunction(
      "b", 2, [](const auto&, const auto& u, const auto&, const auto& p, auto& out) {
        out[0] = 2.0 * p[0];
        out[1] = u[0] + p[0] * p[1];
      });
  const SmoothFunction g = MakeSmoothFunction(
      "g", 1, [](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        out[0] = p[0] * x[0] - x[1] / 3.0 + t * p[1];
      });
  const SmoothFunction h = MakeSmoothFunction(
      "h", 1, [](const auto& x, const auto&, const auto& t, const auto&, auto& out) {
        out[0] = x[0] * x[1] + t * t;
      });
  Vector u{{0.5}}, p{{3.0, -4.0}};
  Vector value, evaluated;
  Matrix jac;
  for (int call = 0; call < 6; ++call) {
    if (call == 3) p[0] = -1.25;  // another key: new values and Jacobians
    if (call == 5) u[0] = 7.0;
    const Vector x{{0.1 * call - 0.4, 1.0 + call}};
    const double t = 0.25 * call;
    const std::string at = "call " + std::to_string(call);

    b.Jacobian(x, u, t, p, Wrt::XT(), &value, &jac);
    b.Evaluate(x, u, t, p, &evaluated);
    EXPECT_EQ(value, evaluated) << at;
    EXPECT_EQ(jac, Matrix::Zero(2, 3)) << at;

    g.Jacobian(x, u, t, p, Wrt::XT(), &value, &jac);
    g.Evaluate(x, u, t, p, &evaluated);
    EXPECT_EQ(value, evaluated) << at;
    EXPECT_EQ(jac, (Matrix(1, 3) << p[0], -1.0 / 3.0, p[1]).finished()) << at;

    h.Jacobian(x, u, t, p, Wrt::XT(), &value, &jac);
    h.Evaluate(x, u, t, p, &evaluated);
    EXPECT_EQ(value, evaluated) << at;
    EXPECT_EQ(jac, (Matrix(1, 3) << x[1], x[0], 2.0 * t).finished()) << at;

    // With u and p selected too, b's values depend on the selection: not kept.
    b.Jacobian(x, u, t, p, Wrt::All(), &value, &jac);
    b.Evaluate(x, u, t, p, &evaluated);
    EXPECT_EQ(value, evaluated) << at;
    EXPECT_EQ(jac(1, 4), p[1]) << at;  // d(u0 + p0 p1)/dp0: columns x0, x1, u0, t, p0, p1
  }
}

TEST(SmoothFunctionTest, ChunkedJacobianForManyInputs) {
  // 40 inputs exceed one chunk of Dual<double>::kCapacity directions.
  constexpr int n = 40;
  const SmoothFunction g = MakeSmoothFunction(
      "sum_of_squares", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        for (int i = 0; i < x.size(); ++i) out[0] += (i + 1.0) * x[i] * x[i];
      });
  Vector x = Vector::LinSpaced(n, -1.0, 1.0);
  Vector value;
  Matrix jac, hess;
  g.Jacobian(x, Vector(), 0.0, Vector(), Wrt::X(), &value, &jac);
  g.WeightedHessian(x, Vector(), 0.0, Vector(), Wrt::X(), Vector::Constant(1, 2.0), &hess);
  for (int i = 0; i < n; ++i) {
    EXPECT_NEAR(jac(0, i), 2.0 * (i + 1.0) * x[i], kRoundOff);
    for (int j = 0; j < n; ++j) EXPECT_EQ(hess(i, j), i == j ? 4.0 * (i + 1.0) : 0.0);
  }
}

TEST(SmoothFunctionTest, WeightedHessianMatchesAnalyticSecondDerivatives) {
  const SmoothFunction g = MakeTestFunction();
  const Vector x{{1.5, -2.0}}, u{{0.5}}, p{{3.0, 4.0}};
  const double t = 0.3;
  Matrix hess;
  g.WeightedHessian(x, u, t, p, Wrt::XT(), Vector{{2.0, -1.0}}, &hess);
  // 2 * d2(g0) - d2(g1) over (x0, x1, t).
  const double e = std::exp(t);
  Matrix expected(3, 3);
  expected << 2 * 2 * 0.5, -e, 2.0 * e,  //
      -e, 0, -1.5 * e,                   //
      2.0 * e, -1.5 * e, 2 * -std::sin(t) * 3.0 + 1.5 * 2.0 * e;
  EXPECT_LE((hess - expected).lpNorm<Eigen::Infinity>(), kRoundOff) << hess;
}

TEST(SmoothFunctionTest, OutOfRangeArgumentIsAClearError) {
  const SmoothFunction g = MakeSmoothFunction(
      "wall.c", 1,
      [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = x[2]; });
  Vector value;
  try {
    g.Evaluate(Vector{{1.0, 2.0}}, Vector(), 0.0, Vector(), &value);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_STREQ(error.what(), "function 'wall.c' reads x[2], but x has 2 components");
  }
  const SmoothFunction h = MakeSmoothFunction(
      "f", 1, [](const auto&, const auto&, const auto&, const auto&, auto& out) { out[1] = 0.0; });
  EXPECT_THROW(h.Evaluate(Vector{{1.0}}, Vector(), 0.0, Vector(), &value), std::invalid_argument);
}

TEST(SmoothFunctionTest, CopiesAreIndependent) {
  const SmoothFunction g = MakeTestFunction();
  const SmoothFunction copy = g;
  Vector a, b;
  g.Evaluate(Vector{{1.0, 2.0}}, Vector{{1.0}}, 0.0, Vector{{1.0, 1.0}}, &a);
  copy.Evaluate(Vector{{1.0, 2.0}}, Vector{{1.0}}, 0.0, Vector{{1.0, 1.0}}, &b);
  EXPECT_EQ(a, b);
  EXPECT_EQ(copy.name(), "test.g");
}

TEST(ConvergenceTest, FitOrderRecoversSyntheticOrders) {
  // Synthetic errors C h^p (1 + 0.05 h) with a round-off floor: the fit ignores the floor.
  for (double p : {1.0, 3.0, 5.0, 7.0}) {
    std::vector<double> h, e;
    for (double step = 0.2; step > 1e-3; step /= 2) {
      h.push_back(step);
      e.push_back(std::max(2.0 * std::pow(step, p) * (1 + 0.05 * step), 1e-14));
    }
    const OrderFit fit = FitOrder(h, e, 1e-13);
    ASSERT_GE(fit.points_used, 2);
    EXPECT_NEAR(fit.order, p, 0.05) << "p = " << p;
  }
  const OrderFit none = FitOrder({0.1, 0.05}, {1e-15, 1e-16}, 1e-13);
  EXPECT_LT(none.points_used, 2);
  EXPECT_THROW(FitOrder({0.1}, {1.0, 2.0}, 0.0), std::invalid_argument);
}

TEST(SmoothFunctionTest, StackedFunctionsConcatenateValuesAndDerivatives) {
  const SmoothFunction g = MakeTestFunction();
  const SmoothFunction h = MakeSmoothFunction(
      "test.h", 1, [](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::cos;
        out[0] = cos(x[1] * t) * u[0] + p[0] * p[1] * x[0];
      });
  const SmoothFunction stacked =
      MakeStackedFunction("stacked", {g, MakeZeroFunction("zero", 2), h});
  ASSERT_EQ(stacked.num_outputs(), 5);
  const Vector x{{1.5, -2.0}}, u{{0.5}}, p{{3.0, 4.0}};
  const double t = 0.3;
  Vector value, part;
  Matrix jac, part_jac;
  stacked.Jacobian(x, u, t, p, Wrt::All(), &value, &jac);
  g.Jacobian(x, u, t, p, Wrt::All(), &part, &part_jac);
  // Stacking only copies: the blocks are bit-identical to the parts'.
  EXPECT_EQ(value.head(2), part);
  EXPECT_EQ(jac.topRows(2), part_jac);
  EXPECT_EQ(value.segment(2, 2), Vector::Zero(2));
  EXPECT_EQ(jac.middleRows(2, 2), Matrix::Zero(2, jac.cols()));
  h.Jacobian(x, u, t, p, Wrt::All(), &part, &part_jac);
  EXPECT_EQ(value.tail(1), part);
  EXPECT_EQ(jac.bottomRows(1), part_jac);
  // Weighted Hessians add up part by part.
  const Vector weights{{0.7, -1.3, 5.0, 6.0, 2.1}};
  Matrix hess, hess_g, hess_h;
  stacked.WeightedHessian(x, u, t, p, Wrt::All(), weights, &hess);
  g.WeightedHessian(x, u, t, p, Wrt::All(), weights.head(2), &hess_g);
  h.WeightedHessian(x, u, t, p, Wrt::All(), weights.tail(1), &hess_h);
  EXPECT_LE((hess - hess_g - hess_h).lpNorm<Eigen::Infinity>(), kRoundOff);
  // A part with a hand-written Jacobian cannot be differentiated twice: refused by name.
  const SmoothFunction sparse = MakeSparseStateFunction(
      "sparse", 1, [](const auto&, const auto&, double, const auto&, VectorRef out) { out[0] = 1; },
      [](const auto& x_, const auto&, double, const auto&, SparseMatrix* jac_x) {
        jac_x->resize(1, x_.size());
      });
  try {
    MakeStackedFunction("bad", {g, sparse});
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("part 'sparse'"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace moreau
