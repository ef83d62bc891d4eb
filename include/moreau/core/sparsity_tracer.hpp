#pragma once
/// @file
/// SparsityTracer: the scalar type with which moreau detects the sparsity of a model function
/// (docs/sparse-derivatives.md).
///
/// A model function written once as a generic lambda (see smooth_function.hpp) is evaluated
/// a fourth time with T = SparsityTracer. Each tracer carries its double value, so that the
/// evaluation follows the same branches as the double evaluation at the same point, and the
/// index of the operation that produced it in a tape (internal::SparsityTape). The tape records
/// for every operation on traced values which operands it combines and how:
///  - linearly (a + b, a - b, -a, c a, a / c, |a|): no second derivatives of its own;
///  - as a product a b of two traced values: d^2/(da db) != 0 only (pairs D(a) x D(b));
///  - as a quotient a / b with b traced: pairs D(a) x D(b) and D(b) x D(b);
///  - nonlinearly in every operand (sqrt, exp, sin, pow, atan2, hypot, ...): all pairs of
///    (D(a) u D(b)) x (D(a) u D(b)),
/// where D(v) is the set of inputs on which v depends. The Jacobian pattern of an output is the
/// set of inputs reachable from it in the tape; its second-derivative pattern is the union of
/// the pairs contributed by the nonlinear operations reachable from it (Walther 2008). Values
/// that involve no input (constants, parameters when they are not traced) record nothing, and
/// operations of a traced value with a constant that keep it affine (a + c, c a, a / c, -a)
/// reuse the operand's tape entry: an affine function has an empty second-derivative pattern.
///
/// Branch safety: comparisons and the other nonsmooth operations do not compile on tracers,
/// as on dual numbers (dual.hpp). isfinite/isnan and ValueOf applied to a traced value mark
/// the tape as value-dependent, because control flow that depends on the point may change the
/// pattern. SmoothFunction then re-detects the pattern at every sparse call (see
/// docs/sparse-derivatives.md for the cost and for how the stored pattern is kept a superset).
///
/// The overloads below are found by argument-dependent lookup, like those of Dual, and are
/// declared in namespace std too, so model code may write `sin(x)` or `std::sin(x)`.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "moreau/core/dual.hpp"
#include "moreau/core/error.hpp"

namespace moreau {

namespace internal {

// The operations of one traced evaluation: node i < num_inputs is input i; every later node is
// an operation on one or two earlier nodes.
struct SparsityTape {
  enum class Kind : std::uint8_t {
    kInput,      // an independent variable
    kLinear,     // a + b, a - b (both traced): first derivatives only
    kProduct,    // a b, both traced
    kQuotient,   // a / b, b traced (a traced or not: a == -1 then)
    kNonlinear,  // f(a) or f(a, b), nonlinear in each traced operand
  };
  struct Node {
    Kind kind;
    int a;  // operand node, or -1 (constant)
    int b;  // second operand node, or -1
  };
  std::vector<Node> nodes;
  // A comparison, isfinite/isnan or ValueOf was applied to a traced value.
  bool value_dependent = false;
  // |a| was applied to a traced value: a first derivative changes sign with the point although
  // no second derivative appears.
  bool piecewise = false;

  int Record(Kind kind, int a, int b) {
    nodes.push_back({kind, a, b});
    return static_cast<int>(nodes.size()) - 1;
  }
};

}  // namespace internal

/// Scalar type of the sparsity-detecting evaluation (see file comment).
class SparsityTracer {
 public:
  SparsityTracer() = default;
  /// A constant: it depends on no input. Implicit so that literals mix with tracers.
  SparsityTracer(double value) : value_(value) {}  // NOLINT(google-explicit-constructor)
  /// The value `value` recorded as tape node `node` (an input, or the result of an operation).
  SparsityTracer(double value, internal::SparsityTape* tape, int node)
      : value_(value), node_(node), tape_(tape) {}

  /// The double value (the same as the double evaluation's at the same point).
  double value() const { return value_; }
  /// Tape node of this value, -1 for a constant.
  int node() const { return node_; }
  /// The tape of the evaluation this value belongs to (nullptr for a constant).
  internal::SparsityTape* tape() const { return tape_; }
  /// True if the value depends (structurally) on an input.
  bool traced() const { return tape_ != nullptr; }

  /// Compound assignments, by the binary operators below.
  SparsityTracer& operator+=(const SparsityTracer& other);
  /// *this = *this - other.
  SparsityTracer& operator-=(const SparsityTracer& other);
  /// *this = *this * other.
  SparsityTracer& operator*=(const SparsityTracer& other);
  /// *this = *this / other.
  SparsityTracer& operator/=(const SparsityTracer& other);

 private:
  double value_ = 0.0;
  int node_ = -1;
  internal::SparsityTape* tape_ = nullptr;
};

namespace internal {

using TraceKind = SparsityTape::Kind;

// Same dependencies, no second derivatives of its own: the result shares the operand's node.
inline SparsityTracer TraceAffine(double value, const SparsityTracer& a) {
  return a.traced() ? SparsityTracer(value, a.tape(), a.node()) : SparsityTracer(value);
}

// A function nonlinear in its only traced operand.
inline SparsityTracer TraceNonlinear(double value, const SparsityTracer& a) {
  if (!a.traced()) return SparsityTracer(value);
  return SparsityTracer(value, a.tape(), a.tape()->Record(TraceKind::kNonlinear, a.node(), -1));
}

inline SparsityTape* CommonTape(const SparsityTracer& a, const SparsityTracer& b) {
  MOREAU_ASSERT(a.tape() == b.tape(), "sparsity tracers from different evaluations combined");
  return a.tape();
}

// A binary operation of kind `kind` on two values of which at least one is traced; the cases
// with a constant operand are handled by the callers.
inline SparsityTracer TraceBinary(TraceKind kind, double value, const SparsityTracer& a,
                                  const SparsityTracer& b) {
  SparsityTape* tape = CommonTape(a, b);
  return SparsityTracer(value, tape, tape->Record(kind, a.node(), b.node()));
}

// A binary function nonlinear in each operand (pow, atan2, hypot).
inline SparsityTracer TraceNonlinear(double value, const SparsityTracer& a,
                                     const SparsityTracer& b) {
  if (!a.traced()) return TraceNonlinear(value, b);
  if (!b.traced()) return TraceNonlinear(value, a);
  return TraceBinary(TraceKind::kNonlinear, value, a, b);
}

// A query of the value that control flow may act on (see file comment).
inline void NoteValueUse(const SparsityTracer& a) {
  if (a.traced()) a.tape()->value_dependent = true;
}

}  // namespace internal

// ---- arithmetic -------------------------------------------------------------------------
/// @name Arithmetic on tracers
/// The value is the double arithmetic; the tape records how the operands combine (file
/// comment). Operations with a constant operand that keep the result affine reuse the tape
/// entry of the traced operand.
/// @{

/// Unary plus, minus and the binary operators, traced.
inline SparsityTracer operator+(const SparsityTracer& a) { return a; }
inline SparsityTracer operator-(const SparsityTracer& a) {
  return internal::TraceAffine(-a.value(), a);
}
inline SparsityTracer operator+(const SparsityTracer& a, const SparsityTracer& b) {
  const double value = a.value() + b.value();
  if (!b.traced()) return internal::TraceAffine(value, a);
  if (!a.traced() || a.node() == b.node()) return internal::TraceAffine(value, b);
  return internal::TraceBinary(internal::TraceKind::kLinear, value, a, b);
}
inline SparsityTracer operator-(const SparsityTracer& a, const SparsityTracer& b) {
  const double value = a.value() - b.value();
  if (!b.traced()) return internal::TraceAffine(value, a);
  if (!a.traced() || a.node() == b.node()) return internal::TraceAffine(value, b);
  return internal::TraceBinary(internal::TraceKind::kLinear, value, a, b);
}
inline SparsityTracer operator*(const SparsityTracer& a, const SparsityTracer& b) {
  const double value = a.value() * b.value();
  if (!b.traced()) return internal::TraceAffine(value, a);
  if (!a.traced()) return internal::TraceAffine(value, b);
  return internal::TraceBinary(internal::TraceKind::kProduct, value, a, b);
}
inline SparsityTracer operator/(const SparsityTracer& a, const SparsityTracer& b) {
  const double value = a.value() / b.value();
  if (!b.traced()) return internal::TraceAffine(value, a);
  if (!a.traced()) return internal::TraceNonlinear(value, b);  // c / b
  return internal::TraceBinary(internal::TraceKind::kQuotient, value, a, b);
}
// Mixed forms with double (exact matches, so that `2.0 * x` needs no conversion).
inline SparsityTracer operator+(const SparsityTracer& a, double b) {
  return internal::TraceAffine(a.value() + b, a);
}
inline SparsityTracer operator+(double a, const SparsityTracer& b) {
  return internal::TraceAffine(a + b.value(), b);
}
inline SparsityTracer operator-(const SparsityTracer& a, double b) {
  return internal::TraceAffine(a.value() - b, a);
}
inline SparsityTracer operator-(double a, const SparsityTracer& b) {
  return internal::TraceAffine(a - b.value(), b);
}
inline SparsityTracer operator*(const SparsityTracer& a, double b) {
  return internal::TraceAffine(a.value() * b, a);
}
inline SparsityTracer operator*(double a, const SparsityTracer& b) {
  return internal::TraceAffine(a * b.value(), b);
}
inline SparsityTracer operator/(const SparsityTracer& a, double b) {
  return internal::TraceAffine(a.value() / b, a);
}
inline SparsityTracer operator/(double a, const SparsityTracer& b) {
  return internal::TraceNonlinear(a / b.value(), b);
}
/// @}

inline SparsityTracer& SparsityTracer::operator+=(const SparsityTracer& other) {
  return *this = *this + other;
}
inline SparsityTracer& SparsityTracer::operator-=(const SparsityTracer& other) {
  return *this = *this - other;
}
inline SparsityTracer& SparsityTracer::operator*=(const SparsityTracer& other) {
  return *this = *this * other;
}
inline SparsityTracer& SparsityTracer::operator/=(const SparsityTracer& other) {
  return *this = *this / other;
}

// ---- refused nonsmooth operations (messages and reasons: dual.hpp) ------------------------
namespace internal {
// Enables a refused overload for a deduced SparsityTracer only: no double converts to a
// tracer to reach one (moreau's own code calls min, floor, ... on doubles).
template <class Tracer>
using IfTracer = std::enable_if_t<std::is_same_v<Tracer, SparsityTracer>, int>;
}  // namespace internal

/// @name Refused nonsmooth operations on tracers
/// Each fails to compile with the message of its dual-number twin (dual.hpp).
/// @{

/// abs and fabs: a kink (a SwitchingSurfaces effect models it).
template <class Tracer, internal::IfTracer<Tracer> = 0>
Tracer abs(const Tracer& a) {
  static_assert(internal::kRefusedForAd<Tracer>, MOREAU_REFUSED_ABS);
  return a;
}
template <class Tracer, internal::IfTracer<Tracer> = 0>
Tracer fabs(const Tracer& a) {
  static_assert(internal::kRefusedForAd<Tracer>, MOREAU_REFUSED_ABS);
  return a;
}
#define MOREAU_TRACER_REFUSED_BINARY(name, message)                       \
  template <class Refused = void> /* more specialized than std::min<T> */ \
  SparsityTracer name(const SparsityTracer& a, const SparsityTracer&) {   \
    static_assert(internal::kRefusedForAd<Refused>, message);             \
    return a;                                                             \
  }                                                                       \
  template <class Tracer, internal::IfTracer<Tracer> = 0>                 \
  Tracer name(const Tracer& a, double) {                                  \
    static_assert(internal::kRefusedForAd<Tracer>, message);              \
    return a;                                                             \
  }                                                                       \
  template <class Tracer, internal::IfTracer<Tracer> = 0>                 \
  Tracer name(double, const Tracer& b) {                                  \
    static_assert(internal::kRefusedForAd<Tracer>, message);              \
    return b;                                                             \
  }
MOREAU_TRACER_REFUSED_BINARY(min, MOREAU_REFUSED_MIN_MAX)
MOREAU_TRACER_REFUSED_BINARY(max, MOREAU_REFUSED_MIN_MAX)
MOREAU_TRACER_REFUSED_BINARY(fmin, MOREAU_REFUSED_MIN_MAX)
MOREAU_TRACER_REFUSED_BINARY(fmax, MOREAU_REFUSED_MIN_MAX)
MOREAU_TRACER_REFUSED_BINARY(fmod, MOREAU_REFUSED_ROUNDING)
#undef MOREAU_TRACER_REFUSED_BINARY
#define MOREAU_TRACER_REFUSED_ROUNDING(name)                                 \
  template <class Tracer, internal::IfTracer<Tracer> = 0>                    \
  Tracer name(const Tracer& a) {                                             \
    static_assert(internal::kRefusedForAd<Tracer>, MOREAU_REFUSED_ROUNDING); \
    return a;                                                                \
  }
MOREAU_TRACER_REFUSED_ROUNDING(floor)
MOREAU_TRACER_REFUSED_ROUNDING(ceil)
MOREAU_TRACER_REFUSED_ROUNDING(round)
MOREAU_TRACER_REFUSED_ROUNDING(trunc)
#undef MOREAU_TRACER_REFUSED_ROUNDING
#define MOREAU_TRACER_REFUSED_COMPARISON(op)                                   \
  template <class Tracer, internal::IfTracer<Tracer> = 0>                      \
  bool operator op(const Tracer&, const Tracer&) {                             \
    static_assert(internal::kRefusedForAd<Tracer>, MOREAU_REFUSED_COMPARISON); \
    return false;                                                              \
  }                                                                            \
  template <class Tracer, internal::IfTracer<Tracer> = 0>                      \
  bool operator op(const Tracer&, double) {                                    \
    static_assert(internal::kRefusedForAd<Tracer>, MOREAU_REFUSED_COMPARISON); \
    return false;                                                              \
  }                                                                            \
  template <class Tracer, internal::IfTracer<Tracer> = 0>                      \
  bool operator op(double, const Tracer&) {                                    \
    static_assert(internal::kRefusedForAd<Tracer>, MOREAU_REFUSED_COMPARISON); \
    return false;                                                              \
  }
MOREAU_TRACER_REFUSED_COMPARISON(<)
MOREAU_TRACER_REFUSED_COMPARISON(<=)
MOREAU_TRACER_REFUSED_COMPARISON(>)
MOREAU_TRACER_REFUSED_COMPARISON(>=)
MOREAU_TRACER_REFUSED_COMPARISON(==)
MOREAU_TRACER_REFUSED_COMPARISON(!=)
#undef MOREAU_TRACER_REFUSED_COMPARISON
/// @}

/// The value, for code that inspects it (marks the tape value-dependent, like a comparison).
inline double ValueOf(const SparsityTracer& a) {
  internal::NoteValueUse(a);
  return a.value();
}
/// True if the value is finite (marks the tape value-dependent).
inline bool isfinite(const SparsityTracer& a) {  // NOLINT(readability-identifier-naming)
  internal::NoteValueUse(a);
  return std::isfinite(a.value());
}
/// True if the value is NaN (marks the tape value-dependent).
inline bool isnan(const SparsityTracer& a) {  // NOLINT(readability-identifier-naming)
  internal::NoteValueUse(a);
  return std::isnan(a.value());
}

// ---- elementary functions (values as the double evaluation computes them) -----------------
#define MOREAU_TRACER_NONLINEAR_UNARY(name)                   \
  inline SparsityTracer name(const SparsityTracer& a) {       \
    return internal::TraceNonlinear(std::name(a.value()), a); \
  }
/// @name Smooth elementary functions of tracers
/// Values as the double evaluation computes them; each records a nonlinear operation (an
/// affine one for pow(a, 1)).
/// @{

/// sin, cos, tan, exp, log, sqrt, the inverse and hyperbolic functions, exp2, expm1, log2,
/// log10, log1p, cbrt and erf/erfc of a tracer.
MOREAU_TRACER_NONLINEAR_UNARY(sin)
MOREAU_TRACER_NONLINEAR_UNARY(cos)
MOREAU_TRACER_NONLINEAR_UNARY(tan)
MOREAU_TRACER_NONLINEAR_UNARY(exp)
MOREAU_TRACER_NONLINEAR_UNARY(log)
MOREAU_TRACER_NONLINEAR_UNARY(sqrt)
MOREAU_TRACER_NONLINEAR_UNARY(atan)
MOREAU_TRACER_NONLINEAR_UNARY(asin)
MOREAU_TRACER_NONLINEAR_UNARY(acos)
MOREAU_TRACER_NONLINEAR_UNARY(sinh)
MOREAU_TRACER_NONLINEAR_UNARY(cosh)
MOREAU_TRACER_NONLINEAR_UNARY(tanh)
MOREAU_TRACER_NONLINEAR_UNARY(exp2)
MOREAU_TRACER_NONLINEAR_UNARY(expm1)
MOREAU_TRACER_NONLINEAR_UNARY(log2)
MOREAU_TRACER_NONLINEAR_UNARY(log10)
MOREAU_TRACER_NONLINEAR_UNARY(log1p)
MOREAU_TRACER_NONLINEAR_UNARY(cbrt)
MOREAU_TRACER_NONLINEAR_UNARY(asinh)
MOREAU_TRACER_NONLINEAR_UNARY(acosh)
MOREAU_TRACER_NONLINEAR_UNARY(atanh)
MOREAU_TRACER_NONLINEAR_UNARY(erf)
MOREAU_TRACER_NONLINEAR_UNARY(erfc)
#undef MOREAU_TRACER_NONLINEAR_UNARY

/// a^b for a constant exponent b: affine for b == 1, nonlinear otherwise.
inline SparsityTracer pow(const SparsityTracer& a, double b) {
  const double value = std::pow(a.value(), b);
  return b == 1.0 ? internal::TraceAffine(value, a) : internal::TraceNonlinear(value, a);
}
inline SparsityTracer pow(const SparsityTracer& a, const SparsityTracer& b) {
  return internal::TraceNonlinear(std::pow(a.value(), b.value()), a, b);
}
inline SparsityTracer pow(double a, const SparsityTracer& b) {
  return internal::TraceNonlinear(std::pow(a, b.value()), b);
}
inline SparsityTracer atan2(const SparsityTracer& y, const SparsityTracer& x) {
  return internal::TraceNonlinear(std::atan2(y.value(), x.value()), y, x);
}
inline SparsityTracer atan2(const SparsityTracer& y, double x) {
  return internal::TraceNonlinear(std::atan2(y.value(), x), y);
}
inline SparsityTracer atan2(double y, const SparsityTracer& x) {
  return internal::TraceNonlinear(std::atan2(y, x.value()), x);
}
inline SparsityTracer hypot(const SparsityTracer& a, const SparsityTracer& b) {
  return internal::TraceNonlinear(std::hypot(a.value(), b.value()), a, b);
}
inline SparsityTracer hypot(const SparsityTracer& a, double b) {
  return internal::TraceNonlinear(std::hypot(a.value(), b), a);
}
inline SparsityTracer hypot(double a, const SparsityTracer& b) {
  return internal::TraceNonlinear(std::hypot(a, b.value()), b);
}
/// @}

}  // namespace moreau

// Eigen integration so that Eigen::Matrix<moreau::SparsityTracer, ...> works in model code.
namespace Eigen {
template <>
struct NumTraits<moreau::SparsityTracer> : GenericNumTraits<moreau::SparsityTracer> {
  using Real = moreau::SparsityTracer;
  using NonInteger = moreau::SparsityTracer;
  using Nested = moreau::SparsityTracer;
  using Literal = double;
  enum {
    IsComplex = 0,
    IsInteger = 0,
    IsSigned = 1,
    RequireInitialization = 1,
    ReadCost = 1,
    AddCost = 2,
    MulCost = 2
  };
  static Real epsilon() { return Real(NumTraits<double>::epsilon()); }
  static Real dummy_precision() { return Real(NumTraits<double>::dummy_precision()); }
  static Real highest() { return Real(NumTraits<double>::highest()); }
  static Real lowest() { return Real(NumTraits<double>::lowest()); }
  static int digits10() { return NumTraits<double>::digits10(); }
};
template <class BinaryOp>
struct ScalarBinaryOpTraits<moreau::SparsityTracer, double, BinaryOp> {
  using ReturnType = moreau::SparsityTracer;
};
template <class BinaryOp>
struct ScalarBinaryOpTraits<double, moreau::SparsityTracer, BinaryOp> {
  using ReturnType = moreau::SparsityTracer;
};
}  // namespace Eigen

// `std::sin(tracer)` as for dual numbers (see the end of dual.hpp): the same using-declarations,
// now naming the tracer's overloads too.
MOREAU_DECLARE_MATH_IN_STD
