#pragma once
// Zeros of event indicators inside a step (docs/fesd-formulation.md, section 11): a polynomial
// path through the states (a collocation polynomial, IDA's interpolant) and the search along it
// for a watched function that falls below zero and may rise again before the step's end, where
// sign checks at the step's ends and stages see nothing. Private to moreau::integrators.
//
// The search is a branch and bound on the path parameter theta in [0, 1]. On an interval
// [a, b] the functions are bounded by interval arithmetic (the box of the path over [a, b],
// then the model functions over that box, LoweredSystem::BoundEventIndicators): where the
// lower bound of every watched function stays above its threshold, the interval holds no
// crossing, proved. Otherwise the functions are evaluated at its midpoint (a value below
// minus the threshold is a crossing, found) and both halves are searched, left first, down to
// kMaxDepth halvings (2^-30 of the step). A pulse narrower than any sampling grid is inside the
// bound and is found this way. What the bound cannot decide within the depth and budget is
// reported as unresolved, except next to the path's ends, where the values are known: a
// dip there within 2^-30 of the step is not a crossing the step could resolve anyway.

#include <type_traits>
#include <utility>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/integrators/radau_tableau.hpp"

namespace moreau::internal {

// y(theta) = sum_{d=0}^{q} a_d theta^d, theta in [0, 1]; a_d the columns of coefficients().
class PolynomialPath {
 public:
  // The collocation polynomial of an element of `tableau` from y0 with stage increments Z
  // (n_y x s): y(theta) = y0 + sum_j w_j(theta) Z_j (RadauTableau::InterpolationWeights).
  void SetCollocation(const RadauTableau& tableau, const ConstVectorRef& y0,
                      const Matrix& increments);
  // Direct access (IDA: Taylor coefficients of its interpolant in the step's parameter).
  Matrix& coefficients() { return coefficients_; }
  // Sizes the coefficients (zero) and Box's scratch for n components of degree `degree`, so
  // that a path written through coefficients() at that shape allocates nothing.
  void SetShape(Eigen::Index n, int degree);
  const Matrix& coefficients() const { return coefficients_; }
  // y(theta).
  void Point(double theta, Vector* y) const;
  // dy/dtheta.
  void Derivative(double theta, Vector* dy) const;
  // A box that contains y(theta) for every theta in [a, b]: the centred form
  // y(m) +- sum_{d >= 1} |y^(d)(m) / d!| r^d, m the midpoint, r the half-width (every term
  // rounded outward).
  void Box(double a, double b, Vector* lower, Vector* upper) const;

 private:
  Matrix coefficients_;
  // Monomial coefficients of the interpolation weights (row j: w_j's coefficients of
  // theta^1..theta^s), per number of stages; made on first use.
  const Matrix& WeightCoefficients(const RadauTableau& tableau);
  Matrix weight_coefficients_;
  int weight_stages_ = 0;
  mutable Matrix taylor_;  // Box's Taylor coefficients at the midpoint (kept: no allocation)
};

enum class CrossingOutcome {
  kNone,        // no watched function below its threshold (proved where bounds exist)
  kFound,       // a watched function is below minus its threshold at `theta`
  kUnresolved,  // the bounds admit a crossing that neither samples nor the depth resolved
};

struct Crossing {
  CrossingOutcome outcome = CrossingOutcome::kNone;
  int function = -1;    // kFound: the function found below, kUnresolved: one that may be
  double theta = 1.0;   // kFound: the first zero before the negative sample (bisection)
  double sample = 1.0;  // kFound: where the negative value was seen; kUnresolved: the interval
  int bound_evaluations = 0;
};

// A non-owning reference to a callable (std::function_ref of C++26, reduced to what the search
// needs): the search is called per element or step, and a std::function holding a lambda that
// captures more than two pointers allocates on every construction. The callable must outlive
// the reference: callers name their lambdas and build CrossingFunctionRefs from them.
template <typename Signature>
class FunctionRef;
template <typename R, typename... Args>
class FunctionRef<R(Args...)> {
 public:
  template <typename F>
  requires(!std::is_same_v<std::remove_cvref_t<F>, FunctionRef>)
      FunctionRef(F& f)  // NOLINT(google-explicit-constructor): a parameter type, like a reference
      : object_(const_cast<void*>(static_cast<const void*>(&f))),
        call_([](void* object, Args... args) -> R {
          return (*static_cast<std::remove_reference_t<F>*>(object))(std::forward<Args>(args)...);
        }) {}
  R operator()(Args... args) const { return call_(object_, std::forward<Args>(args)...); }

 private:
  void* object_;
  R (*call_)(void*, Args...);
};

// The functions f_k(theta) along a path and their enclosures over intervals of theta, by
// non-owning reference (callers search every step or element: no std::function is made per
// search); the callables must outlive it.
struct CrossingFunctionRefs {
  // Values at theta into *values (all functions); false if not evaluable there.
  FunctionRef<bool(double theta, Vector* values)> values;
  // Enclosures over [a, b] (entries -inf, +inf where none).
  FunctionRef<void(double a, double b, Vector* lower, Vector* upper)> bounds;
};

// Tuning of the search, with the reasons for each value.
struct CrossingSearchLimits {
  // Halvings of [0, 1]: 2^-30 ~ 1e-9 of the step, below which a dip is a graze of negligible
  // duration (the bound's overestimate shrinks linearly with the interval, so a function whose
  // minimum is a margin m above its threshold is proved positive on intervals of about m / |f'|).
  int max_depth = 30;
  // Interval evaluations per search: a proof costs one, a located crossing about two per
  // halving; this leaves room for several suspicious places in one step.
  int max_bounds = 400;
  // Bisection steps of the first zero before a negative sample (2^-40 of the interval).
  int bisections = 40;
};

// SearchCrossing's work storage, kept by a caller that searches every step so that the search
// allocates nothing once the sizes are met.
struct CrossingWorkspace {
  struct Node {  // an interval [a, b] of theta at depth `depth` of the bisection tree
    double a, b;
    int depth;
  };
  Vector lower, upper, values, levels;
  // After a search: bounded[k] is true where watched function k has a finite lower bound over
  // the whole step, [0, 1] (the search's first evaluation); the others were checked by samples
  // only, and a caller with another test for them reads this instead of bounding again.
  std::vector<char> bounded;
  std::vector<Node> stack;
  // Sizes the storage for `functions` watched functions and the depth of `limits` (an
  // integrator's set-up: the first search of a run then allocates nothing either).
  void Reserve(int functions, const CrossingSearchLimits& limits = {});
};

// Searches [0, 1] for the first theta where some watched function k (watched[k]) is below
// -thresholds[k], given that every watched function is at least -thresholds[k] at theta = 0
// and at theta = 1 (the step's ends are checked by the caller). Functions whose bound is
// (-inf, +inf) everywhere are checked by the samples only.
// The search runs in the caller's workspace (kept across searches: no allocation once its
// sizes are met).
Crossing SearchCrossing(const std::vector<char>& watched, const Vector& thresholds,
                        const CrossingFunctionRefs& functions, const CrossingSearchLimits& limits,
                        CrossingWorkspace* workspace);

// The smallest value of the Hermite interpolant through (nodes[i], values[i], slopes[i]) (degree
// 2 n - 1 for n nodes, Newton's divided differences with doubled nodes) at `samples` equally
// spaced points (m + 1/2) / samples of [0, 1], and *theta where it is taken: the extremum of a
// function between nodes predicted from its values and exact derivatives there.
double HermiteMinimum(const std::vector<double>& nodes, const std::vector<double>& values,
                      const std::vector<double>& slopes, int samples, double* theta);

// A lower bound of the same interpolant over [0, 1] (nodes in [0, 1]): the least coefficient
// of its Bernstein form, of which the interpolant is a convex combination at every point of
// [0, 1], less a bound on the rounding of the conversions (Newton form to powers to Bernstein)
// and of HermiteMinimum's evaluations. O(n^2) operations against HermiteMinimum's
// O(samples n): where it is at least a level, no sample of HermiteMinimum is below that level,
// and the samples need not be taken.
double HermiteLowerBound(const std::vector<double>& nodes, const std::vector<double>& values,
                         const std::vector<double>& slopes);

}  // namespace moreau::internal
