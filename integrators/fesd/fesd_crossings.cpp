// Zeros of the continuous free sides between the nodes of an element (docs/fesd-formulation.md,
// section 11): the crossing search of common/crossing_search.hpp on the element's collocation
// polynomial, in fixed and adaptive steps.
#include <algorithm>
#include <cmath>
#include <limits>

#include "fesd_run.hpp"

namespace moreau::internal {
namespace {

// Samples of the Hermite interpolant per element (free sides without bounds): a polynomial of
// degree 2 s + 1 <= 15 has at most seven local minima in [0, 1]; 64 points find a dip wider
// than 1/64 of the element and deeper than the interpolant's change over 1/64.
constexpr int kHermiteSamples = 64;

// Sides within this many event tolerances of zero at an element's start or end are at a
// contact or switch there, not searched between the nodes (InsideViolation).
constexpr double kGrazeBand = 10.0;

// Jump free sides (an active pair's multiplier, a sliding mode's theta) between the stages of an
// error-controlled element, at kJumpDipSamples - 1 equidistant points, each a consistent
// velocity-level solve on the collocation polynomial: a release window of 1/16 of the element
// and more is seen. Every jump side is sampled where there are at most kJumpDipAllPairs of
// them; beyond (a crowd's contacts) only those whose stage values come within kJumpDipSpread
// times their spread over the stages of zero (a side far above zero for its variation is not
// sampled): the samples cost a velocity-level solve of the whole scene each.
constexpr double kJumpDipSpread = 2.0;
constexpr int kJumpDipSamples = 16;
constexpr int kJumpDipAllPairs = 16;

}  // namespace

Violation FesdRun::InsideViolation(const CollocationStages& stages, const Vector& y0,
                                   const ConstVectorRef& w_e, const Vector& scales, int element) {
  Violation violation;
  if (np_ == 0 || inside_search_off_) return violation;
  InsideBuffers& b = inside_;
  b.watched.assign(static_cast<std::size_t>(np_), 0);
  bool any = false;
  for (int k = 0; k < np_; ++k) {
    if (FreeSideIsJump(k)) continue;
    b.watched[static_cast<std::size_t>(k)] = 1;
    any = true;
  }
  b.increments.resize(ny_, s_);
  for (int i = 0; i < s_; ++i) b.increments.col(i) = w_e.segment(stages.state_offset(i), ny_);
  b.path.SetCollocation(tableau_, y0, b.increments);
  b.thresholds.resize(np_);
  for (int k = 0; k < np_; ++k) b.thresholds[k] = options_.event_tolerance * scales[k];
  if (!any) return JumpDipViolation(stages, element);
  // Jump sides are not read for the watched pairs; the last stage's algebraic values fill v.
  const Vector& v = stages.stage_algebraic(s_ - 1);
  auto values_at = [&](double theta, Vector* values) {
    b.path.Point(theta, &b.y);
    system_.EvaluateEventIndicators(b.y, v, a_zero_, Derivatives::kNone, &b.at);
    *values = b.at.values;
    return values->allFinite();
  };
  auto bounds_over = [&](double a, double c, Vector* lower, Vector* upper) {
    b.path.Box(a, c, &b.box_lower, &b.box_upper);
    system_.BoundEventIndicators(b.box_lower, b.box_upper, a_zero_, lower, upper);
  };
  const CrossingFunctionRefs functions{values_at, bounds_over};
  // Side k below minus its tolerance at theta (a crossing, then located between the start and
  // theta by bisection on the polynomial, as the bounded search would locate it).
  auto negative_at = [&](int k, double theta) {
    return functions.values(theta, &b.probe) && b.probe[k] < -b.thresholds[k];
  };
  auto zero_before = [&](int k, double theta) {
    double lo = 0.0, hi = theta;
    for (int i = 0; i < CrossingSearchLimits{}.bisections; ++i) {
      const double mid = 0.5 * (lo + hi);
      (functions.values(mid, &b.probe) && b.probe[k] < 0.0 ? hi : lo) = mid;
    }
    return hi;
  };
  // A side at zero at the element's start or end (within kGrazeBand tolerances: a contact
  // just released, a switch the element ends on, a graze along the boundary) is not watched:
  // its bound over any piece next to that end admits zero, so the search could not decide
  // it, and a return below zero shows at the stages and the end, which are checked.
  bool watched_any = false;
  b.end_grazes.assign(static_cast<std::size_t>(np_), 0);
  for (double end : {0.0, 1.0}) {
    if (!functions.values(end, &b.end_values)) continue;
    for (int k = 0; k < np_; ++k) {
      if (b.end_values[k] <= kGrazeBand * b.thresholds[k]) {
        if (end == 1.0 && b.watched[static_cast<std::size_t>(k)]) {
          b.end_grazes[static_cast<std::size_t>(k)] = 1;
        }
        b.watched[static_cast<std::size_t>(k)] = 0;
      }
    }
  }
  // ... but a side at zero at the end may have reached it from below: the group solve can
  // land on the far zero of a contact shorter than the element's nodes are apart (a disc
  // brushing a point for a hundredth of the element: the side is positive at the stages and
  // zero at the end, and the dip before the end is never looked at). A side rising into the
  // end is probed where its tangent there is two tolerances below zero; a value below minus
  // one tolerance is a crossing, located between the start and the probe.
  Violation end_dip;
  if (std::find(b.end_grazes.begin(), b.end_grazes.end(), 1) != b.end_grazes.end()) {
    b.path.Point(1.0, &b.y);
    b.path.Derivative(1.0, &b.dy);
    system_.EvaluateEventIndicators(b.y, v, a_zero_, Derivatives::kStates, &b.at);
    for (int p = 0; p < np_; ++p) {
      if (!b.end_grazes[static_cast<std::size_t>(p)]) continue;
      b.at.d_y.Row(p, &b.row);
      const double slope = b.row.dot(b.dy);
      if (!(slope > 0.0)) continue;
      const double end_value = b.at.values[p];
      const double step = (std::fabs(end_value) + 2.0 * b.thresholds[p]) / slope;
      if (!(step < 0.5)) continue;  // a rise too slow to dip beyond the tolerance
      if (!negative_at(p, 1.0 - step)) continue;
      const double zero = zero_before(p, 1.0 - step);
      if (!end_dip.found || zero < end_dip.fraction) {
        end_dip = {true, element, std::clamp(zero, 1e-3, 1.0), p};
      }
    }
  }
  auto with_end_dip = [&](const Violation& found) {
    if (!end_dip.found || (found.found && found.fraction <= end_dip.fraction)) return found;
    if (!found.found) ++result_.stats.num_inside_crossings;
    return end_dip;
  };
  for (int k = 0; k < np_; ++k) watched_any |= b.watched[static_cast<std::size_t>(k)] != 0;
  if (!watched_any) return with_end_dip(JumpDipViolation(stages, element));
  Crossing crossing = SearchCrossing(b.watched, b.thresholds, functions, {}, &b.search);
  result_.stats.num_bound_evaluations += crossing.bound_evaluations;
  if (crossing.outcome == CrossingOutcome::kNone) {
    // Free sides without a bound (index-1 complementarity, functions without interval
    // evaluation): the extremum of their Hermite interpolant from the values and exact
    // derivatives at the element start and the stages, evaluated on the polynomial.
    // (The search's bound over the whole element told which sides have one: search.bounded.)
    const std::vector<double>& nodes = Resolution().nodes;
    bool have_node_values = false;  // the buffers keep their vectors across calls
    for (int k = 0; k < np_; ++k) {
      const auto i = static_cast<std::size_t>(k);
      if (!b.watched[i] || b.search.bounded[i]) continue;
      if (!have_node_values) {
        // Values and d/dtheta = d_y . y'(theta) at every node, for all pairs at once.
        have_node_values = true;
        b.node_values.resize(nodes.size());
        b.node_slopes.resize(nodes.size());
        // The slopes along the path directly where every block provides them (index-1
        // complementarity: no Jacobian d_y formed), else from d_y (a block that declines at
        // one node declines at all: not asked again).
        bool direct_slopes = true;
        for (std::size_t j = 0; j < nodes.size(); ++j) {
          b.path.Point(nodes[j], &b.y);
          b.path.Derivative(nodes[j], &b.dy);
          if (direct_slopes && system_.EvaluateEventIndicatorSlopes(
                                   b.y, v, a_zero_, b.dy, &b.node_values[j], &b.node_slopes[j])) {
            continue;
          }
          direct_slopes = false;
          system_.EvaluateEventIndicators(b.y, v, a_zero_, Derivatives::kStates, &b.at);
          b.node_values[j] = b.at.values;
          b.node_slopes[j].resize(np_);
          for (int p = 0; p < np_; ++p) {
            b.at.d_y.Row(p, &b.row);
            b.node_slopes[j][p] = b.row.dot(b.dy);
          }
        }
      }
      b.values.resize(nodes.size());
      b.slopes.resize(nodes.size());
      for (std::size_t j = 0; j < nodes.size(); ++j) {
        b.values[j] = b.node_values[j][k];
        b.slopes[j] = b.node_slopes[j][k];
      }
      // Most elements are far from a switch: the Bernstein bound of the interpolant already
      // shows that no sample can be below the threshold (the same outcome, without them).
      if (HermiteLowerBound(nodes, b.values, b.slopes) >= -b.thresholds[k]) continue;
      double theta = 0.5;
      if (!(HermiteMinimum(nodes, b.values, b.slopes, kHermiteSamples, &theta) <
            -b.thresholds[k])) {
        continue;
      }
      if (negative_at(k, theta)) {
        crossing.outcome = CrossingOutcome::kFound;
        crossing.function = k;
        crossing.theta = zero_before(k, theta);
        break;
      }
    }
  }
  if (crossing.outcome == CrossingOutcome::kUnresolved) {
    ++result_.stats.num_unresolved_crossings;
    if (!std::isfinite(first_unresolved_time_)) {
      first_unresolved_time_ = y0[system_.clock_index()];
    }
    return with_end_dip(violation);
  }
  if (crossing.outcome != CrossingOutcome::kFound) {
    return with_end_dip(JumpDipViolation(stages, element));
  }
  ++result_.stats.num_inside_crossings;
  violation = {true, element, std::clamp(crossing.theta, 1e-3, 1.0), crossing.function};
  return with_end_dip(violation);
}

Violation FesdRun::JumpDipViolation(const CollocationStages& stages, int element) {
  Violation violation;
  if (!check_jump_stages_) return violation;
  InsideBuffers& b = inside_;  // (path and thresholds set by InsideViolation)
  // Stage values are order-s approximations of the consistent ones (JumpStageViolation checks
  // the consistent values at the stages); with many jump sides, one whose smallest stage value
  // exceeds kJumpDipSpread times its spread is not sampled.
  b.watched.assign(static_cast<std::size_t>(np_), 0);
  bool any = false;
  int jump_sides = 0;
  for (int k = 0; k < np_; ++k) jump_sides += FreeSideIsJump(k) ? 1 : 0;
  const bool screen = jump_sides > kJumpDipAllPairs;
  for (int k = 0; k < np_; ++k) {
    if (!FreeSideIsJump(k)) continue;
    const bool a_zero = a_zero_[static_cast<std::size_t>(k)];
    double lowest = std::numeric_limits<double>::infinity();
    double highest = -lowest;
    for (int i = 0; i < s_; ++i) {
      const double free = a_zero ? stages.stage(i).B[k] : stages.stage(i).A[k];
      lowest = std::min(lowest, free);
      highest = std::max(highest, free);
    }
    if (screen && lowest > kJumpDipSpread * (highest - lowest)) continue;
    b.watched[static_cast<std::size_t>(k)] = 1;
    any = true;
  }
  if (!any) return violation;
  // The consistent jump sides at equidistant points of the collocation polynomial (the stage
  // nearest to each point gives the velocity level's initial guess); the first negative one
  // beyond the tolerance is a switch at the zero interpolated from the sample before it.
  b.values.assign(static_cast<std::size_t>(np_), std::numeric_limits<double>::quiet_NaN());
  double previous_theta = 0.0;
  for (int j = 1; j < kJumpDipSamples; ++j) {
    const double theta = static_cast<double>(j) / kJumpDipSamples;
    int nearest = 0;
    for (int i = 1; i < s_; ++i) {
      if (std::fabs(tableau_.c[i] - theta) < std::fabs(tableau_.c[nearest] - theta)) nearest = i;
    }
    b.path.Point(theta, &b.y);
    const Vector& z = stages.stage_algebraic(nearest);
    if (!system_.SolveVelocityLevel(b.y, a_zero_, z, &b.dy)) continue;  // undecided: no sample
    system_.EvaluateEventIndicators(b.y, b.dy, a_zero_, Derivatives::kNone, &b.at);
    for (int k = 0; k < np_; ++k) {
      if (!b.watched[static_cast<std::size_t>(k)]) continue;
      const double free = b.at.values[k];
      const double before = b.values[static_cast<std::size_t>(k)];
      if (free < -b.thresholds[k]) {
        double fraction = theta;
        if (std::isfinite(before) && before > free) {
          fraction = previous_theta + (theta - previous_theta) * before / (before - free);
        }
        fraction = std::clamp(fraction, 1e-3, 1.0);
        if (!violation.found || fraction < violation.fraction) {
          violation = {true, element, fraction, k};
        }
      }
      b.values[static_cast<std::size_t>(k)] = free;
    }
    if (violation.found) break;
    previous_theta = theta;
  }
  if (violation.found) ++result_.stats.num_inside_crossings;
  return violation;
}

}  // namespace moreau::internal
