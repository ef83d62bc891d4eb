#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "fesd_run.hpp"
#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/projection.hpp"

namespace moreau::internal {

// Decides the statuses at y_ (the slow solution) and records the events against `previous`
// (null at t0). Returns false, with the status set, if no continuation exists.
bool FesdRun::Decide(double t, const std::vector<bool>* previous) {
  const StatusDecision decision = system_.DecideStatuses(y_, options_.event_tolerance);
  if (!decision.solved) {
    Fail(FesdStatus::kStatusDecisionFailure, t, decision.message);
    return false;
  }
  if (decision.ambiguous) {
    result_.events.push_back({t, EventKind::kAmbiguous, system_.scene().name, decision.message});
  }
  const std::vector<Event> events = previous != nullptr
                                        ? system_.StatusEvents(t, *previous, decision.a_zero)
                                        : system_.InitialEvents(t, y_, decision.a_zero);
  result_.events.insert(result_.events.end(), events.begin(), events.end());
  if (system_.time_freezing()) {
    // A relay jumps (in physical time) when it starts travelling between 0 and 1.
    const std::vector<int> after = system_.MemoryTargets(decision.a_zero);
    const std::vector<int> before =
        previous != nullptr ? system_.MemoryTargets(*previous) : std::vector<int>(after.size(), -1);
    for (std::size_t i = 0; i < after.size(); ++i) {
      if (after[i] >= 0 && before[i] < 0) {
        result_.relays[i].jump_times.push_back(t);
        result_.relays[i].values.push_back(after[i]);
      }
    }
  }
  a_zero_ = decision.a_zero;
  set_v(decision.v);
  return true;
}

// After a stretch without a switch: a free side that is zero at its end (a switch exactly
// on a step boundary, or at the final time) is decided there.
bool FesdRun::DecideAtBoundary() {
  if (np_ == 0) return false;
  IndicatorEvaluation& end = indicators_;
  IndicatorsAt(y_, velocity_, &end);
  Vector& scaled = boundary_scaled_;
  scaled.resize(np_);
  for (int k = 0; k < np_; ++k) scaled[k] = end.values[k] / std::max(1.0, std::fabs(end.values[k]));
  Eigen::Index first = 0;
  if (scaled.minCoeff(&first) > options_.event_tolerance) return false;
  const std::vector<bool> previous = a_zero_;
  const Vector v_before = v();
  if (!Decide(y_[system_.clock_index()], &previous)) return true;
  if (previous != a_zero_) {
    ++result_.stats.num_switches;
    z_guess_ = ConsistentGuess(y_, v());
    have_last_w_ = false;
    if (options_.sensitivities) ApplySaltation(previous, v_before, static_cast<int>(first));
  }
  return false;
}

bool FesdRun::DecideAtBreakpoint() {
  if (np_ == 0) return true;
  Vector solved;
  bool consistent = system_.SolveVelocityLevel(y_, a_zero_, v(), &solved);
  if (consistent) {
    IndicatorEvaluation indicators;
    system_.EvaluateEventIndicators(y_, solved, a_zero_, Derivatives::kNone, &indicators);
    for (int k = 0; k < np_; ++k) {
      consistent &= indicators.values[k] >
                    options_.event_tolerance * std::max(1.0, std::fabs(indicators.values[k]));
    }
  }
  if (consistent) {
    set_v(solved);
    return true;
  }
  const std::vector<bool> previous = a_zero_;
  if (!Decide(y_[system_.clock_index()], &previous)) return false;
  if (previous == a_zero_) return true;
  ++result_.stats.num_switches;
  // Continuous values and the start boundary of the next element under the new statuses.
  z_guess_ = ConsistentGuess(y_, v());
  have_last_w_ = false;
  PointEvaluation point;
  system_.Evaluate(y_, z_guess_, Derivatives::kNone, &point);
  boundary_a_ = point.A;
  boundary_b_ = point.B;
  return true;
}

// A given initial state outside the moving sets jumps onto them (the sweeping process's
// projection at t0); with sensitivities the transfer of the projection (implicit function
// theorem on its complementarity system) starts the chain. Returns false on failure.
bool FesdRun::ProjectInitialState() {
  const Scene& scene = system_.scene();
  const int clock = system_.clock_index();
  const Vector x0 = y_.head(nx_);
  const Vector u = system_.inputs(), p = system_.parameters();
  const double violation = MinimumMovingSetConstraint(scene, x0, y_[clock], u, p);
  const double tolerance =
      kInitialFeasibilityTolerance * std::max(1.0, x0.lpNorm<Eigen::Infinity>());
  const bool outside = violation < -tolerance;
  // On the boundary (a shooting node that rides a moving set lies there) the map from the
  // given state is not differentiable: inward perturbations start free, outward ones are
  // projected. The derivative of the outward branch (the projection's, an identity on the
  // state) keeps the chain consistent with nearby infeasible starts (docs/ocp.md).
  const bool on_boundary =
      !outside && options_.sensitivities &&
      violation <= kMovingSetBoundaryTolerance * std::max(1.0, x0.lpNorm<Eigen::Infinity>());
  if (!outside && !on_boundary) return true;
  const MovingSetProjection projection =
      ProjectOntoMovingSets(scene, x0, y_[clock], u, p, options_.sensitivities);
  if (!projection.converged) {
    Fail(FesdStatus::kNewtonFailure, y_[clock], projection.message);
    return false;
  }
  if (outside) {
    std::ostringstream detail;
    detail << "initial state outside the moving sets (min c = " << violation
           << "): projected onto C(t0), jump of size " << projection.distance;
    result_.events.push_back({y_[clock], EventKind::kEnter, scene.name, detail.str()});
    y_.head(nx_) = projection.x;
  }
  if (options_.sensitivities) {
    TrackProjection(projection.d_x0, projection.d_t, projection.d_p, projection.d_u);
  }
  return true;
}

// Index in y of a relay's memory state (relays follow the scene states in order).
int FesdRun::RelayMemoryIndex(const RelaySignal& signal) const {
  const auto& names = system_.relay_names();
  const auto it = std::find(names.begin(), names.end(), signal.relay);
  return nx_ + static_cast<int>(it - names.begin());
}

// Algebraic guess at y: consistent values of the continuous variables from y, jump
// variables (theta, alpha, multipliers) from the velocity-level values v.
const Vector& FesdRun::ConsistentGuess(const Vector& y, const Vector& v) const {
  MOREAU_ASSERT(&v != &consistent_z_, "ConsistentGuess: v is its own output");
  Vector& z = consistent_z_;
  system_.InitialAlgebraicGuess(y, nullptr, &z);
  for (int i = 0; i < nz_; ++i) {
    if (!system_.continuous_algebraic()[static_cast<std::size_t>(i)]) z[i] = v[i];
  }
  return z;
}

}  // namespace moreau::internal
