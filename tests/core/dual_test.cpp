#include "moreau/core/dual.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace moreau {
namespace {

using D1 = Dual<double>;
using D2 = Dual<Dual<double>>;

// Derivatives of elementary functions are exact to round-off: compare with the analytic
// derivative at a few points, tolerance 4 ulp-ish relative (1e-15).
constexpr double kRoundOff = 1e-15;

template <class F, class G>
void ExpectDerivative(F f, G dfdx, double x) {
  const D1 v = f(D1::Variable(x, 1, 0));
  EXPECT_NEAR(v.value(), f(x), kRoundOff * (1 + std::fabs(f(x))));
  EXPECT_NEAR(v.d(0), dfdx(x), kRoundOff * (1 + std::fabs(dfdx(x)))) << "at x = " << x;
}

TEST(DualTest, ElementaryFunctionsHaveExactDerivatives) {
  using std::atan;
  using std::cos;
  using std::exp;
  using std::log;
  using std::pow;
  using std::sin;
  using std::sqrt;
  for (double x : {0.3, 0.7, 1.9}) {
    ExpectDerivative([](auto a) { return sin(a); }, [](double a) { return std::cos(a); }, x);
    ExpectDerivative([](auto a) { return cos(a); }, [](double a) { return -std::sin(a); }, x);
    ExpectDerivative([](auto a) { return exp(a); }, [](double a) { return std::exp(a); }, x);
    ExpectDerivative([](auto a) { return log(a); }, [](double a) { return 1 / a; }, x);
    ExpectDerivative([](auto a) { return sqrt(a); }, [](double a) { return 0.5 / std::sqrt(a); },
                     x);
    ExpectDerivative([](auto a) { return atan(a); }, [](double a) { return 1 / (1 + a * a); }, x);
    ExpectDerivative([](auto a) { return pow(a, 2.5); },
                     [](double a) { return 2.5 * std::pow(a, 1.5); }, x);
    ExpectDerivative([](auto a) { return 1.0 / (a * a + 1.0) - a / 3.0; },
                     [](double a) { return -2 * a / ((a * a + 1) * (a * a + 1)) - 1.0 / 3.0; }, x);
  }
}

TEST(DualTest, Atan2PartialDerivatives) {
  const D1 y = D1::Variable(0.4, 2, 0);
  const D1 x = D1::Variable(-1.3, 2, 1);
  const D1 r = atan2(y, x);
  const double d = 0.4 * 0.4 + 1.3 * 1.3;
  EXPECT_NEAR(r.value(), std::atan2(0.4, -1.3), kRoundOff);
  EXPECT_NEAR(r.d(0), -1.3 / d, kRoundOff);
  EXPECT_NEAR(r.d(1), -0.4 / d, kRoundOff);
}

TEST(DualTest, NestedDualGivesTheHessian) {
  // f(x, y) = x^2 y + sin(x y); Hessian [[2y - y^2 s, 2x + c - x y s], [.., -x^2 s]].
  const double x0 = 0.7, y0 = -0.4;
  auto seed = [](double v, int i) { return D2::Variable(D1::Variable(v, 2, i), 2, i); };
  const D2 x = seed(x0, 0), y = seed(y0, 1);
  const D2 f = x * x * y + sin(x * y);
  const double s = std::sin(x0 * y0), c = std::cos(x0 * y0);
  EXPECT_NEAR(f.d(0).value(), 2 * x0 * y0 + y0 * c, kRoundOff);
  EXPECT_NEAR(f.d(0).d(0), 2 * y0 - y0 * y0 * s, kRoundOff);
  EXPECT_NEAR(f.d(0).d(1), 2 * x0 + c - x0 * y0 * s, kRoundOff);
  EXPECT_NEAR(f.d(1).d(0), 2 * x0 + c - x0 * y0 * s, kRoundOff);
  EXPECT_NEAR(f.d(1).d(1), -x0 * x0 * s, kRoundOff);
}

TEST(DualTest, ConstantsMixWithSeededNumbers) {
  const D1 x = D1::Variable(2.0, 3, 1);
  const D1 y = 3.0 * x - 1.0 + D1(5.0) / x;
  EXPECT_DOUBLE_EQ(y.value(), 7.5);
  EXPECT_DOUBLE_EQ(y.d(0), 0.0);
  EXPECT_DOUBLE_EQ(y.d(1), 3.0 - 5.0 / 4.0);
  EXPECT_TRUE(ValueOf(x) > 1.0);
  EXPECT_TRUE(isfinite(x));
}

}  // namespace
}  // namespace moreau
