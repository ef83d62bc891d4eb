#pragma once
// Path constraints between the ends of an alpha-method step (docs/alpha-method.md, "Constraints
// between step ends"). The method imposes phi(x, u, t) <= 0 at t_{n+1} only; a long smooth step
// can carry the states across a thin region where phi > 0 (an obstacle reaching a little into
// the path) and land beyond it. This searches the step's continuous extension for such a
// region with the crossing search of common/crossing_search.hpp: interval bounds of phi over
// the box of the extension on [a, b] prove that there is none, samples find one, and what
// neither decides is reported as unresolved. Private to the alpha stepper.
//
// Continuous extension of a step from (t0, x0, u0, f0) to (t1, x1, u1, f1), theta in [0, 1]:
// x the cubic Hermite interpolant of the values and slopes f at the ends (the states' own
// derivative, so its error is O(h^4), one order below the step's O(h^3) local error), u the
// linear interpolant of the algebraic inputs (the method defines them at the ends only; for
// rows in u, index 1, the hull of u0 and u1 is where a solution's inputs lie to first order).
// The box of x over [a, b] is widened by `margin` per state: the step's local error estimate
// (step doubling), which bounds, asymptotically, how far the computed ends (and so the
// interpolant) are from the exact solution through x0.

#include <functional>
#include <vector>

#include "../common/crossing_search.hpp"
#include "moreau/core/interval.hpp"
#include "moreau/core/smooth_function.hpp"

namespace moreau::internal {

// One end of a step.
struct AlphaStepPoint {
  double t = 0.0;
  const Vector* x = nullptr;  // states
  const Vector* u = nullptr;  // algebraic inputs
  const Vector* f = nullptr;  // x' = f(x, u, t)
};

class InsideConstraintSearch {
 public:
  // The path constraints (their rows stacked in order), the scene's parameters, and the
  // indices of the algebraic inputs among the scene's inputs; kept by reference.
  InsideConstraintSearch(const std::vector<SmoothFunction>& constraints, const Vector& parameters,
                         const std::vector<int>& algebraic);

  // Searches the step from `start` to `end` for the first time where a row k with watched[k]
  // has phi_k > thresholds()[k] on the continuous extension (theta of the step in the result,
  // see SearchCrossing). Rows whose value at the step's end is within kGrazeBand tolerances
  // of zero are left out (the next step starts there and watches them). One bound over the
  // whole step first: where it proves phi_k <= tolerance for every watched row (a step far
  // from every constraint) that is all; else `thresholds` (each >= tolerance) is asked for and
  // the search runs. `inputs` holds all the scene's inputs of the segment (the algebraic
  // entries are replaced by the path's).
  Crossing Search(const AlphaStepPoint& start, const AlphaStepPoint& end, const Vector& inputs,
                  std::vector<char> watched, const Vector& margin, double tolerance,
                  const std::function<Vector()>& thresholds);

 private:
  // phi at (x, u, t) into values (all rows, negated: the search looks for values below
  // -tolerance); false if not finite.
  bool Values(const ConstVectorRef& x, const ConstVectorRef& u, double t, Vector* values);
  // Enclosure of the negated rows over the box [x_lower_, x_upper_] x [u box] x [t_lower,
  // t_upper] (-inf, +inf for rows without one).
  void Bounds(double t_lower, double t_upper, Vector* lower, Vector* upper);

  const std::vector<SmoothFunction>& constraints_;
  const Vector& parameters_;
  const std::vector<int>& algebraic_;
  int nphi_ = 0;
  PolynomialPath path_;
  Vector full_inputs_, y_, box_lower_, box_upper_, x_lower_, x_upper_, value_;
  Vector step_lower_, step_upper_;  // the whole step's bound
  CrossingWorkspace search_;
  std::vector<Interval> x_box_, u_box_, p_box_, out_box_;
};

}  // namespace moreau::internal
