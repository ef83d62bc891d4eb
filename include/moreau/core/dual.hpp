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
/// Model functions are written as templates in a scalar type T and use unqualified calls
/// (sin(x), sqrt(x), ...) after `using std::sin;` etc., so that argument-dependent lookup
/// finds the overloads below for dual numbers.

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <type_traits>

#include "moreau/core/error.hpp"

namespace moreau {

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

  const T& value() const { return value_; }
  T& value() { return value_; }
  int size() const { return size_; }
  const T& d(int i) const { return d_[i]; }
  T& d(int i) { return d_[i]; }

  Dual& operator+=(const Dual& other) { return *this = *this + other; }
  Dual& operator-=(const Dual& other) { return *this = *this - other; }
  Dual& operator*=(const Dual& other) { return *this = *this * other; }
  Dual& operator/=(const Dual& other) { return *this = *this / other; }

  /// A number with `size` derivative directions left unset: the caller writes all of them
  /// (the chain rules below; zeroing them first doubled their stores).
  struct Unset {};
  Dual(const T& value, int size, Unset) : value_(value), size_(size) {}

 private:
  // The first size_ directions of other. A loop over the capacity with a test, not up to
  // size_: GCC turns the latter into a memcpy or `rep movs` of a few doubles, whose start-up
  // cost dominated Jacobian evaluations of small functions (issue 15, FESD element cost).
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

/// The innermost double value of a (possibly nested) dual number or a double.
inline double ValueOf(double x) { return x; }
template <class T>
double ValueOf(const Dual<T>& x) {
  return ValueOf(x.value());
}

namespace internal {
// Result with value `value` and derivatives da * a.d + db * b.d (chain rule for binary ops).
template <class T>
Dual<T> Combine(const T& value, const Dual<T>& a, const T& da, const Dual<T>& b, const T& db) {
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

// ---- comparisons (on the innermost value; derivatives do not take part) ------------------
#define MOREAU_DUAL_COMPARISON(op)                       \
  template <class T>                                     \
  bool operator op(const Dual<T>& a, const Dual<T>& b) { \
    return ValueOf(a) op ValueOf(b);                     \
  }                                                      \
  template <class T>                                     \
  bool operator op(const Dual<T>& a, double b) {         \
    return ValueOf(a) op b;                              \
  }                                                      \
  template <class T>                                     \
  bool operator op(double a, const Dual<T>& b) {         \
    return a op ValueOf(b);                              \
  }
MOREAU_DUAL_COMPARISON(<)
MOREAU_DUAL_COMPARISON(<=)
MOREAU_DUAL_COMPARISON(>)
MOREAU_DUAL_COMPARISON(>=)
MOREAU_DUAL_COMPARISON(==)
MOREAU_DUAL_COMPARISON(!=)
#undef MOREAU_DUAL_COMPARISON

// ---- elementary functions ----------------------------------------------------------------
// Each uses the value type's own overload through unqualified calls, so that nesting works.
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
Dual<T> log(const Dual<T>& a) {
  using std::log;
  return internal::Chain<T>(log(a.value()), a, T(1.0) / a.value());
}
template <class T>
Dual<T> sqrt(const Dual<T>& a) {
  using std::sqrt;
  const T r = sqrt(a.value());
  return internal::Chain<T>(r, a, T(0.5) / r);
}
template <class T>
Dual<T> pow(const Dual<T>& a, double b) {
  using std::pow;
  return internal::Chain<T>(pow(a.value(), b), a, b * pow(a.value(), b - 1.0));
}
template <class T>
Dual<T> pow(const Dual<T>& a, const Dual<T>& b) {
  using std::log;
  using std::pow;
  const T value = pow(a.value(), b.value());
  return internal::Combine<T>(value, a, b.value() * pow(a.value(), b.value() - 1.0), b,
                              value * log(a.value()));
}
template <class T>
Dual<T> pow(double a, const Dual<T>& b) {
  using std::log;
  using std::pow;
  const T value = pow(a, b.value());
  return internal::Chain<T>(value, b, value * std::log(a));
}
/// |a|; the derivative at a == 0 is taken as 0 (an element of the subdifferential).
template <class T>
Dual<T> abs(const Dual<T>& a) {
  const double v = ValueOf(a);
  const T sign = v > 0.0 ? T(1.0) : (v < 0.0 ? T(-1.0) : T(0.0));
  return internal::Chain<T>(sign * a.value(), a, sign);
}
template <class T>
Dual<T> fabs(const Dual<T>& a) {
  return abs(a);
}
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
template <class T>
Dual<T> hypot(const Dual<T>& a, const Dual<T>& b) {
  using std::hypot;
  const T h = hypot(a.value(), b.value());
  return internal::Combine<T>(h, a, a.value() / h, b, b.value() / h);
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
bool isfinite(const Dual<T>& a) {
  return std::isfinite(ValueOf(a));
}
template <class T>
bool isnan(const Dual<T>& a) {
  return std::isnan(ValueOf(a));
}

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
