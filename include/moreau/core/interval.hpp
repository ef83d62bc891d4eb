#pragma once
/// @file
/// Interval: the scalar type with which moreau bounds a model function over a box of states
/// and a time interval (interval arithmetic; Moore, Kearfott and Cloud, Introduction to
/// Interval Analysis, 2009).
///
/// A model function written once as a generic lambda (smooth_function.hpp) or as expressions
/// (expression.hpp) is evaluated a fifth time with T = Interval: every argument is an interval
/// [lower, upper] and every operation returns an interval that contains the operation's value
/// at every point of its operands' intervals. The result is therefore an enclosure of the
/// function's range over the box: rigorous (up to the accuracy of the C library's elementary
/// functions, which every bound absorbs by rounding outward by one ulp), and an overestimate
/// (the dependency problem: x - x over [0, 1] gives [-1, 1]) that shrinks linearly with the
/// box. Integrators use it to prove that an event indicator has no zero inside a step, which
/// sampling cannot: a pulse narrower than the distance between samples is inside the bound
/// (docs/fesd-formulation.md, section 11).
///
/// Branches: a comparison of intervals that overlap (and ValueOf, isfinite, isnan of a
/// non-degenerate interval) cannot be decided for every point of the box. It compares the
/// midpoints, so that the evaluation runs through, and marks the evaluation as undecided
/// (internal::IntervalFlags): its result is then not an enclosure, and SmoothFunction::Bounds
/// reports that no bound is available. The expression language has no comparisons; compiled
/// lambdas that branch get bounds only where the branch is decided over the whole box.
///
/// Domains: sqrt, log, pow with a non-integer exponent, asin and acos enclose the values at
/// the points of the operand interval where they are defined (sqrt([-1, 4]) = [0, 2]): the
/// operand interval is an overestimate, and the double evaluation at a point where the
/// operand is outside the domain is NaN anyway. An operand entirely outside the domain marks
/// the evaluation undecided. Division by an interval that contains zero gives the entire line.

#include <Eigen/Core>
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include "moreau/core/dual.hpp"

namespace moreau {

namespace internal {
// What an interval evaluation could not decide (see the file comment). The evaluator resets it
// before and reads it after each evaluation; thread-local, as evaluations are.
struct IntervalFlags {
  bool undecided = false;
};
inline IntervalFlags& CurrentIntervalFlags() {
  static thread_local IntervalFlags flags;
  return flags;
}
inline void MarkIntervalUndecided() { CurrentIntervalFlags().undecided = true; }
// The next double toward +infinity (RoundUp) or -infinity (RoundDown): std::nextafter's
// results, stepping the bit pattern directly (bounds are rounded twice per operation, and
// nextafter's library call and checks were a fifth of a large scene's crossing search). For a
// finite nonzero x, the neighbour away from zero is the bit pattern plus one, toward zero minus
// one; from -infinity the step up gives the most negative finite double, from +-0 the smallest
// subnormal of the step's sign; NaN and the infinity in the step's direction stay.
inline double RoundUp(double x) {
  if (x == 0.0) return std::numeric_limits<double>::denorm_min();
  if (!(x < std::numeric_limits<double>::infinity())) return x;  // +inf, NaN
  const auto bits = std::bit_cast<std::uint64_t>(x);
  return std::bit_cast<double>(x > 0.0 ? bits + 1 : bits - 1);
}
inline double RoundDown(double x) { return -RoundUp(-x); }
}  // namespace internal

/// A closed interval [lower, upper] of doubles (see file comment).
class Interval {
 public:
  Interval() = default;
  /// A point. Implicit so that literals mix with intervals.
  Interval(double value) : lower_(value), upper_(value) {}  // NOLINT(google-explicit-constructor)
  /// [lower, upper]; a NaN bound or lower > upper gives the entire line.
  Interval(double lower, double upper) : lower_(lower), upper_(upper) {
    if (!(lower <= upper)) *this = Entire();
  }
  /// The entire real line (an unknown value).
  static Interval Entire() {
    Interval entire;
    entire.lower_ = -std::numeric_limits<double>::infinity();
    entire.upper_ = std::numeric_limits<double>::infinity();
    return entire;
  }
  /// [lower, upper] widened outward by one ulp on each side (results of rounded operations).
  static Interval Outward(double lower, double upper) {
    return Interval(internal::RoundDown(lower), internal::RoundUp(upper));
  }

  /// The lower bound.
  double lower() const { return lower_; }
  /// The upper bound.
  double upper() const { return upper_; }
  /// The midpoint (0 for the entire line).
  double mid() const {
    if (std::isinf(lower_) || std::isinf(upper_)) {
      return std::isinf(lower_) && std::isinf(upper_) ? 0.0
                                                      : (std::isinf(lower_) ? upper_ : lower_);
    }
    return 0.5 * (lower_ + upper_);
  }
  /// upper - lower.
  double width() const { return upper_ - lower_; }
  /// True for a point (lower == upper).
  bool degenerate() const { return lower_ == upper_; }
  /// True if value lies in [lower, upper].
  bool contains(double value) const { return lower_ <= value && value <= upper_; }

  /// *this = *this + other.
  Interval& operator+=(const Interval& other);
  /// *this = *this - other.
  Interval& operator-=(const Interval& other);
  /// *this = *this * other.
  Interval& operator*=(const Interval& other);
  /// *this = *this / other.
  Interval& operator/=(const Interval& other);

 private:
  double lower_ = 0.0;
  double upper_ = 0.0;
};

// ---- arithmetic (outward rounded) -----------------------------------------------------------
inline Interval pow(const Interval& a, double b);

/// @name Interval arithmetic
/// Each result contains the operation's value at every point of its operands' intervals,
/// rounded outward by one ulp; a division by an interval that contains zero gives the entire
/// line.
/// @{

/// +a, -a, a + b, a - b, a * b, a / b of intervals and of an interval and a double.
inline Interval operator+(const Interval& a) { return a; }
inline Interval operator-(const Interval& a) { return Interval(-a.upper(), -a.lower()); }
inline Interval operator+(const Interval& a, const Interval& b) {
  return Interval::Outward(a.lower() + b.lower(), a.upper() + b.upper());
}
inline Interval operator-(const Interval& a, const Interval& b) {
  return Interval::Outward(a.lower() - b.upper(), a.upper() - b.lower());
}
namespace internal {
// The product of two bounds, with 0 * inf = 0 (a zero bound times an unbounded one).
inline double BoundProduct(double a, double b) { return a == 0.0 || b == 0.0 ? 0.0 : a * b; }
}  // namespace internal
/// a a: a square where both factors are the same object (x[0] * x[0] in a model function), a
/// product of independent intervals otherwise.
inline Interval operator*(const Interval& a, const Interval& b) {
  using internal::BoundProduct;
  if (&a == &b) return pow(a, 2.0);
  const double p1 = BoundProduct(a.lower(), b.lower()), p2 = BoundProduct(a.lower(), b.upper()),
               p3 = BoundProduct(a.upper(), b.lower()), p4 = BoundProduct(a.upper(), b.upper());
  return Interval::Outward(std::min({p1, p2, p3, p4}), std::max({p1, p2, p3, p4}));
}
inline Interval operator/(const Interval& a, const Interval& b) {
  if (b.contains(0.0)) return Interval::Entire();
  const double q1 = a.lower() / b.lower(), q2 = a.lower() / b.upper(), q3 = a.upper() / b.lower(),
               q4 = a.upper() / b.upper();
  return Interval::Outward(std::min({q1, q2, q3, q4}), std::max({q1, q2, q3, q4}));
}
inline Interval operator+(const Interval& a, double b) { return a + Interval(b); }
inline Interval operator+(double a, const Interval& b) { return Interval(a) + b; }
inline Interval operator-(const Interval& a, double b) { return a - Interval(b); }
inline Interval operator-(double a, const Interval& b) { return Interval(a) - b; }
inline Interval operator*(const Interval& a, double b) { return a * Interval(b); }
inline Interval operator*(double a, const Interval& b) { return Interval(a) * b; }
inline Interval operator/(const Interval& a, double b) { return a / Interval(b); }
inline Interval operator/(double a, const Interval& b) { return Interval(a) / b; }
/// @}

inline Interval& Interval::operator+=(const Interval& other) { return *this = *this + other; }
inline Interval& Interval::operator-=(const Interval& other) { return *this = *this - other; }
inline Interval& Interval::operator*=(const Interval& other) { return *this = *this * other; }
inline Interval& Interval::operator/=(const Interval& other) { return *this = *this / other; }

// ---- comparisons: decided where the intervals do not overlap (see file comment) -------------
namespace internal {
// a < b for every point (1), for none (0), or undecided (-1).
inline int CertainlyLess(const Interval& a, const Interval& b, bool or_equal) {
  if (or_equal ? a.upper() <= b.lower() : a.upper() < b.lower()) return 1;
  if (or_equal ? a.lower() > b.upper() : a.lower() >= b.upper()) return 0;
  return -1;
}
inline bool Decide(int certain, bool midpoints) {
  if (certain >= 0) return certain == 1;
  MarkIntervalUndecided();
  return midpoints;
}
}  // namespace internal
/// @name Comparisons
/// Decided where the intervals do not overlap; otherwise the midpoints are compared and the
/// evaluation is marked undecided (see the file comment).
/// @{

/// a < b, a <= b, a > b, a >= b, a == b, a != b of intervals and of an interval and a double.
inline bool operator<(const Interval& a, const Interval& b) {
  return internal::Decide(internal::CertainlyLess(a, b, false), a.mid() < b.mid());
}
inline bool operator<=(const Interval& a, const Interval& b) {
  return internal::Decide(internal::CertainlyLess(a, b, true), a.mid() <= b.mid());
}
inline bool operator>(const Interval& a, const Interval& b) { return b < a; }
inline bool operator>=(const Interval& a, const Interval& b) { return b <= a; }
inline bool operator==(const Interval& a, const Interval& b) {
  if (a.degenerate() && b.degenerate()) return a.lower() == b.lower();
  if (a.upper() < b.lower() || b.upper() < a.lower()) return false;
  internal::MarkIntervalUndecided();
  return a.mid() == b.mid();
}
inline bool operator!=(const Interval& a, const Interval& b) { return !(a == b); }
#define MOREAU_INTERVAL_MIXED_COMPARISON(op)                                        \
  inline bool operator op(const Interval& a, double b) { return a op Interval(b); } \
  inline bool operator op(double a, const Interval& b) { return Interval(a) op b; }
MOREAU_INTERVAL_MIXED_COMPARISON(<)
MOREAU_INTERVAL_MIXED_COMPARISON(<=)
MOREAU_INTERVAL_MIXED_COMPARISON(>)
MOREAU_INTERVAL_MIXED_COMPARISON(>=)
MOREAU_INTERVAL_MIXED_COMPARISON(==)
MOREAU_INTERVAL_MIXED_COMPARISON(!=)
#undef MOREAU_INTERVAL_MIXED_COMPARISON
/// @}

/// The midpoint, for code that inspects the value (undecided unless the interval is a point).
inline double ValueOf(const Interval& a) {
  if (!a.degenerate()) internal::MarkIntervalUndecided();
  return a.mid();
}
/// True if both bounds are finite (undecided if not, unless a point).
inline bool isfinite(const Interval& a) {  // NOLINT(readability-identifier-naming)
  const bool all = std::isfinite(a.lower()) && std::isfinite(a.upper());
  if (!all && !a.degenerate()) internal::MarkIntervalUndecided();
  return all;
}
/// False: an interval is never NaN (a NaN bound gives the entire line).
inline bool isnan(const Interval& /*a*/) { return false; }  // NOLINT

// ---- elementary functions -------------------------------------------------------------------
namespace internal {
// f monotone increasing on the interval.
template <class F>
Interval Increasing(const Interval& a, F f) {
  return Interval::Outward(f(a.lower()), f(a.upper()));
}
template <class F>
Interval Decreasing(const Interval& a, F f) {
  return Interval::Outward(f(a.upper()), f(a.lower()));
}
// The interval clipped to [low, high] (the domain of a function); undecided if it misses it.
inline bool ClipToDomain(const Interval& a, double low, double high, Interval* clipped) {
  if (a.upper() < low || a.lower() > high) {
    MarkIntervalUndecided();
    return false;
  }
  *clipped = Interval(std::max(a.lower(), low), std::min(a.upper(), high));
  return true;
}
// f monotone increasing on its domain [low, high]: the interval clipped to it first.
template <class F>
Interval IncreasingOn(const Interval& a, double low, double high, F f) {
  Interval clipped;
  if (!ClipToDomain(a, low, high, &clipped)) return Interval::Entire();
  return Increasing(clipped, f);
}
// True if x0 + k period lies in [lower, upper] for some integer k, counting points within a
// relative 1e-12 of the ends as inside (the reduction by the period rounds).
inline bool ContainsPeriodic(double lower, double upper, double x0, double period) {
  const double slack = 1e-12 * (1.0 + std::max(std::fabs(lower), std::fabs(upper)));
  const double k = std::ceil((lower - slack - x0) / period);
  return x0 + k * period <= upper + slack;
}
}  // namespace internal

/// @name Elementary functions of intervals
/// Each encloses the function's values at the points of its operand where it is defined
/// (monotone pieces evaluated at their ends, rounded outward by one ulp; sin and cos also
/// take their extrema inside the interval); an operand entirely outside the domain gives the
/// entire line and marks the evaluation undecided.
/// @{

/// sqrt, exp, log, the trigonometric, inverse and hyperbolic functions, abs, pow, hypot,
/// atan2, exp2, expm1, log2, log10, log1p, cbrt, erf and erfc of intervals; floor, ceil, round
/// and trunc refuse to compile, as for dual numbers.
inline Interval sqrt(const Interval& a) {
  Interval clipped;
  if (!internal::ClipToDomain(a, 0.0, std::numeric_limits<double>::infinity(), &clipped)) {
    return Interval::Entire();
  }
  const Interval r = internal::Increasing(clipped, [](double v) { return std::sqrt(v); });
  return Interval(std::max(r.lower(), 0.0), r.upper());
}
inline Interval exp(const Interval& a) {
  const Interval r = internal::Increasing(a, [](double v) { return std::exp(v); });
  return Interval(std::max(r.lower(), 0.0), r.upper());
}
inline Interval log(const Interval& a) {
  Interval clipped;
  if (!internal::ClipToDomain(a, 0.0, std::numeric_limits<double>::infinity(), &clipped)) {
    return Interval::Entire();
  }
  return internal::Increasing(clipped, [](double v) { return std::log(v); });
}
inline Interval sin(const Interval& a) {
  constexpr double kPi = 3.14159265358979323846;
  if (!(a.width() < 2.0 * kPi)) return Interval(-1.0, 1.0);
  double low = std::min(std::sin(a.lower()), std::sin(a.upper()));
  double high = std::max(std::sin(a.lower()), std::sin(a.upper()));
  if (internal::ContainsPeriodic(a.lower(), a.upper(), 0.5 * kPi, 2.0 * kPi)) high = 1.0;
  if (internal::ContainsPeriodic(a.lower(), a.upper(), -0.5 * kPi, 2.0 * kPi)) low = -1.0;
  const Interval r = Interval::Outward(low, high);
  return Interval(std::max(r.lower(), -1.0), std::min(r.upper(), 1.0));
}
inline Interval cos(const Interval& a) {
  constexpr double kPi = 3.14159265358979323846;
  if (!(a.width() < 2.0 * kPi)) return Interval(-1.0, 1.0);
  double low = std::min(std::cos(a.lower()), std::cos(a.upper()));
  double high = std::max(std::cos(a.lower()), std::cos(a.upper()));
  if (internal::ContainsPeriodic(a.lower(), a.upper(), 0.0, 2.0 * kPi)) high = 1.0;
  if (internal::ContainsPeriodic(a.lower(), a.upper(), kPi, 2.0 * kPi)) low = -1.0;
  const Interval r = Interval::Outward(low, high);
  return Interval(std::max(r.lower(), -1.0), std::min(r.upper(), 1.0));
}
inline Interval tan(const Interval& a) {
  constexpr double kPi = 3.14159265358979323846;
  if (!(a.width() < kPi) || internal::ContainsPeriodic(a.lower(), a.upper(), 0.5 * kPi, kPi)) {
    return Interval::Entire();
  }
  return internal::Increasing(a, [](double v) { return std::tan(v); });
}
inline Interval asin(const Interval& a) {
  Interval clipped;
  if (!internal::ClipToDomain(a, -1.0, 1.0, &clipped)) return Interval::Entire();
  return internal::Increasing(clipped, [](double v) { return std::asin(v); });
}
inline Interval acos(const Interval& a) {
  Interval clipped;
  if (!internal::ClipToDomain(a, -1.0, 1.0, &clipped)) return Interval::Entire();
  return internal::Decreasing(clipped, [](double v) { return std::acos(v); });
}
inline Interval atan(const Interval& a) {
  return internal::Increasing(a, [](double v) { return std::atan(v); });
}
inline Interval sinh(const Interval& a) {
  return internal::Increasing(a, [](double v) { return std::sinh(v); });
}
inline Interval tanh(const Interval& a) {
  return internal::Increasing(a, [](double v) { return std::tanh(v); });
}
/// |a|.
inline Interval abs(const Interval& a) {
  if (a.lower() >= 0.0) return a;
  if (a.upper() <= 0.0) return -a;
  return Interval(0.0, std::max(-a.lower(), a.upper()));
}
inline Interval fabs(const Interval& a) { return abs(a); }
inline Interval cosh(const Interval& a) {
  const Interval m = abs(a);
  return internal::Increasing(m, [](double v) { return std::cosh(v); });
}
/// a^b for a constant exponent: integer exponents on the whole line (even ones nonnegative),
/// others on a >= 0.
inline Interval pow(const Interval& a, double b) {
  if (b == 0.0) return Interval(1.0);
  if (b == 1.0) return a;
  if (b == std::round(b) && std::fabs(b) < 1e9) {
    const bool even = std::fmod(std::fabs(b), 2.0) == 0.0;
    if (b < 0.0) return Interval(1.0) / pow(a, -b);
    if (even) {
      // The square of a model's x * x (or pow(x, 2)): one correctly rounded product.
      if (b == 2.0) return internal::Increasing(abs(a), [](double v) { return v * v; });
      return internal::Increasing(abs(a), [b](double v) { return std::pow(v, b); });
    }
    return internal::Increasing(a, [b](double v) { return std::pow(v, b); });
  }
  Interval clipped;
  if (!internal::ClipToDomain(a, 0.0, std::numeric_limits<double>::infinity(), &clipped)) {
    return Interval::Entire();
  }
  if (b > 0.0) return internal::Increasing(clipped, [b](double v) { return std::pow(v, b); });
  if (clipped.contains(0.0)) return Interval::Entire();
  return internal::Decreasing(clipped, [b](double v) { return std::pow(v, b); });
}
/// a^b = exp(b log a) for a > 0 (a degenerate exponent: the constant-exponent form).
inline Interval pow(const Interval& a, const Interval& b) {
  if (b.degenerate()) return pow(a, b.lower());
  return exp(b * log(a));
}
inline Interval pow(double a, const Interval& b) { return pow(Interval(a), b); }
inline Interval hypot(const Interval& a, const Interval& b) {
  const Interval x = abs(a), y = abs(b);
  return Interval::Outward(std::hypot(x.lower(), y.lower()), std::hypot(x.upper(), y.upper()));
}
inline Interval hypot(const Interval& a, double b) { return hypot(a, Interval(b)); }
inline Interval hypot(double a, const Interval& b) { return hypot(Interval(a), b); }
/// atan2(y, x): the angles of the box's corners where the box avoids the origin and the branch
/// cut (x <= 0, y = 0; the angle of a convex set is an arc ending at extreme points), else
/// [-pi, pi].
inline Interval atan2(const Interval& y, const Interval& x) {
  constexpr double kPi = 3.14159265358979323846;
  const bool cut = x.lower() <= 0.0 && y.contains(0.0);
  if (cut) return Interval::Outward(-kPi, kPi);
  const double a1 = std::atan2(y.lower(), x.lower()), a2 = std::atan2(y.lower(), x.upper()),
               a3 = std::atan2(y.upper(), x.lower()), a4 = std::atan2(y.upper(), x.upper());
  return Interval::Outward(std::min({a1, a2, a3, a4}), std::max({a1, a2, a3, a4}));
}
inline Interval atan2(const Interval& y, double x) { return atan2(y, Interval(x)); }
inline Interval atan2(double y, const Interval& x) { return atan2(Interval(y), x); }
// The other elementary functions of the model language (dual.hpp).
inline Interval exp2(const Interval& a) {
  const Interval r = internal::Increasing(a, [](double v) { return std::exp2(v); });
  return Interval(std::max(r.lower(), 0.0), r.upper());
}
inline Interval expm1(const Interval& a) {
  const Interval r = internal::Increasing(a, [](double v) { return std::expm1(v); });
  return Interval(std::max(r.lower(), -1.0), r.upper());
}
inline Interval log2(const Interval& a) {
  return internal::IncreasingOn(a, 0.0, std::numeric_limits<double>::infinity(),
                                [](double v) { return std::log2(v); });
}
inline Interval log10(const Interval& a) {
  return internal::IncreasingOn(a, 0.0, std::numeric_limits<double>::infinity(),
                                [](double v) { return std::log10(v); });
}
inline Interval log1p(const Interval& a) {
  return internal::IncreasingOn(a, -1.0, std::numeric_limits<double>::infinity(),
                                [](double v) { return std::log1p(v); });
}
inline Interval cbrt(const Interval& a) {
  return internal::Increasing(a, [](double v) { return std::cbrt(v); });
}
inline Interval asinh(const Interval& a) {
  return internal::Increasing(a, [](double v) { return std::asinh(v); });
}
inline Interval acosh(const Interval& a) {
  const Interval r = internal::IncreasingOn(a, 1.0, std::numeric_limits<double>::infinity(),
                                            [](double v) { return std::acosh(v); });
  return Interval(std::max(r.lower(), 0.0), r.upper());
}
inline Interval atanh(const Interval& a) {
  return internal::IncreasingOn(a, -1.0, 1.0, [](double v) { return std::atanh(v); });
}
inline Interval erf(const Interval& a) {
  const Interval r = internal::Increasing(a, [](double v) { return std::erf(v); });
  return Interval(std::max(r.lower(), -1.0), std::min(r.upper(), 1.0));
}
inline Interval erfc(const Interval& a) {
  const Interval r = internal::Decreasing(a, [](double v) { return std::erfc(v); });
  return Interval(std::max(r.lower(), 0.0), std::min(r.upper(), 2.0));
}

// Rounding is refused in model functions with dual.hpp's message (the same code is also
// evaluated with dual numbers, where it must not compile; this makes the interval evaluation
// fail with the same words instead of a missing overload).
#define MOREAU_INTERVAL_REFUSED_ROUNDING(name)                                \
  template <class Refused = void>                                             \
  Interval name(const Interval& a) {                                          \
    static_assert(internal::kRefusedForAd<Refused>, MOREAU_REFUSED_ROUNDING); \
    return a;                                                                 \
  }
MOREAU_INTERVAL_REFUSED_ROUNDING(floor)
MOREAU_INTERVAL_REFUSED_ROUNDING(ceil)
MOREAU_INTERVAL_REFUSED_ROUNDING(round)
MOREAU_INTERVAL_REFUSED_ROUNDING(trunc)
#undef MOREAU_INTERVAL_REFUSED_ROUNDING
/// @}

}  // namespace moreau

// The Interval overloads declared in namespace std as well, as dual.hpp does for dual numbers
// (model code may call std::exp2(x)).
MOREAU_DECLARE_MATH_IN_STD

// Eigen integration so that Eigen::Matrix<moreau::Interval, ...> works in model code.
namespace Eigen {
template <>
struct NumTraits<moreau::Interval> : GenericNumTraits<moreau::Interval> {
  using Real = moreau::Interval;
  using NonInteger = moreau::Interval;
  using Nested = moreau::Interval;
  using Literal = double;
  enum {
    IsComplex = 0,
    IsInteger = 0,
    IsSigned = 1,
    RequireInitialization = 1,
    ReadCost = 1,
    AddCost = 4,
    MulCost = 8
  };
  static Real epsilon() { return Real(NumTraits<double>::epsilon()); }
  static Real dummy_precision() { return Real(NumTraits<double>::dummy_precision()); }
  static Real highest() { return Real(NumTraits<double>::highest()); }
  static Real lowest() { return Real(NumTraits<double>::lowest()); }
  static int digits10() { return NumTraits<double>::digits10(); }
};
template <class BinaryOp>
struct ScalarBinaryOpTraits<moreau::Interval, double, BinaryOp> {
  using ReturnType = moreau::Interval;
};
template <class BinaryOp>
struct ScalarBinaryOpTraits<double, moreau::Interval, BinaryOp> {
  using ReturnType = moreau::Interval;
};
}  // namespace Eigen
