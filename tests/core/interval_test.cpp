#include "moreau/core/interval.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "moreau/core/smooth_function.hpp"
#include "moreau/model/expression.hpp"

namespace moreau {
namespace {

// Points per interval at which the enclosure is checked (the ends, and equally spaced inside).
constexpr int kSamples = 101;

// Every value of f at points of [lo, hi] lies in the enclosure F([lo, hi]), for a grid of
// intervals across `range` (widths from 1e-6 to the whole range).
void ExpectEncloses(const std::string& name, const std::function<double(double)>& f,
                    const std::function<Interval(const Interval&)>& enclosure, double low,
                    double high) {
  for (double width : {1e-6, 1e-3, 0.1, 1.0, high - low}) {
    for (double a = low; a + width <= high + 1e-12; a += std::max(width, (high - low) / 37.0)) {
      const Interval bound = enclosure(Interval(a, a + width));
      for (int k = 0; k < kSamples; ++k) {
        const double x = a + width * k / (kSamples - 1);
        const double value = f(x);
        if (!std::isfinite(value)) continue;  // outside the function's domain
        ASSERT_TRUE(bound.lower() <= value && value <= bound.upper())
            << name << " at " << x << " in [" << a << ", " << a + width << "]: " << value
            << " outside [" << bound.lower() << ", " << bound.upper() << "]";
      }
    }
  }
}

TEST(IntervalTest, ElementaryFunctionsEncloseTheirValues) {
  ExpectEncloses(
      "sin", [](double x) { return std::sin(x); }, [](const Interval& x) { return sin(x); }, -10.0,
      10.0);
  ExpectEncloses(
      "cos", [](double x) { return std::cos(x); }, [](const Interval& x) { return cos(x); }, -10.0,
      10.0);
  ExpectEncloses(
      "tan", [](double x) { return std::tan(x); }, [](const Interval& x) { return tan(x); }, -1.5,
      1.5);
  ExpectEncloses(
      "exp", [](double x) { return std::exp(x); }, [](const Interval& x) { return exp(x); }, -20.0,
      20.0);
  ExpectEncloses(
      "log", [](double x) { return std::log(x); }, [](const Interval& x) { return log(x); }, 1e-3,
      10.0);
  ExpectEncloses(
      "sqrt", [](double x) { return std::sqrt(x); }, [](const Interval& x) { return sqrt(x); },
      -1.0, 10.0);
  ExpectEncloses(
      "x^2", [](double x) { return x * x; }, [](const Interval& x) { return pow(x, 2.0); }, -3.0,
      3.0);
  ExpectEncloses(
      "x^3", [](double x) { return x * x * x; }, [](const Interval& x) { return pow(x, 3.0); },
      -3.0, 3.0);
  ExpectEncloses(
      "x^-2", [](double x) { return 1.0 / (x * x); },
      [](const Interval& x) { return pow(x, -2.0); }, 0.1, 3.0);
  ExpectEncloses(
      "x^1.5", [](double x) { return std::pow(x, 1.5); },
      [](const Interval& x) { return pow(x, 1.5); }, 0.0, 4.0);
  ExpectEncloses(
      "atan", [](double x) { return std::atan(x); }, [](const Interval& x) { return atan(x); },
      -5.0, 5.0);
  ExpectEncloses(
      "asin", [](double x) { return std::asin(x); }, [](const Interval& x) { return asin(x); },
      -1.0, 1.0);
  ExpectEncloses(
      "acos", [](double x) { return std::acos(x); }, [](const Interval& x) { return acos(x); },
      -1.0, 1.0);
  ExpectEncloses(
      "sinh", [](double x) { return std::sinh(x); }, [](const Interval& x) { return sinh(x); },
      -3.0, 3.0);
  ExpectEncloses(
      "cosh", [](double x) { return std::cosh(x); }, [](const Interval& x) { return cosh(x); },
      -3.0, 3.0);
  ExpectEncloses(
      "tanh", [](double x) { return std::tanh(x); }, [](const Interval& x) { return tanh(x); },
      -3.0, 3.0);
  ExpectEncloses(
      "abs", [](double x) { return std::fabs(x); }, [](const Interval& x) { return abs(x); }, -3.0,
      3.0);
  ExpectEncloses(
      "1/(1+x^2)", [](double x) { return 1.0 / (1.0 + x * x); },
      [](const Interval& x) { return 1.0 / (1.0 + x * x); }, -3.0, 3.0);
  // atan2 around the origin (the branch cut on the negative axis gives [-pi, pi]).
  for (double y : {-1.0, -0.1, 0.0, 0.2, 1.0}) {
    ExpectEncloses(
        "atan2", [y](double x) { return std::atan2(y, x); },
        [y](const Interval& x) { return atan2(Interval(y - 0.05, y + 0.05), x); }, -2.0, 2.0);
  }
  ExpectEncloses(
      "hypot", [](double x) { return std::hypot(x, 0.5); },
      [](const Interval& x) { return hypot(x, Interval(0.5)); }, -3.0, 3.0);
  // The other functions of the model language, written with std:: as model code may.
  ExpectEncloses(
      "exp2", [](double x) { return std::exp2(x); }, [](const Interval& x) { return std::exp2(x); },
      -20.0, 20.0);
  ExpectEncloses(
      "expm1", [](double x) { return std::expm1(x); },
      [](const Interval& x) { return std::expm1(x); }, -20.0, 5.0);
  ExpectEncloses(
      "log2", [](double x) { return std::log2(x); }, [](const Interval& x) { return std::log2(x); },
      1e-3, 10.0);
  ExpectEncloses(
      "log10", [](double x) { return std::log10(x); },
      [](const Interval& x) { return std::log10(x); }, 1e-3, 10.0);
  ExpectEncloses(
      "log1p", [](double x) { return std::log1p(x); },
      [](const Interval& x) { return std::log1p(x); }, -0.999, 10.0);
  ExpectEncloses(
      "cbrt", [](double x) { return std::cbrt(x); }, [](const Interval& x) { return std::cbrt(x); },
      -8.0, 8.0);
  ExpectEncloses(
      "asinh", [](double x) { return std::asinh(x); },
      [](const Interval& x) { return std::asinh(x); }, -5.0, 5.0);
  ExpectEncloses(
      "acosh", [](double x) { return std::acosh(x); },
      [](const Interval& x) { return std::acosh(x); }, 1.0, 5.0);
  ExpectEncloses(
      "atanh", [](double x) { return std::atanh(x); },
      [](const Interval& x) { return std::atanh(x); }, -0.99, 0.99);
  ExpectEncloses(
      "erf", [](double x) { return std::erf(x); }, [](const Interval& x) { return std::erf(x); },
      -4.0, 4.0);
  ExpectEncloses(
      "erfc", [](double x) { return std::erfc(x); }, [](const Interval& x) { return std::erfc(x); },
      -4.0, 4.0);
}

TEST(IntervalTest, ArithmeticIsOutwardRoundedAndSquaresAreSquares) {
  const Interval a(1.0, 2.0), b(-3.0, 0.5);
  const Interval product = a * b;
  EXPECT_LE(product.lower(), -6.0);
  EXPECT_GE(product.upper(), 1.0);
  EXPECT_LT(product.lower(), -6.0 + 1e-14);
  // 0.1 + 0.2 is not representable: the enclosure holds the real sum.
  const Interval sum = Interval(0.1) + Interval(0.2);
  EXPECT_LT(sum.lower(), sum.upper());
  EXPECT_TRUE(sum.contains(0.1 + 0.2));
  // x * x with one object is the square (the dependency problem is avoided where the model
  // writes it so); a product of two objects with the same bounds is the product.
  const Interval x(-2.0, 3.0), y(-2.0, 3.0);
  // (Its lower bound is 0 rounded outward by one ulp, the policy of every rounded operation.)
  EXPECT_GE((x * x).lower(), -std::numeric_limits<double>::denorm_min());
  EXPECT_LE((x * y).lower(), -6.0);
  EXPECT_TRUE((Interval(1.0) / Interval(-1.0, 1.0)).lower() == -HUGE_VAL);
}

// The outward rounding steps bit patterns instead of calling std::nextafter: the same doubles at
// every kind of operand (zeros of both signs, subnormals, the largest finite double, the
// infinities), so that every enclosure is what it was with nextafter.
TEST(IntervalTest, OutwardRoundingIsNextafter) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const double values[] = {0.0,
                           -0.0,
                           std::numeric_limits<double>::denorm_min(),
                           -std::numeric_limits<double>::denorm_min(),
                           std::numeric_limits<double>::min(),
                           -std::numeric_limits<double>::min(),
                           1.0,
                           -1.0,
                           0.1,
                           -3.75e200,
                           std::numeric_limits<double>::max(),
                           -std::numeric_limits<double>::max(),
                           kInf,
                           -kInf};
  for (const double v : values) {
    const double up = internal::RoundUp(v), down = internal::RoundDown(v);
    const double next_up = std::nextafter(v, kInf), next_down = std::nextafter(v, -kInf);
    EXPECT_EQ(std::memcmp(&up, &next_up, sizeof(double)), 0) << "up from " << v;
    EXPECT_EQ(std::memcmp(&down, &next_down, sizeof(double)), 0) << "down from " << v;
  }
  EXPECT_TRUE(std::isnan(internal::RoundUp(std::nan(""))));
  EXPECT_TRUE(std::isnan(internal::RoundDown(std::nan(""))));
  // A square's bounds are the squares of its end points' magnitudes, rounded outward.
  const Interval x(-3.0, 0.1);
  const Interval square = x * x;
  EXPECT_EQ(square.upper(), std::nextafter(9.0, kInf));
  EXPECT_EQ(square.lower(), -std::numeric_limits<double>::denorm_min());
  EXPECT_EQ(pow(Interval(0.5, 3.0), 2.0).lower(), std::nextafter(0.25, -kInf));
}

TEST(IntervalTest, UndecidedComparisonsMarkTheEvaluation) {
  internal::CurrentIntervalFlags() = {};
  EXPECT_TRUE(Interval(0.0, 1.0) < Interval(2.0, 3.0));
  EXPECT_FALSE(internal::CurrentIntervalFlags().undecided);
  (void)(Interval(0.0, 2.0) < Interval(1.0, 3.0));
  EXPECT_TRUE(internal::CurrentIntervalFlags().undecided);
  internal::CurrentIntervalFlags() = {};
}

TEST(IntervalTest, SmoothFunctionBoundsOverABox) {
  // A lambda: c = x0^2 + sin(t) x1, over x0 in [-1, 2], x1 in [0, 1], t in [0, pi/2].
  const SmoothFunction f = MakeSmoothFunction(
      "c", 1, [](const auto& x, const auto&, const auto& t, const auto&, auto& out) {
        using std::sin;
        out[0] = x[0] * x[0] + sin(t) * x[1];
      });
  Vector lower, upper;
  ASSERT_TRUE(f.Bounds(Vector{{-1.0, 0.0}}, Vector{{2.0, 1.0}}, Vector(), 0.0, 1.5707963267948966,
                       Vector(), &lower, &upper));
  EXPECT_LE(lower[0], 0.0);
  EXPECT_GE(lower[0], -1e-12);  // x0^2 >= 0 and sin(t) x1 >= 0: the bound is tight below
  EXPECT_GE(upper[0], 5.0);
  EXPECT_LE(upper[0], 5.0 + 1e-12);
  // A branch on the value (model functions may branch only through ValueOf, which an interval
  // answers with its midpoint): undecided over a box, so no bound; decided at a point.
  const SmoothFunction branching = MakeSmoothFunction(
      "relu", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = ValueOf(x[0]) > 0.0 ? x[0] : 0.0 * x[0];
      });
  EXPECT_FALSE(branching.Bounds(Vector{{-1.0}}, Vector{{1.0}}, Vector(), 0.0, 0.0, Vector(), &lower,
                                &upper));
  EXPECT_FALSE(
      branching.Bounds(Vector{{0.5}}, Vector{{1.0}}, Vector(), 0.0, 0.0, Vector(), &lower, &upper));
  EXPECT_TRUE(
      branching.Bounds(Vector{{0.5}}, Vector{{0.5}}, Vector(), 0.0, 0.0, Vector(), &lower, &upper));
  EXPECT_EQ(lower[0], 0.5);
  // An expression (the scene-file language): the Gaussian pulse of a switching function,
  // exp(-((t - 2)/w)^2) - 1/2, is bounded over a time interval as exactly as over a point (x^2
  // is evaluated as the square it is): on [1.9, 2.1] with w = 0.05 it reaches its maximum 1/2.
  ExpressionModel model({{"x"}, {}, {"w"}, {}});
  const SmoothFunction pulse = model.Function("pulse", {"exp(-((t - 2)/w)^2) - 0.5"}, {});
  ASSERT_TRUE(pulse.Bounds(Vector{{0.0}}, Vector{{0.0}}, Vector(), 1.9, 2.1, Vector{{0.05}}, &lower,
                           &upper));
  EXPECT_GE(upper[0], 0.5);
  EXPECT_LE(upper[0], 0.5 + 1e-12);
  EXPECT_LE(lower[0], std::exp(-4.0) - 0.5);
  ASSERT_TRUE(pulse.Bounds(Vector{{0.0}}, Vector{{0.0}}, Vector(), 0.0, 1.8, Vector{{0.05}}, &lower,
                           &upper));
  EXPECT_LT(upper[0], 0.0);  // the pulse is below 1/2 before t = 1.9: no crossing there
}

}  // namespace
}  // namespace moreau
