#pragma once
/// @file
/// Forward-mode automatic differentiation: a dual number carrying up to
/// Dual<T>::kCapacity directional derivatives next to its value.
///
/// Dual<double> gives first derivatives; the nested Dual<Dual<double>> gives second
/// derivatives (the inner level seeds one set of directions, the outer level another),
/// which the gradient-form lowering of moving sets needs for its exact Jacobian
/// (d/dx of grad c(x) lambda). moreau uses this type instead of Eigen's unsupported
/// AutoDiffScalar because the latter does not compile nested (second-order) for several
/// elementary functions and stores derivative expressions by reference.
///
/// Derivative directions are stored inline (no heap allocation). Callers that need more
/// directions than kCapacity evaluate in chunks (see SmoothFunction). A constant has
/// size() == 0; binary operations between a constant and a seeded number treat the
/// constant's derivatives as zero.
///
/// **Model code reads like maths.** The smooth elementary functions (sin, cos, tan, exp,
/// log, sqrt, pow, atan2, hypot, the hyperbolic and inverse functions, erf, ...) take dual
/// numbers however they are called: `sin(x)`, `std::sin(x)`, or `using std::sin; sin(x)`.
/// The overloads live in namespace moreau (found by argument-dependent lookup) and are also
/// declared in namespace std by using-declarations (see the end of this file: the C++
/// standard reserves namespace std, but every compiler moreau supports accepts these
/// declarations, which only add overloads for moreau's own types).
///
/// **Nonsmooth operations do not compile.** abs, fabs, min, max, fmin, fmax, floor, ceil,
/// round, trunc, fmod and the comparisons <, <=, >, >=, ==, != on dual numbers stop the
/// compilation with a static_assert whose message names the effect that models the
/// behaviour (a SwitchingSurfaces effect for a kink or a mode, a MovingSet or
/// PathConstraints effect for a bound, a HysteresisRelay for a switch with memory, a
/// piecewise-constant input for a jump in time), exactly as scene files refuse them: a kink
/// hidden in a model function is invisible to the integrators, which then lose their order
/// and may step over the switch. A branch that provably never changes during a run (a guard
/// of a formula at a point the run never reaches) may test the value explicitly with
/// moreau::ValueOf(x).

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <type_traits>

#include "moreau/core/error.hpp"

namespace moreau {

/// A dual number: a value of type T (double, or a dual number for second derivatives) and up
/// to kCapacity directional derivatives (see the file comment).
template <class T>
class Dual {
 public:
  /// Number of derivative directions stored inline.
  static constexpr int kCapacity = 16;

  Dual() : value_(0.0), size_(0) {}
  /// A constant (no derivative directions). Implicit so that literals mix with duals.
  Dual(double value) : value_(value), size_(0) {}  // NOLINT(google-explicit-constructor)
  /// A constant of the value type (for nested duals).
  template <class U = T, class = std::enable_if_t<!std::is_same_v<U, double>>>
  Dual(const T& value) : value_(value), size_(0) {}  // NOLINT(google-explicit-constructor)
  /// A number with `size` derivative directions, all zero.
  Dual(const T& value, int size) : value_(value), size_(size) {
    MOREAU_ASSERT(size >= 0 && size <= kCapacity, "dual size out of range");
    for (int i = 0; i < kCapacity; ++i) {
      if (i < size_) d_[i] = T(0.0);  // (loop form: see the copy constructor)
    }
  }
  /// Copies carry the value and the size() active directions only: a constant copies in
  /// O(1), not kCapacity derivatives (for Dual<Dual<double>> the difference is ~2.4 kB per
  /// copy, which dominates evaluations where most values are constants).
  Dual(const Dual& other) : value_(other.value_), size_(other.size_) { CopyDirections(other); }
  /// Copies the value and the size() active directions.
  Dual& operator=(const Dual& other) {
    value_ = other.value_;
    size_ = other.size_;
    CopyDirections(other);
    return *this;
  }
  ~Dual() = default;
  /// A seeded variable: derivative 1 in direction `direction` of `size`.
  static Dual Variable(const T& value, int size, int direction) {
    Dual result(value, size);
    result.d_[direction] = T(1.0);
    return result;
  }

  /// The value (a double, or the inner dual number of a nested dual).
  const T& value() const { return value_; }
  /// The value, writable.
  T& value() { return value_; }
  /// Number of active derivative directions (0 for a constant).
  int size() const { return size_; }
  /// Derivative in direction i (0 <= i < size()).
  const T& d(int i) const { return d_[i]; }
  /// Derivative in direction i, writable.
  T& d(int i) { return d_[i]; }

  /// Compound assignments, by the binary operators below.
  Dual& operator+=(const Dual& other) { return *this = *this + other; }
  /// *this = *this - other.
  Dual& operator-=(const Dual& other) { return *this = *this - other; }
  /// *this = *this * other.
  Dual& operator*=(const Dual& other) { return *this = *this * other; }
  /// *this = *this / other.
  Dual& operator/=(const Dual& other) { return *this = *this / other; }

  /// A number with `size` derivative directions left unset: the caller writes all of them
  /// (the chain rules below; zeroing them first doubled their stores).
  struct Unset {};
  /// The constructor that leaves the directions unset (see Unset).
  Dual(const T& value, int size, Unset) : value_(value), size_(size) {}

 private:
  // The first size_ directions of other. A loop over the capacity with a test, not up to
  // size_: GCC turns the latter into a memcpy or `rep movs` of a few doubles, whose start-up
  // cost dominated Jacobian evaluations of small functions (FESD's element cost).
  void CopyDirections(const Dual& other) {
    for (int i = 0; i < kCapacity; ++i) {
      if (i < size_) d_[i] = other.d_[i];
    }
  }

  T value_;
  int size_;
  std::array<T, kCapacity> d_;
};

namespace internal {
template <class T>
struct IsDual : std::false_type {};
template <class T>
struct IsDual<Dual<T>> : std::true_type {};
}  // namespace internal

/// The innermost double value of a (possibly nested) dual number or a double: the explicit
/// way to branch on a value (see the file comment).
inline double ValueOf(double x) { return x; }
/// The innermost double value of a dual number (nested duals included).
template <class T>
double ValueOf(const Dual<T>& x) {
  return ValueOf(x.value());
}

namespace internal {
// Result with value `value` and derivatives da * a.d + db * b.d (chain rule for binary ops).
// Always inlined: Jacobian evaluations are mostly these chain rules, and out of line GCC
// neither knows the constant factors of + and - (1 and -1, whose products it folds
// exactly) nor that the result aliases neither operand.
template <class T>
[[gnu::always_inline]] inline Dual<T> Combine(const T& value, const Dual<T>& a, const T& da,
                                              const Dual<T>& b, const T& db) {
  const int n = a.size() > b.size() ? a.size() : b.size();
  Dual<T> result(value, n, typename Dual<T>::Unset{});  // every direction written below
  if (a.size() == n && b.size() == n) {
    for (int i = 0; i < n; ++i) result.d(i) = da * a.d(i) + db * b.d(i);
  } else if (a.size() == n) {
    MOREAU_ASSERT(b.size() == 0, "dual numbers with different seed sizes");
    for (int i = 0; i < n; ++i) result.d(i) = da * a.d(i);
  } else {
    MOREAU_ASSERT(a.size() == 0, "dual numbers with different seed sizes");
    for (int i = 0; i < n; ++i) result.d(i) = db * b.d(i);
  }
  return result;
}
// Result with value `value` and derivatives da * a.d (chain rule for unary functions).
template <class T>
Dual<T> Chain(const T& value, const Dual<T>& a, const T& da) {
  Dual<T> result(value, a.size(), typename Dual<T>::Unset{});  // every direction written
  for (int i = 0; i < a.size(); ++i) result.d(i) = da * a.d(i);
  return result;
}
}  // namespace internal

// ---- arithmetic -------------------------------------------------------------------------
/// @name Arithmetic on dual numbers
/// The value of the result is the double (or inner dual) arithmetic of the values, except
/// for the quotient of two dual numbers, whose value is a * (1 / b) (the inverse serves the
/// derivatives too), which may differ from a / b in the last bit; its derivatives follow by
/// the chain rule. The mixed forms with a double operand treat the
/// double as a constant (no derivative directions), so `2.0 * x` and `x - 1.0` need no
/// conversion.
/// @{

/// Unary plus, minus and the binary operators (chain rule; constants mix with seeded numbers).
template <class T>
Dual<T> operator+(const Dual<T>& a) {
  return a;
}
template <class T>
Dual<T> operator-(const Dual<T>& a) {
  return internal::Chain<T>(-a.value(), a, T(-1.0));
}
template <class T>
Dual<T> operator+(const Dual<T>& a, const Dual<T>& b) {
  return internal::Combine<T>(a.value() + b.value(), a, T(1.0), b, T(1.0));
}
template <class T>
Dual<T> operator-(const Dual<T>& a, const Dual<T>& b) {
  return internal::Combine<T>(a.value() - b.value(), a, T(1.0), b, T(-1.0));
}
template <class T>
Dual<T> operator*(const Dual<T>& a, const Dual<T>& b) {
  return internal::Combine<T>(a.value() * b.value(), a, b.value(), b, a.value());
}
template <class T>
Dual<T> operator/(const Dual<T>& a, const Dual<T>& b) {
  const T inverse = T(1.0) / b.value();
  const T quotient = a.value() * inverse;
  return internal::Combine<T>(quotient, a, inverse, b, -quotient * inverse);
}
// Mixed forms with double (so that `2.0 * x` and `x - 1.0` need no conversion).
template <class T>
Dual<T> operator+(const Dual<T>& a, double b) {
  return a + Dual<T>(b);
}
template <class T>
Dual<T> operator+(double a, const Dual<T>& b) {
  return Dual<T>(a) + b;
}
template <class T>
Dual<T> operator-(const Dual<T>& a, double b) {
  return a - Dual<T>(b);
}
template <class T>
Dual<T> operator-(double a, const Dual<T>& b) {
  return Dual<T>(a) - b;
}
template <class T>
Dual<T> operator*(const Dual<T>& a, double b) {
  return internal::Chain<T>(a.value() * b, a, T(b));
}
template <class T>
Dual<T> operator*(double a, const Dual<T>& b) {
  return internal::Chain<T>(a * b.value(), b, T(a));
}
template <class T>
Dual<T> operator/(const Dual<T>& a, double b) {
  return internal::Chain<T>(a.value() / b, a, T(1.0 / b));
}
template <class T>
Dual<T> operator/(double a, const Dual<T>& b) {
  return Dual<T>(a) / b;
}
/// @}

// ---- nonsmooth operations: refused at compile time (see the file comment) ----------------
namespace internal {
/// False for every T, but only known once T is: a static_assert on it fires when, and only
/// when, the function template holding it is instantiated (called).
template <class T>
inline constexpr bool kRefusedForAd = false;
}  // namespace internal

/// Compiler message for abs/fabs on an AD scalar (the refused operations name the effect that
/// models the behaviour).
#define MOREAU_REFUSED_ABS                                                                   \
  "moreau: abs/fabs of an AD scalar in a model function is not smooth: model the kink with " \
  "a SwitchingSurfaces effect on the argument (two modes, one per sign)"
/// Compiler message for min/max/fmin/fmax on AD scalars.
#define MOREAU_REFUSED_MIN_MAX                                                                \
  "moreau: min/max/fmin/fmax of AD scalars in a model function is not smooth: model it with " \
  "a SwitchingSurfaces effect on the difference (one mode per branch), or a bound with a "    \
  "MovingSet or PathConstraints effect"
/// Compiler message for floor/ceil/round/trunc/fmod on an AD scalar.
#define MOREAU_REFUSED_ROUNDING                                                               \
  "moreau: floor/ceil/round/trunc/fmod of an AD scalar in a model function jumps: model the " \
  "jumps with a SwitchingSurfaces effect, or a jump in time with a piecewise-constant input " \
  "(InputSpec breakpoints)"
/// Compiler message for a comparison of AD scalars.
#define MOREAU_REFUSED_COMPARISON                                                             \
  "moreau: comparison of AD scalars in a model function: a branch on the state or time is a " \
  "switch, which must be an effect: SwitchingSurfaces (modes), HysteresisRelay (a switch "    \
  "with memory), MovingSet or PathConstraints (a bound); a branch that never changes "        \
  "during a run may compare moreau::ValueOf(x)"

/// @name Refused nonsmooth operations on dual numbers
/// Each fails to compile with a message naming the effect that models it (file comment).
/// @{

/// abs, fabs, min, max, fmin, fmax, floor, ceil, round, trunc, fmod and the comparisons of dual
/// numbers: each refuses to compile (static_assert with one of the MOREAU_REFUSED_ messages).
template <class T>
Dual<T> abs(const Dual<T>& a) {
  static_assert(internal::kRefusedForAd<T>, MOREAU_REFUSED_ABS);
  return a;
}
template <class T>
Dual<T> fabs(const Dual<T>& a) {
  static_assert(internal::kRefusedForAd<T>, MOREAU_REFUSED_ABS);
  return a;
}
#define MOREAU_DUAL_REFUSED_BINARY(name, message)       \
  template <class T>                                    \
  Dual<T> name(const Dual<T>& a, const Dual<T>&) {      \
    static_assert(internal::kRefusedForAd<T>, message); \
    return a;                                           \
  }                                                     \
  template <class T>                                    \
  Dual<T> name(const Dual<T>& a, double) {              \
    static_assert(internal::kRefusedForAd<T>, message); \
    return a;                                           \
  }                                                     \
  template <class T>                                    \
  Dual<T> name(double, const Dual<T>& b) {              \
    static_assert(internal::kRefusedForAd<T>, message); \
    return b;                                           \
  }
MOREAU_DUAL_REFUSED_BINARY(min, MOREAU_REFUSED_MIN_MAX)
MOREAU_DUAL_REFUSED_BINARY(max, MOREAU_REFUSED_MIN_MAX)
MOREAU_DUAL_REFUSED_BINARY(fmin, MOREAU_REFUSED_MIN_MAX)
MOREAU_DUAL_REFUSED_BINARY(fmax, MOREAU_REFUSED_MIN_MAX)
MOREAU_DUAL_REFUSED_BINARY(fmod, MOREAU_REFUSED_ROUNDING)
#undef MOREAU_DUAL_REFUSED_BINARY
#define MOREAU_DUAL_REFUSED_ROUNDING(name)                              \
  template <class T>                                                    \
  Dual<T> name(const Dual<T>& a) {                                      \
    static_assert(internal::kRefusedForAd<T>, MOREAU_REFUSED_ROUNDING); \
    return a;                                                           \
  }
MOREAU_DUAL_REFUSED_ROUNDING(floor)
MOREAU_DUAL_REFUSED_ROUNDING(ceil)
MOREAU_DUAL_REFUSED_ROUNDING(round)
MOREAU_DUAL_REFUSED_ROUNDING(trunc)
#undef MOREAU_DUAL_REFUSED_ROUNDING
#define MOREAU_DUAL_REFUSED_COMPARISON(op)                                \
  template <class T>                                                      \
  bool operator op(const Dual<T>&, const Dual<T>&) {                      \
    static_assert(internal::kRefusedForAd<T>, MOREAU_REFUSED_COMPARISON); \
    return false;                                                         \
  }                                                                       \
  template <class T>                                                      \
  bool operator op(const Dual<T>&, double) {                              \
    static_assert(internal::kRefusedForAd<T>, MOREAU_REFUSED_COMPARISON); \
    return false;                                                         \
  }                                                                       \
  template <class T>                                                      \
  bool operator op(double, const Dual<T>&) {                              \
    static_assert(internal::kRefusedForAd<T>, MOREAU_REFUSED_COMPARISON); \
    return false;                                                         \
  }
MOREAU_DUAL_REFUSED_COMPARISON(<)
MOREAU_DUAL_REFUSED_COMPARISON(<=)
MOREAU_DUAL_REFUSED_COMPARISON(>)
MOREAU_DUAL_REFUSED_COMPARISON(>=)
MOREAU_DUAL_REFUSED_COMPARISON(==)
MOREAU_DUAL_REFUSED_COMPARISON(!=)
#undef MOREAU_DUAL_REFUSED_COMPARISON
/// @}

// ---- elementary functions ----------------------------------------------------------------
/// @name Smooth elementary functions of dual numbers
/// Each computes its value with the value type's own function (so that nested duals give
/// second derivatives) and its derivatives by the chain rule, exact to round-off. They are
/// found for `sin(x)` by argument-dependent lookup and for `std::sin(x)` through the
/// using-declarations in namespace std at the end of this file.
/// @{

/// sin, cos, tan, exp, exp2, expm1, log, log2, log10, log1p, sqrt, cbrt, the inverse and
/// hyperbolic functions and erf/erfc of a dual number.
template <class T>
Dual<T> sin(const Dual<T>& a) {
  using std::cos;
  using std::sin;
  return internal::Chain<T>(sin(a.value()), a, cos(a.value()));
}
template <class T>
Dual<T> cos(const Dual<T>& a) {
  using std::cos;
  using std::sin;
  return internal::Chain<T>(cos(a.value()), a, -sin(a.value()));
}
template <class T>
Dual<T> tan(const Dual<T>& a) {
  using std::tan;
  const T t = tan(a.value());
  return internal::Chain<T>(t, a, T(1.0) + t * t);
}
template <class T>
Dual<T> exp(const Dual<T>& a) {
  using std::exp;
  const T e = exp(a.value());
  return internal::Chain<T>(e, a, e);
}
template <class T>
Dual<T> exp2(const Dual<T>& a) {
  using std::exp2;
  const T e = exp2(a.value());
  return internal::Chain<T>(e, a, e * std::log(2.0));
}
template <class T>
Dual<T> expm1(const Dual<T>& a) {
  using std::exp;
  using std::expm1;
  return internal::Chain<T>(expm1(a.value()), a, exp(a.value()));
}
template <class T>
Dual<T> log(const Dual<T>& a) {
  using std::log;
  return internal::Chain<T>(log(a.value()), a, T(1.0) / a.value());
}
template <class T>
Dual<T> log2(const Dual<T>& a) {
  using std::log2;
  return internal::Chain<T>(log2(a.value()), a, T(1.0) / (a.value() * std::log(2.0)));
}
template <class T>
Dual<T> log10(const Dual<T>& a) {
  using std::log10;
  return internal::Chain<T>(log10(a.value()), a, T(1.0) / (a.value() * std::log(10.0)));
}
template <class T>
Dual<T> log1p(const Dual<T>& a) {
  using std::log1p;
  return internal::Chain<T>(log1p(a.value()), a, T(1.0) / (T(1.0) + a.value()));
}
template <class T>
Dual<T> sqrt(const Dual<T>& a) {
  using std::sqrt;
  const T r = sqrt(a.value());
  return internal::Chain<T>(r, a, T(0.5) / r);
}
template <class T>
Dual<T> cbrt(const Dual<T>& a) {
  using std::cbrt;
  const T r = cbrt(a.value());
  return internal::Chain<T>(r, a, T(1.0) / (3.0 * r * r));
}
/// a^b for a constant exponent b (an integer exponent converts: `pow(x, 2)`).
template <class T>
Dual<T> pow(const Dual<T>& a, double b) {
  using std::pow;
  return internal::Chain<T>(pow(a.value(), b), a, b * pow(a.value(), b - 1.0));
}
/// a^b with both a and b dual numbers (a > 0 where b varies).
template <class T>
Dual<T> pow(const Dual<T>& a, const Dual<T>& b) {
  using std::log;
  using std::pow;
  const T value = pow(a.value(), b.value());
  return internal::Combine<T>(value, a, b.value() * pow(a.value(), b.value() - 1.0), b,
                              value * log(a.value()));
}
/// a^b for a constant base a > 0.
template <class T>
Dual<T> pow(double a, const Dual<T>& b) {
  using std::pow;
  const T value = pow(a, b.value());
  return internal::Chain<T>(value, b, value * std::log(a));
}
/// atan, asin, acos, the hyperbolic functions and their inverses, erf and erfc.
template <class T>
Dual<T> atan(const Dual<T>& a) {
  using std::atan;
  return internal::Chain<T>(atan(a.value()), a, T(1.0) / (T(1.0) + a.value() * a.value()));
}
template <class T>
Dual<T> asin(const Dual<T>& a) {
  using std::asin;
  using std::sqrt;
  return internal::Chain<T>(asin(a.value()), a, T(1.0) / sqrt(T(1.0) - a.value() * a.value()));
}
template <class T>
Dual<T> acos(const Dual<T>& a) {
  using std::acos;
  using std::sqrt;
  return internal::Chain<T>(acos(a.value()), a, T(-1.0) / sqrt(T(1.0) - a.value() * a.value()));
}
template <class T>
Dual<T> sinh(const Dual<T>& a) {
  using std::cosh;
  using std::sinh;
  return internal::Chain<T>(sinh(a.value()), a, cosh(a.value()));
}
template <class T>
Dual<T> cosh(const Dual<T>& a) {
  using std::cosh;
  using std::sinh;
  return internal::Chain<T>(cosh(a.value()), a, sinh(a.value()));
}
template <class T>
Dual<T> tanh(const Dual<T>& a) {
  using std::tanh;
  const T t = tanh(a.value());
  return internal::Chain<T>(t, a, T(1.0) - t * t);
}
template <class T>
Dual<T> asinh(const Dual<T>& a) {
  using std::asinh;
  using std::sqrt;
  return internal::Chain<T>(asinh(a.value()), a, T(1.0) / sqrt(a.value() * a.value() + 1.0));
}
template <class T>
Dual<T> acosh(const Dual<T>& a) {
  using std::acosh;
  using std::sqrt;
  return internal::Chain<T>(acosh(a.value()), a, T(1.0) / sqrt(a.value() * a.value() - 1.0));
}
template <class T>
Dual<T> atanh(const Dual<T>& a) {
  using std::atanh;
  return internal::Chain<T>(atanh(a.value()), a, T(1.0) / (T(1.0) - a.value() * a.value()));
}
template <class T>
Dual<T> erf(const Dual<T>& a) {
  using std::erf;
  using std::exp;
  // d/da erf(a) = 2/sqrt(pi) exp(-a^2)
  constexpr double kTwoOverSqrtPi = 1.1283791670955125739;
  return internal::Chain<T>(erf(a.value()), a, kTwoOverSqrtPi * exp(-(a.value() * a.value())));
}
template <class T>
Dual<T> erfc(const Dual<T>& a) {
  using std::erfc;
  using std::exp;
  constexpr double kTwoOverSqrtPi = 1.1283791670955125739;
  return internal::Chain<T>(erfc(a.value()), a, -kTwoOverSqrtPi * exp(-(a.value() * a.value())));
}
/// atan2(y, x): the angle of (x, y), smooth away from the origin.
template <class T>
Dual<T> atan2(const Dual<T>& y, const Dual<T>& x) {
  using std::atan2;
  const T denominator = x.value() * x.value() + y.value() * y.value();
  return internal::Combine<T>(atan2(y.value(), x.value()), y, x.value() / denominator, x,
                              -y.value() / denominator);
}
template <class T>
Dual<T> atan2(const Dual<T>& y, double x) {
  return atan2(y, Dual<T>(x));
}
template <class T>
Dual<T> atan2(double y, const Dual<T>& x) {
  return atan2(Dual<T>(y), x);
}
/// hypot(a, b) = sqrt(a^2 + b^2) without overflow, smooth away from the origin.
template <class T>
Dual<T> hypot(const Dual<T>& a, const Dual<T>& b) {
  using std::hypot;
  const T h = hypot(a.value(), b.value());
  return internal::Combine<T>(h, a, a.value() / h, b, b.value() / h);
}
template <class T>
Dual<T> hypot(const Dual<T>& a, double b) {
  return hypot(a, Dual<T>(b));
}
template <class T>
Dual<T> hypot(double a, const Dual<T>& b) {
  return hypot(Dual<T>(a), b);
}
/// @}

/// @name Value queries
/// Tests of the value (not comparisons: they do not decide a branch of the model).
/// @{

/// True if the innermost value is finite.
template <class T>
bool isfinite(const Dual<T>& a) {
  return std::isfinite(ValueOf(a));
}
/// True if the innermost value is NaN.
template <class T>
bool isnan(const Dual<T>& a) {
  return std::isnan(ValueOf(a));
}
/// @}

}  // namespace moreau

// Eigen integration so that Eigen::Matrix<moreau::Dual<T>, ...> works in model code.
namespace Eigen {
template <class T>
struct NumTraits<moreau::Dual<T>> : GenericNumTraits<moreau::Dual<T>> {
  using Real = moreau::Dual<T>;
  using NonInteger = moreau::Dual<T>;
  using Nested = moreau::Dual<T>;
  using Literal = double;
  enum {
    IsComplex = 0,
    IsInteger = 0,
    IsSigned = 1,
    RequireInitialization = 1,
    ReadCost = 1,
    AddCost = 4,
    MulCost = 4
  };
  static Real epsilon() { return Real(NumTraits<double>::epsilon()); }
  static Real dummy_precision() { return Real(NumTraits<double>::dummy_precision()); }
  static Real highest() { return Real(NumTraits<double>::highest()); }
  static Real lowest() { return Real(NumTraits<double>::lowest()); }
  static int digits10() { return NumTraits<double>::digits10(); }
};
template <class T, class BinaryOp>
struct ScalarBinaryOpTraits<moreau::Dual<T>, double, BinaryOp> {
  using ReturnType = moreau::Dual<T>;
};
template <class T, class BinaryOp>
struct ScalarBinaryOpTraits<double, moreau::Dual<T>, BinaryOp> {
  using ReturnType = moreau::Dual<T>;
};
}  // namespace Eigen

// Model code may write `std::sin(x)` as it would for doubles: the overloads above are declared
// in namespace std as well. The standard reserves namespace std ([namespace.std]); these
// using-declarations add no new entity there, only name moreau's overloads for moreau's own
// types (no standard call can resolve to them), and GCC and Clang accept them. The refused
// operations are declared too, so that `std::abs(x)` and `std::min(x, y)` fail with the
// message naming the effect instead of a list of candidates. sparsity_tracer.hpp repeats
// these declarations for the tracer's overloads.
/// Declares moreau's math overloads in namespace std (used at the end of dual.hpp and of
/// sparsity_tracer.hpp; not for user code).
#define MOREAU_DECLARE_MATH_IN_STD             \
  namespace std { /* NOLINT(cert-dcl58-cpp) */ \
  using moreau::abs;                           \
  using moreau::acos;                          \
  using moreau::acosh;                         \
  using moreau::asin;                          \
  using moreau::asinh;                         \
  using moreau::atan;                          \
  using moreau::atan2;                         \
  using moreau::atanh;                         \
  using moreau::cbrt;                          \
  using moreau::ceil;                          \
  using moreau::cos;                           \
  using moreau::cosh;                          \
  using moreau::erf;                           \
  using moreau::erfc;                          \
  using moreau::exp;                           \
  using moreau::exp2;                          \
  using moreau::expm1;                         \
  using moreau::fabs;                          \
  using moreau::floor;                         \
  using moreau::fmax;                          \
  using moreau::fmin;                          \
  using moreau::fmod;                          \
  using moreau::hypot;                         \
  using moreau::isfinite;                      \
  using moreau::isnan;                         \
  using moreau::log;                           \
  using moreau::log10;                         \
  using moreau::log1p;                         \
  using moreau::log2;                          \
  using moreau::max;                           \
  using moreau::min;                           \
  using moreau::pow;                           \
  using moreau::round;                         \
  using moreau::sin;                           \
  using moreau::sinh;                          \
  using moreau::sqrt;                          \
  using moreau::tan;                           \
  using moreau::tanh;                          \
  using moreau::trunc;                         \
  }
MOREAU_DECLARE_MATH_IN_STD
