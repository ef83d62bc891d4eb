#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <utility>
#include <variant>

#include "fesd_run.hpp"
#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/projection.hpp"

namespace moreau::internal {

// Advances from tau_ towards step_end with `remaining` nominal elements: a trial pass of
// fixed-length elements; if a free side turns negative, a group solve of equal elements that
// ends on the switch. Returns true if a switch ended the advance.
bool FesdRun::Advance(double step_end, int* remaining) {
  // Fixed steps: a crossing found between an element's nodes (InsideViolation) that the group
  // solves then cannot locate (a graze at the event tolerance, a dip of a sliding mode's
  // indicator) would end a run that succeeds without the search, and a fixed step cannot be
  // shortened: the step is taken again without it, and the crossing counts as unresolved (a
  // warning, FesdResult::warnings). Error-controlled runs instead retry the step shorter and,
  // at min_step_size, end with the failure's status.
  const bool fallback = np_ > 0 && !inside_search_off_ && !options_.ErrorControlled();
  const long found = result_.stats.num_inside_crossings;
  const int remaining_before = *remaining;
  if (fallback) Save(&advance_before_);
  bool switched = false;
  for (;;) {
    UpdateWorkingSet(step_end - tau_);
    bool retry = false;
    switched = AdvanceOnce(step_end, remaining, &retry);
    if (!retry) {
      filter_.StepAccepted();
      break;
    }
  }
  if (fallback && failed() && result_.stats.num_inside_crossings > found) {
    const double t = advance_before_.y[system_.clock_index()];
    Restore(advance_before_);
    *remaining = remaining_before;
    ++result_.stats.num_unresolved_crossings;
    if (!std::isfinite(first_unresolved_time_)) first_unresolved_time_ = t;
    inside_search_off_ = true;
    switched = Advance(step_end, remaining);
    inside_search_off_ = false;
  }
  return switched;
}

bool FesdRun::AdvanceOnce(double step_end, int* remaining, bool* retry) {
  const double rest = step_end - tau_;
  const double h_trial = rest / *remaining;
  AdvanceBuffers& buffers = advance_;
  buffers.y_start = y_;
  const Vector& y_start = buffers.y_start;
  // Indicator scales, and the pairs that start at zero (just switched): their indicators
  // are divided by tau^2 so that h -> 0 is not a root (zero-length elements are excluded).
  IndicatorEvaluation& start = indicators_;
  IndicatorsAt(y_start, velocity_, &start);
  Vector& scales = buffers.scales;
  scales.resize(np_);
  std::vector<int>& powers = buffers.powers;
  powers.assign(static_cast<std::size_t>(np_), 0);
  for (int k = 0; k < np_; ++k) {
    scales[k] = std::max(1.0, std::fabs(start.values[k]));
    if (std::fabs(start.values[k]) <= options_.event_tolerance) {
      powers[static_cast<std::size_t>(k)] = 2;
    }
  }

  // Trial pass: Radau IIA elements of length h_trial with the current statuses.
  std::vector<SolveRecord>& records = buffers.records;
  std::vector<Vector>& trial_w = buffers.trial_w;
  std::size_t& num_records = buffers.num_records;
  num_records = 0;
  for (Vector& w : trial_w) buffers.spare_w.push_back(std::move(w));  // recycled below
  trial_w.clear();
  records.reserve(static_cast<std::size_t>(*remaining));  // no regrowth per element
  trial_w.reserve(static_cast<std::size_t>(*remaining));
  Vector& y = buffers.y;
  y = y_start;
  EndVelocity& v_end = buffers.v_end;
  v_end = velocity_;  // the velocity level at the end of the last checked element
  Violation violation;
  std::string trial_failure;  // why the trial pass suspected a switch, if not by signs
  GroupSetup& trial_setup = buffers.trial_setup;  // one element of fixed length
  trial_setup.a_zero = a_zero_;
  trial_setup.h_fixed = h_trial;
  for (int e = 0; e < *remaining; ++e) {
    trial_setup.y_start = y;
    group_.Configure(trial_setup);
    const Vector* previous = trial_w.empty() ? last_w_ptr() : &trial_w.back();
    Vector& guess = buffers.guess;
    int reduced_iterations = 0;
    long reduced_factorizations = 0;
    const bool reduced = SmoothElementGuess(y, h_trial, previous, &guess, &reduced_iterations,
                                            &reduced_factorizations);
    if (!reduced) {
      group_.element(0).InitialGuess(y, h_trial, previous, previous != nullptr ? h_trial : 0.0,
                                     z_guess_, &guess);
    }
    solved_by_ = reduced ? &reduced_newton_ : &newton_;
    SemismoothNewtonResult& solved = buffers.solved;
    (reduced ? reduced_newton_ : newton_).Solve(group_, guess, &solved);
    if (reduced) {
      // The full element system held at the reduced solution (or its Newton went on from it).
      if (solved.converged() && solved.stats.iterations == 0) ++result_.stats.num_reduced_elements;
      solved.stats.iterations += reduced_iterations;
      solved.stats.factorizations += reduced_factorizations;
    }
    CountNewton(solved);
    if (!solved.converged()) {
      // A fixed-status element that does not converge: look for a switch inside it.
      trial_failure = "element " + std::to_string(e) +
                      " with the current statuses did not converge (" + ToString(solved.status) +
                      ": " + solved.message + "), so a switch was assumed";
      violation = {true, e, 0.5};
      break;
    }
    excluded_min_.assign(1, std::numeric_limits<double>::infinity());
    if (!FilterCheck(group_.element(0), y, solved.solution, 0)) {
      *retry = true;  // a left-out constraint came into contact: solve again with it
      return false;
    }
    violation = StageViolation(group_.element(0), scales, e);
    if (!violation.found && check_jump_stages_) {
      violation = JumpStageViolation(group_.element(0), scales, e);
    }
    group_.EndState(solved.solution, &buffers.y_next);
    const Vector& y_next = buffers.y_next;
    if (!violation.found) violation = EndViolation(group_.element(0), y_next, scales, e, &v_end);
    if (!violation.found) {
      violation = InsideViolation(group_.element(0), y, solved.solution, scales, e);
    }
    if (!violation.found) {
      if (records.size() == num_records) records.emplace_back();  // before taking a0, b0
      const Vector& a0 = num_records == 0 ? boundary_a_ : records[num_records - 1].a_last;
      const Vector& b0 = num_records == 0 ? boundary_b_ : records[num_records - 1].b_last;
      Record(solved.solution, h_trial, false, solved, *remaining - e, a0, b0,
             &records[num_records]);
      ++num_records;
    }
    if (buffers.spare_w.empty()) buffers.spare_w.emplace_back();
    trial_w.push_back(std::move(buffers.spare_w.back()));  // a recycled vector's storage
    buffers.spare_w.pop_back();
    trial_w.back() = solved.solution;
    if (violation.found) break;
    y = y_next;
  }

  if (!violation.found) {
    for (std::size_t i = 0; i < num_records; ++i) Commit(records[i]);
    last_w_ = trial_w.back();
    have_last_w_ = true;
    last_h_ = h_trial;
    *remaining = 0;
    tau_ = step_end;    // exact step end
    velocity_ = v_end;  // solved where it is read (v())
    z_guess_ = z_last_;
    return DecideAtBoundary();
  }

  // A switch inside trial element `violation.element`: re-solve the first m elements as a
  // group of equal length ending on it (equilibration); if the switch is not confirmed the
  // group covers the rest of the step.
  const int e = violation.element;
  ResolveVelocity(&v_end);  // the group's guess
  int m = (violation.fraction >= 0.5 || e == 0) ? e + 1 : e;
  double h_guess = (e + violation.fraction) * h_trial / m;
  // On a continuous free side, before the attempts proper (and only where the reduced switch
  // group does not apply): the same m, the length where the interpolant through the start and
  // the stages of trial element e crosses zero (CrossingGuess), and the stage states on the
  // trial elements' collocation polynomials. The sampled fraction above is at best the linear
  // crossing between two samples, and only the first node c_1 if the first stage is already
  // negative (F1, s = 2: a third of the element for a switch at a twentieth of it; the group's
  // Newton then takes four iterations instead of two). If this try does not converge or shows
  // an earlier switch, the attempts proceed exactly as without it.
  bool trajectory_try = violation.pair >= 0;
  bool reduced_tried = false;
  // The first try whose Newton does not converge is repeated once with the indicators
  // normalized by their own size (NormalizeIndicatorWeights): (E)'s roots stay, the spurious
  // minima of its residual near h = 0 go. If the repetition fails too, the tries go on as
  // without it: normalized weights for every later try turned two random scenes that succeed
  // into failures, and from the first try on they cost small crowds more tries than they saved.
  bool normalized = false;        // this try's weights are normalized
  bool normalize_pending = true;  // the normalized repetition is still to come
  for (int attempt = 0; attempt <= options_.max_event_retries; ++attempt) {
    if (attempt > 0) ++result_.stats.num_event_retries;
    GroupSetup& setup = buffers.group_setup;  // every member set (kept: no allocation)
    setup.y_start = y_start;
    setup.a_zero = a_zero_;
    setup.elements = m;
    setup.with_event = true;
    setup.h_fixed = 0.0;
    setup.h_max = rest / m;
    setup.h_reference = h_trial;
    setup.indicator_weights = scales.cwiseInverse();
    if (normalized) NormalizeIndicatorWeights(trial_w, y_start, &setup.indicator_weights);
    setup.indicator_power = powers;
    group_.Configure(setup);
    // First attempt: the reduced switch group where the statuses leave a smooth field, checked
    // on the full group system (its Newton continues from there if it does not hold).
    Vector& guess = buffers.group_guess;
    int reduced_iterations = 0;
    long reduced_factorizations = 0;
    const int pair = violation.pair;
    const bool reduced =
        attempt == 0 && pair >= 0 && !reduced_tried &&
        ReducedSwitchGuess(trial_w, y_start, h_trial, e, m, h_guess, pair,
                           setup.indicator_weights[pair], powers[static_cast<std::size_t>(pair)],
                           &guess, &reduced_iterations, &reduced_factorizations);
    reduced_tried = true;  // a repeated attempt 0 (after the trajectory try) does not redo it
    trajectory_try = trajectory_try && !reduced;
    if (!reduced) {
      const double h_try =
          trajectory_try ? CrossingGuess(trial_w, y_start, h_trial, e, pair, m, h_guess) : h_guess;
      guess = GroupGuess(trial_w, y_start, h_trial, m, h_try, v_end.v, trajectory_try);
    }
    solved_by_ = reduced ? &reduced_newton_ : &newton_;
    SemismoothNewtonResult& solved = buffers.solved;
    (reduced ? reduced_newton_ : newton_).Solve(group_, guess, &solved);
    if (reduced) {
      if (solved.converged() && solved.stats.iterations == 0) {
        result_.stats.num_reduced_elements += m;
      }
      solved.stats.iterations += reduced_iterations;
      solved.stats.factorizations += reduced_factorizations;
    }
    CountNewton(solved);
    ++result_.stats.num_groups;
    if (!solved.converged() && normalize_pending) {
      normalize_pending = false;
      normalized = true;
      --attempt;  // the same try again
      continue;
    }
    normalized = false;
    if (trajectory_try && !solved.converged()) {
      trajectory_try = false;
      --attempt;  // the attempts proper start now
      continue;
    }
    if (!solved.converged()) {
      // Other element counts and shorter guesses, alternately.
      if (attempt % 2 == 0 && m > 1) {
        --m;
      } else {
        h_guess *= 0.5;
      }
      continue;
    }
    const Vector& w = solved.solution;
    const double h = group_.H(w);
    // Cross complementarity inside the group: no continuous free side negative at a stage,
    // no indicator negative at an interior element boundary.
    Violation inner;
    EndVelocity v_inner;
    v_inner.v = w.segment(group_.v_offset(), nz_);
    for (int k = 0; k < m && !inner.found; ++k) {
      inner = StageViolation(group_.element(k), scales, k);
      if (!inner.found && check_jump_stages_) {
        inner = JumpStageViolation(group_.element(k), scales, k);
      }
      if (!inner.found && k + 1 < m) {
        inner = EndViolation(group_.element(k), group_.ElementStart(w, k + 1), scales, k, &v_inner);
      }
      if (!inner.found) {
        inner =
            InsideViolation(group_.element(k), group_.ElementStart(w, k),
                            w.segment(group_.element_offset(k), group_.element_size()), scales, k);
      }
    }
    if (inner.found && trajectory_try) {
      trajectory_try = false;
      --attempt;
      continue;
    }
    trajectory_try = false;
    if (inner.found) {
      // An earlier switch inside the group: aim at it.
      const double offset = (inner.element + inner.fraction) * h;
      m = std::clamp(static_cast<int>(std::lround(offset / h_trial)), 1, e + 1);
      h_guess = offset / m;
      continue;
    }
    excluded_min_.assign(static_cast<std::size_t>(m), std::numeric_limits<double>::infinity());
    bool filtered = true;
    for (int k = 0; k < m; ++k) {
      filtered &= FilterCheck(group_.element(k), group_.ElementStart(w, k),
                              w.segment(group_.element_offset(k), group_.element_size()), k);
    }
    if (!filtered) {
      *retry = true;
      return false;
    }
    const bool switched = h < setup.h_max * (1.0 - 1e-12);
    Record(w, h, switched, solved, *remaining, boundary_a_, boundary_b_, &buffers.group_record);
    Commit(buffers.group_record);
    last_w_ = w.segment(group_.element_offset(m - 1), group_.element_size());
    have_last_w_ = true;
    last_h_ = h;
    set_v(w.segment(group_.v_offset(), nz_));
    if (!switched) {
      *remaining = 0;
      tau_ = step_end;
      z_guess_ = z_last_;
      return DecideAtBoundary();
    }
    ++result_.stats.num_switches;
    const bool early = options_.keep_elements_after_early_switch &&
                       m * h < options_.min_element_fraction * h_trial;
    if (!early) *remaining = std::max(1, *remaining - m);
    const std::vector<bool> previous = a_zero_;
    if (!Decide(y_[system_.clock_index()], &previous)) return true;
    z_guess_ = ConsistentGuess(y_, v());
    have_last_w_ = false;  // no extrapolation across a switch
    return true;
  }
  Fail(FesdStatus::kEventLocationFailure, y_start[system_.clock_index()],
       (trial_failure.empty() ? std::string("a switch was detected") : trial_failure) +
           " within the next " + std::to_string(rest) +
           " but no group of equal elements ending on it converged in " +
           std::to_string(options_.max_event_retries) + " retries");
  return true;
}

// Raises each pair's weight w_k in (E) so that its scaled indicator is at least 1 where the
// group starts: w_k >= 1 / iota_k(y_start) for a free side that starts positive (power 0), and
// w_k >= c_1^2 / iota_k(y_1) for a continuous free side that starts at zero (power 2; y_1 the
// first stage of trial element 0, at tau = c_1, where iota_k / tau^2 approximates its limit
// iota_k'' h_ref^2 / 2 as tau -> 0). With the weights 1 / max(1, |iota_k(y_start)|) alone, a pair
// that starts slightly positive (a gap of 1e-5), or leaves zero with a small curvature, keeps
// (E)'s residual at that size as h -> 0: a near-root that attracts the Newton when the switch
// lies far from the guess (a crowd of 6000 agents, FESD s = 3: every attempt ended at lengths
// of 1e-7 to 1e-5 with residuals of 1e-4 to 1e-6). Weights are positive, so (E)'s roots stay.
// Jump free sides that start at zero keep their weights (their stage values are not the
// velocity level's).
void FesdRun::NormalizeIndicatorWeights(const std::vector<Vector>& trial_w, const Vector& y_start,
                                        Vector* weights) {
  // The indicators at y_start again (the step's evaluation there has been overwritten). Both
  // evaluations take the step start's velocity level: the first stage's values are read for
  // continuous free sides only, which do not depend on it.
  IndicatorEvaluation& start = advance_.start_indicators;
  IndicatorsAt(y_start, velocity_, &start);
  const std::vector<int>& powers = advance_.powers;
  bool first_stage = false;  // iota at trial element 0's first stage evaluated
  for (int k = 0; k < np_; ++k) {
    double size = 0.0;  // the scaled indicator at weight 1 where the group starts
    if (powers[static_cast<std::size_t>(k)] == 0) {
      size = start.values[k];
    } else if (!FreeSideIsJump(k) && !trial_w.empty()) {
      if (!first_stage) {
        Vector& y_first = advance_.first_stage_state;
        y_first = y_start + trial_w.front().segment(group_.element(0).state_offset(0), ny_);
        IndicatorsAt(y_first, velocity_, &advance_.first_stage_indicators);
        first_stage = true;
      }
      size = advance_.first_stage_indicators.values[k] / (tableau_.c[0] * tableau_.c[0]);
    }
    if (size > 0.0) (*weights)[k] = std::max((*weights)[k], 1.0 / size);
  }
}

// --- near-active constraint filter ------------------------------------------------------

void FesdRun::UpdateWorkingSet(double horizon) {
  if (!filter_.enabled()) return;
  LoweredSystem::WorkingLayout previous;
  if (filter_.Update(y_, a_zero_, z_guess_, horizon, &previous)) AdoptLayout(previous);
  result_.stats.max_working_pairs =
      std::max(result_.stats.max_working_pairs, static_cast<long>(np_));
}

void FesdRun::AdoptLayout(const LoweredSystem::WorkingLayout& previous) {
  auto remap = [&](Vector* z) {
    if (z->size() == previous.num_algebraic) *z = system_.RemapAlgebraic(*z, previous, 0.0);
  };
  // No deferred velocity level with the filter (no smooth fields, InitializeSmoothFields).
  MOREAU_ASSERT(!velocity_.deferred, "deferred velocity level in a filtered run");
  remap(&velocity_.v);
  remap(&z_guess_);
  remap(&z_last_);
  // Constraints joining the set are inactive (c > 0, lambda = 0).
  if (static_cast<int>(a_zero_.size()) == previous.num_pairs) {
    a_zero_ = system_.RemapStatuses(a_zero_, previous, false);
  }
  if (boundary_a_.size() == previous.num_pairs) {
    boundary_a_ =
        system_.RemapPairValues(boundary_a_, previous, std::numeric_limits<double>::quiet_NaN());
    boundary_b_ = system_.RemapPairValues(boundary_b_, previous, 0.0);
    PointEvaluation point;
    system_.Evaluate(y_, z_guess_, Derivatives::kNone, &point);
    for (Eigen::Index k = 0; k < boundary_a_.size(); ++k) {
      if (std::isnan(boundary_a_[k])) boundary_a_[k] = point.A[k];
    }
  }
  have_last_w_ = false;  // the previous element's unknowns are in the old layout
  nz_ = system_.num_algebraic();
  np_ = system_.num_pairs();
  group_.Resize();
}

bool FesdRun::FilterCheck(const internal::CollocationStages& stages, const Vector& y0,
                          const ConstVectorRef& w_e, int element) {
  if (!filter_.enabled()) return true;
  bool positive = true;
  double smallest = std::numeric_limits<double>::infinity();
  for (int i = 0; i < s_; ++i) {
    Vector& yi = filter_state_;
    yi = y0 + w_e.segment(stages.state_offset(i), ny_);
    double value = 0.0;
    positive &= filter_.Check(yi, &value);
    smallest = std::min(smallest, value);
  }
  excluded_min_[static_cast<std::size_t>(element)] = smallest;
  if (!positive) ++result_.stats.num_filter_rechecks;
  return positive;
}

Vector FesdRun::TrajectoryAlgebraic(const Vector& z) const {
  return filter_.enabled() && z.size() == nz_ ? system_.DeclaredAlgebraic(z) : z;
}

// A system without algebraic unknowns (no effects) and no sensitivities cannot switch: every
// element is a plain Radau IIA step, solved by the same kernel as the smooth Radau IIA
// integrator (stage increments extrapolated from the previous element's collocation
// polynomial), and committed at once.
void FesdRun::AdvanceSmooth(double step_end, int remaining) {
  internal::SmoothCollocationSolver::Stopping stopping;
  stopping.tolerance = options_.newton.tolerance;
  stopping.max_iterations = options_.newton.max_iterations;
  const double h = (step_end - tau_) / remaining;
  for (int e = 0; e < remaining && !failed(); ++e) {
    if (have_last_w_ && last_h_ > 0.0) {
      ExtrapolatedIncrements(h, &smooth_z_);
    } else {
      smooth_z_.setZero(ny_, s_);
    }
    const long factorizations = smooth_->num_factorizations();
    int iterations = 0;
    const auto outcome = smooth_->Solve(h, y_, stopping, &smooth_z_, &iterations);
    result_.stats.num_newton_iterations += iterations;
    factorizations_ += smooth_->num_factorizations() - factorizations;
    if (outcome != internal::SmoothCollocationSolver::Outcome::kConverged) {
      Fail(FesdStatus::kNewtonFailure, y_[system_.clock_index()],
           "Newton on the collocation equations of an element of length " + std::to_string(h) +
               " did not converge");
      return;
    }
    if (options_.record_stages) {
      for (int i = 0; i < s_; ++i) {
        const Vector yi = y_ + smooth_z_.col(i);
        result_.stage_trajectory.Append(yi[system_.clock_index()], yi.head(nx_), Vector(), h);
      }
    }
    if (keep_polynomials_) {
      ElementPolynomial polynomial = SparePolynomial();
      polynomial.y0 = y_;
      polynomial.increments = smooth_z_;
      polynomial.algebraic.resize(0, s_);
      polynomial.h = h;
      polynomial.a_zero.clear();
      polynomial.frozen = false;
      OnCommittedElement(std::move(polynomial));
    }
    y_ += smooth_z_.col(s_ - 1);
    FesdElement element;
    element.t_start = tau_;
    element.length = h;
    element.newton_iterations = iterations;
    result_.elements.push_back(element);
    result_.stats.min_element_length = std::min(result_.stats.min_element_length, h);
    ++result_.stats.num_elements;
    tau_ += h;
    last_z_matrix_ = smooth_z_;
    last_h_ = h;
    have_last_w_ = true;
    if (options_.record_trajectory && !dense_output_) {
      result_.trajectory.Append(y_[system_.clock_index()], y_.head(nx_), Vector(), h);
    }
    if (progress_) progress_(y_[system_.clock_index()]);
  }
  tau_ = step_end;
}

// Stage increments from the previous element's collocation polynomial (weights cached for
// the step-length ratio).
void FesdRun::ExtrapolatedIncrements(double h, Matrix* z) {
  const double ratio = h / last_h_;
  if (ratio != extrapolation_ratio_) {
    extrapolation_ratio_ = ratio;
    extrapolation_.resize(s_, s_);
    for (int i = 0; i < s_; ++i) {
      extrapolation_.col(i) = tableau_.InterpolationWeights(1.0 + tableau_.c[i] * ratio);
      extrapolation_(s_ - 1, i) -= 1.0;  // minus Z_s: increments from the new start
    }
  }
  z->noalias() = last_z_matrix_ * extrapolation_;
}

// Guess of a group of m elements of length h_guess from the trial elements.
Vector FesdRun::GroupGuess(const std::vector<Vector>& trial_w, const Vector& y_start,
                           double h_trial, int m, double h_guess, const Vector& v_end,
                           bool on_trajectory) {
  Vector w = Vector::Zero(group_.num_unknowns());
  const internal::CollocationStages& stages = group_.element(0);
  const int trials = static_cast<int>(trial_w.size());
  // The trial pass's trajectory at offset t from y_start: trial element q's collocation
  // polynomial y_q + sum_j w_j((t - q h_trial) / h_trial) Z_j (the last one extrapolated).
  std::vector<Vector> trial_start;
  if (on_trajectory && trials > 0) {
    trial_start.assign(static_cast<std::size_t>(trials), y_start);
    for (int q = 1; q < trials; ++q) {
      trial_start[static_cast<std::size_t>(q)] =
          trial_start[static_cast<std::size_t>(q - 1)] +
          trial_w[static_cast<std::size_t>(q - 1)].segment(stages.state_offset(s_ - 1), ny_);
    }
  }
  auto state_at = [&](double t, Vector* y) {
    const int q = std::clamp(static_cast<int>(std::floor(t / h_trial)), 0, trials - 1);
    const Vector weights = tableau_.InterpolationWeights(t / h_trial - q);
    const Vector& z = trial_w[static_cast<std::size_t>(q)];
    *y = trial_start[static_cast<std::size_t>(q)];
    for (int j = 0; j < s_; ++j) *y += weights[j] * z.segment(stages.state_offset(j), ny_);
  };
  Vector element_start, stage_state;
  for (int e = 0; e < m; ++e) {
    Vector element;
    if (e < trials && on_trajectory) {
      element = trial_w[static_cast<std::size_t>(e)];  // algebraic values of trial element e
      state_at(e * h_guess, &element_start);
      for (int i = 0; i < s_; ++i) {
        state_at((e + tableau_.c[i]) * h_guess, &stage_state);
        element.segment(stages.state_offset(i), ny_) = stage_state - element_start;
      }
    } else if (e < trials) {
      element = trial_w[static_cast<std::size_t>(e)];
      // Stage increments scale with the element length to first order.
      for (int i = 0; i < s_; ++i)
        element.segment(stages.state_offset(i), ny_) *= h_guess / h_trial;
    } else {
      element = stages.InitialGuess(y_start, h_guess, nullptr, 0.0, z_guess_);
    }
    w.segment(group_.element_offset(e), group_.element_size()) = element;
  }
  w.segment(group_.v_offset(), nz_) = v_end;
  w[group_.h_index()] = h_guess;
  return w;
}

// The first stage at which a continuous free side is negative beyond tolerance, with the
// crossing fraction (jump free sides are checked at element ends, see EndViolation).
Violation FesdRun::StageViolation(const internal::CollocationStages& stages, const Vector& scales,
                                  int element) const {
  Violation first;
  for (int k = 0; k < np_; ++k) {
    if (FreeSideIsJump(k)) continue;
    const bool a_zero = a_zero_[static_cast<std::size_t>(k)];
    double previous_value = std::numeric_limits<double>::quiet_NaN();
    double previous_c = 0.0;
    for (int i = 0; i < s_; ++i) {
      const double free = a_zero ? stages.stage(i).B[k] : stages.stage(i).A[k];
      if (free < -options_.event_tolerance * scales[k]) {
        double fraction = tableau_.c[i];
        if (std::isfinite(previous_value) && previous_value > free) {
          fraction =
              previous_c + (tableau_.c[i] - previous_c) * previous_value / (previous_value - free);
        }
        fraction = std::clamp(fraction, 1e-3, 1.0);
        if (!first.found || fraction < first.fraction) first = {true, element, fraction, k};
        break;
      }
      previous_value = free;
      previous_c = tableau_.c[i];
    }
  }
  return first;
}

void FesdRun::ResolveVelocity(EndVelocity* end) const {
  if (!end->deferred) return;
  end->deferred = false;
  // The solve EndViolation would have made there (the last stage's algebraic values as the
  // starting point), evaluating the system at (y, z) itself: the stage data may be gone.
  Vector solved;
  if (system_.SolveVelocityLevel(end->y, a_zero_, end->z, &solved)) end->v = solved;
}

void FesdRun::IndicatorsAt(const Vector& y, const EndVelocity& velocity,
                           IndicatorEvaluation* out) const {
  system_.EvaluateEventIndicators(y, velocity.v, a_zero_, Derivatives::kNone, out);
  if (!velocity.deferred) return;
  // Deferred only where the jump sides have a closed form (EndViolation).
  closed_free_.resize(np_);
  const bool closed = JumpFreeSidesInClosedForm(&closed_free_);
  MOREAU_ASSERT(closed, "deferred velocity level without closed-form jump sides");
  for (int k = 0; k < np_; ++k) {
    if (FreeSideIsJump(k)) out->values[k] = closed_free_[k];
  }
}

// Event indicators at the end state y of an element (velocity-level values solved from v,
// which is updated, or deferred): the first negative one beyond tolerance is a switch in the
// element.
Violation FesdRun::EndViolation(const internal::CollocationStages& stages, const Vector& y,
                                const Vector& scales, int element, EndVelocity* end_v) const {
  Violation violation;
  if (np_ == 0) return violation;
  const int last = s_ - 1;
  end_level_.valid = false;
  const bool at_stage = y.size() == stages.stage_state(last).size() &&
                        (y.array() == stages.stage_state(last).array()).all();
  const Vector& z_last = stages.stage_algebraic(last);
  IndicatorEvaluation& end = indicators_;
  closed_free_.resize(np_);
  if (at_stage && JumpFreeSidesInClosedForm(&closed_free_)) {
    // Continuous sides from y, jump sides in closed form (end_v->v only fills the argument):
    // the velocity level itself is solved only where it is used (ResolveVelocity).
    end_v->deferred = true;
    end_v->y = y;
    end_v->z = z_last;
    IndicatorsAt(y, *end_v, &end);
  } else {
    // y is the last stage's state (Radau IIA: c_s = 1): solved from that stage's evaluation
    // where it has derivatives (a linear velocity level needs no evaluation of its own; a
    // nonlinear one is solved by Newton from the stage's algebraic values). That is the solve
    // the element's certificates make at its last stage (ConsistentFreeSides), which
    // therefore take it from end_level_.
    Vector& solved = end_solved_;
    const PointEvaluation* point = at_stage ? stages.stage_with_derivatives(last) : nullptr;
    const bool ok =
        point != nullptr
            ? system_.SolveVelocityLevel(y, a_zero_, z_last, z_last, *point, &solved)
            : system_.SolveVelocityLevel(y, a_zero_, at_stage ? z_last : end_v->v, &solved);
    if (!ok) return violation;
    end_v->v = solved;
    end_v->deferred = false;
    system_.EvaluateEventIndicators(y, solved, a_zero_, Derivatives::kNone, &end);
    if (at_stage) {
      end_level_.valid = true;
      end_level_.a_zero = a_zero_;
      end_level_.y = y;
      end_level_.z = z_last;
      end_level_.indicators = end.values;
    }
  }
  for (int k = 0; k < np_ && !violation.found; ++k) {
    if (end.values[k] < -options_.event_tolerance * scales[k]) {
      violation = {true, element, FreeSideIsJump(k) ? 1.0 : EndCrossing(stages, k, end.values[k]),
                   k};
    }
  }
  return violation;
}

// Crossing fraction of pair k between the second-to-last stage and a negative end value.
double FesdRun::EndCrossing(const internal::CollocationStages& stages, int k,
                            double end_value) const {
  if (s_ < 2) return 1.0;
  const bool a_zero = a_zero_[static_cast<std::size_t>(k)];
  const double before = a_zero ? stages.stage(s_ - 2).B[k] : stages.stage(s_ - 2).A[k];
  if (before <= end_value) return 1.0;
  const double c0 = tableau_.c[s_ - 2];
  return std::clamp(c0 + (1.0 - c0) * before / (before - end_value), 1e-3, 1.0);
}

void FesdRun::CountNewton(const SemismoothNewtonResult& solved) {
  result_.stats.num_newton_iterations += solved.stats.iterations;
  factorizations_ += solved.stats.factorizations;
}

}  // namespace moreau::internal
