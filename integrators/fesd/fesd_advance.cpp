#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
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
  for (;;) {
    UpdateWorkingSet(step_end - tau_);
    bool retry = false;
    const bool switched = AdvanceOnce(step_end, remaining, &retry);
    if (!retry) {
      filter_.StepAccepted();
      return switched;
    }
  }
}

bool FesdRun::AdvanceOnce(double step_end, int* remaining, bool* retry) {
  const double rest = step_end - tau_;
  const double h_trial = rest / *remaining;
  const Vector y_start = y_;
  // Indicator scales, and the pairs that start at zero (just switched): their indicators
  // are divided by tau^2 so that h -> 0 is not a root (zero-length elements are excluded).
  IndicatorEvaluation& start = indicators_;
  IndicatorsAt(y_start, velocity_, &start);
  Vector scales(np_);
  std::vector<int> powers(static_cast<std::size_t>(np_), 0);
  for (int k = 0; k < np_; ++k) {
    scales[k] = std::max(1.0, std::fabs(start.values[k]));
    if (std::fabs(start.values[k]) <= options_.event_tolerance) {
      powers[static_cast<std::size_t>(k)] = 2;
    }
  }

  // Trial pass: Radau IIA elements of length h_trial with the current statuses.
  std::vector<SolveRecord> records;
  std::vector<Vector> trial_w;
  Vector y = y_start;
  EndVelocity v_end = velocity_;  // the velocity level at the end of the last checked element
  Violation violation;
  std::string trial_failure;  // why the trial pass suspected a switch, if not by signs
  GroupSetup trial_setup;     // one element of fixed length (its vectors reused across elements)
  trial_setup.a_zero = a_zero_;
  trial_setup.h_fixed = h_trial;
  for (int e = 0; e < *remaining; ++e) {
    trial_setup.y_start = y;
    group_.Configure(trial_setup);
    const Vector* previous = trial_w.empty() ? last_w_ptr() : &trial_w.back();
    Vector guess;
    int reduced_iterations = 0;
    long reduced_factorizations = 0;
    const bool reduced = SmoothElementGuess(y, h_trial, previous, &guess, &reduced_iterations,
                                            &reduced_factorizations);
    if (!reduced) {
      guess = group_.element(0).InitialGuess(y, h_trial, previous,
                                             previous != nullptr ? h_trial : 0.0, z_guess_);
    }
    solved_by_ = reduced ? &reduced_newton_ : &newton_;
    SemismoothNewtonResult solved = (reduced ? reduced_newton_ : newton_).Solve(group_, guess);
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
    const Vector y_next = group_.EndState(solved.solution);
    if (!violation.found) violation = EndViolation(group_.element(0), y_next, scales, e, &v_end);
    trial_w.push_back(solved.solution);
    if (violation.found) break;
    const Vector& a0 = records.empty() ? boundary_a_ : records.back().a_last;
    const Vector& b0 = records.empty() ? boundary_b_ : records.back().b_last;
    records.push_back(Record(solved.solution, h_trial, false, solved, *remaining - e, a0, b0));
    y = y_next;
  }

  if (!violation.found) {
    for (SolveRecord& record : records) Commit(std::move(record));
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
  for (int attempt = 0; attempt <= options_.max_event_retries; ++attempt) {
    if (attempt > 0) ++result_.stats.num_event_retries;
    GroupSetup setup;
    setup.y_start = y_start;
    setup.a_zero = a_zero_;
    setup.elements = m;
    setup.with_event = true;
    setup.h_max = rest / m;
    setup.h_reference = h_trial;
    setup.indicator_weights = scales.cwiseInverse();
    setup.indicator_power = powers;
    group_.Configure(setup);
    // First attempt: the reduced switch group where the statuses leave a smooth field, checked
    // on the full group system (its Newton continues from there if it does not hold).
    Vector guess;
    int reduced_iterations = 0;
    long reduced_factorizations = 0;
    const int pair = violation.pair;
    const bool reduced =
        attempt == 0 && pair >= 0 &&
        ReducedSwitchGuess(trial_w, y_start, h_trial, e, m, h_guess, pair,
                           setup.indicator_weights[pair], powers[static_cast<std::size_t>(pair)],
                           &guess, &reduced_iterations, &reduced_factorizations);
    if (!reduced) guess = GroupGuess(trial_w, y_start, h_trial, m, h_guess, v_end.v);
    solved_by_ = reduced ? &reduced_newton_ : &newton_;
    SemismoothNewtonResult solved = (reduced ? reduced_newton_ : newton_).Solve(group_, guess);
    if (reduced) {
      if (solved.converged() && solved.stats.iterations == 0) {
        result_.stats.num_reduced_elements += m;
      }
      solved.stats.iterations += reduced_iterations;
      solved.stats.factorizations += reduced_factorizations;
    }
    CountNewton(solved);
    ++result_.stats.num_groups;
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
    }
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
    Commit(Record(w, h, switched, solved, *remaining, boundary_a_, boundary_b_));
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

// --- smooth elements ----------------------------------------------------------------------

void FesdRun::InitializeSmoothFields() {
  const Scene& scene = system_.scene();
  if (!options_.reduce_smooth_elements || filter_.enabled() || scene.effects.empty()) return;
  if (system_.time_freezing()) {
    // Relays only (their state derivative depends on z through theta alone); each relay's
    // theta unknowns found by name (docs/lowering.md: "<relay>.theta_<region>").
    for (const Effect& effect : scene.effects) {
      if (!std::holds_alternative<HysteresisRelay>(effect)) return;
    }
    const char* const regions[] = {"mode_A", "to_A", "to_B", "mode_B"};
    const std::vector<std::string>& names = system_.algebraic_names();
    std::vector<std::array<int, 4>> theta;
    for (const std::string& relay : system_.relay_names()) {
      std::array<int, 4> indices{};
      for (int k = 0; k < 4; ++k) {
        const auto found = std::find(names.begin(), names.end(), relay + ".theta_" + regions[k]);
        if (found == names.end()) return;
        indices[static_cast<std::size_t>(k)] = static_cast<int>(found - names.begin());
      }
      theta.push_back(indices);
    }
    // The pairs are (theta, lambda) of the regions, relay by relay (lower_hysteresis.cpp).
    if (np_ != 4 * static_cast<int>(theta.size())) return;
    relay_theta_ = std::move(theta);
    reduction_ = Reduction::kRelayModes;
    smooth_fields_.resize(1);  // the field of the lowered system itself, built on first use
    return;
  }
  if (ny_ != nx_ + 1) return;
  const auto* switching = std::get_if<SwitchingSurfaces>(&scene.effects.front());
  if (switching != nullptr) {
    // Stewart's form, one switching effect and nothing else: a field per mode.
    if (options_.switching_form != SwitchingForm::kStewart || !scene.dynamics.empty() ||
        scene.effects.size() != 1 || static_cast<int>(switching->modes.size()) != np_) {
      return;
    }
    reduction_ = Reduction::kStewartMode;
    smooth_fields_.resize(static_cast<std::size_t>(np_));  // built on first use
    return;
  }
  for (const Effect& effect : scene.effects) {
    if (!std::holds_alternative<MovingSet>(effect)) return;
  }
  reduction_ = Reduction::kFreeMovingSets;  // one field: the scene's dynamics
  smooth_fields_.resize(1);
}

int FesdRun::SmoothField(const std::vector<bool>& a_zero) const {
  switch (reduction_) {
    case Reduction::kNone:
      return -1;
    case Reduction::kStewartMode: {
      // Stewart's pair k: theta_k ⟂ lambda_k, b = lambda_k = 0 kept (a_zero false) iff mode k
      // is active; with one active mode, e^T theta = 1 and theta_j = 0 (j != k) give theta =
      // e_k, so x' = f_k(x) at every stage, and lambda, mu follow from the state (g - lambda -
      // mu e = 0).
      int mode = -1;
      for (int k = 0; k < np_; ++k) {
        if (a_zero[static_cast<std::size_t>(k)]) continue;
        if (mode >= 0) return -1;  // a sliding mode: theta is not a unit vector
        mode = k;
      }
      return mode;
    }
    case Reduction::kFreeMovingSets:
      // Moving-set pair k: c_k ⟂ lambda_k; with b = lambda_k = 0 kept (a_zero false) for every
      // constraint, x' = f(x) + P grad c lambda = f(x).
      for (int k = 0; k < np_; ++k) {
        if (a_zero[static_cast<std::size_t>(k)]) return -1;  // a constraint is active
      }
      return 0;
    case Reduction::kRelayModes:
      return RelayTheta(a_zero, nullptr) ? 0 : -1;
  }
  return -1;
}

bool FesdRun::RelayTheta(const std::vector<bool>& a_zero, Vector* z) const {
  for (std::size_t i = 0; i < relay_theta_.size(); ++i) {
    // Active regions of relay i (pair 4 i + k: b = lambda_k = 0 kept iff a_zero is false).
    std::array<bool, 4> active{};
    int count = 0;
    for (std::size_t k = 0; k < 4; ++k) {
      active[k] = !a_zero[4 * i + k];
      count += active[k] ? 1 : 0;
    }
    std::array<double, 4> theta{};
    if (count == 1) {
      for (std::size_t k = 0; k < 4; ++k) theta[k] = active[k] ? 1.0 : 0.0;
    } else if (count == 2 && ((active[0] && active[1]) || (active[2] && active[3]))) {
      for (std::size_t k = 0; k < 4; ++k) theta[k] = active[k] ? 0.5 : 0.0;
    } else {
      return false;
    }
    if (z == nullptr) continue;
    for (std::size_t k = 0; k < 4; ++k) (*z)[relay_theta_[i][k]] = theta[k];
  }
  return true;
}

internal::SmoothCollocationSolver* FesdRun::SmoothFieldSolver(const std::vector<bool>& a_zero) {
  const int index = SmoothField(a_zero);
  if (index < 0) return nullptr;
  FieldSolver& field = smooth_fields_[static_cast<std::size_t>(index)];
  if (reduction_ == Reduction::kRelayModes) {
    // The lowered system itself with theta held at its constant values (RelayTheta); the
    // other algebraic unknowns do not enter F.
    if (field.solver == nullptr) {
      field.solver = std::make_unique<internal::SmoothCollocationSolver>(
          &system_, s_, options_.newton.linear_solver);
    }
    relay_field_z_.setZero(nz_);
    RelayTheta(a_zero, &relay_field_z_);
    field.solver->SetFixedAlgebraic(relay_field_z_);
    return field.solver.get();
  }
  if (field.solver == nullptr) {
    // The scene without its effects, built member by member: copying it whole would clone
    // every effect's functions only to drop them (SmoothFunction copies are deep).
    const Scene& scene = system_.scene();
    Scene smooth;
    smooth.name = scene.name;
    smooth.state_names = scene.state_names;
    smooth.initial_state = scene.initial_state;
    smooth.initial_time = scene.initial_time;
    smooth.final_time = scene.final_time;
    smooth.parameters = scene.parameters;
    smooth.inputs = scene.inputs;
    smooth.time_scale_input = scene.time_scale_input;
    smooth.dynamics = reduction_ == Reduction::kStewartMode
                          ? std::get<SwitchingSurfaces>(scene.effects.front())
                                .modes[static_cast<std::size_t>(index)]
                          : scene.dynamics;
    field.system = std::make_unique<LoweredSystem>(smooth, Lowering(options_));
    if (field.system->num_states() != ny_ || field.system->num_algebraic() != 0) {
      reduction_ = Reduction::kNone;  // another layout: never reduce
      return nullptr;
    }
    field.solver = std::make_unique<internal::SmoothCollocationSolver>(
        field.system.get(), s_, options_.newton.linear_solver);
  }
  // The run may have changed parameters (FesdIntegrator) and inputs (control segments).
  field.system->SetParameters(system_.parameters());
  field.system->SetInputs(system_.inputs());
  return field.solver.get();
}

bool FesdRun::SmoothElementGuess(const Vector& y0, double h, const Vector* previous, Vector* w,
                                 int* iterations, long* factorizations) {
  internal::SmoothCollocationSolver* solver = SmoothFieldSolver(a_zero_);
  if (solver == nullptr) return false;
  const internal::CollocationStages& stages = group_.element(0);
  // Stage increments extrapolated as for the full element; algebraic values set below.
  *w = stages.InitialGuess(y0, h, previous, previous != nullptr ? h : 0.0, z_guess_,
                           /*algebraic=*/false);
  smooth_field_z_.resize(ny_, s_);
  for (int i = 0; i < s_; ++i) smooth_field_z_.col(i) = w->segment(stages.state_offset(i), ny_);
  internal::SmoothCollocationSolver::Stopping stopping;
  stopping.tolerance = options_.newton.tolerance;
  stopping.max_iterations = options_.newton.max_iterations;
  const long before = solver->num_factorizations();
  const auto outcome = solver->Solve(h, y0, stopping, &smooth_field_z_, iterations);
  *factorizations = solver->num_factorizations() - before;
  if (outcome != internal::SmoothCollocationSolver::Outcome::kConverged) return false;
  for (int i = 0; i < s_; ++i) {
    w->segment(stages.state_offset(i), ny_) = smooth_field_z_.col(i);
    stage_y_ = y0 + smooth_field_z_.col(i);
    w->segment(stages.algebraic_offset(i), nz_) = ConsistentGuess(stage_y_, z_guess_);
  }
  return true;
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
    const Vector yi = y0 + w_e.segment(stages.state_offset(i), ny_);
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
    if (keep_polynomials_) OnCommittedElement({y_, smooth_z_, Matrix(0, s_), h, {}, false});
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

bool FesdRun::ReducedSwitchGuess(const std::vector<Vector>& trial_w, const Vector& y_start,
                                 double h_trial, int element, int m, double h_guess, int pair,
                                 double weight, int power, Vector* w, int* iterations,
                                 long* factorizations) {
  // The scaled indicator is driven below this fraction of the Newton tolerance: the event row
  // (Fischer-Burmeister of a positive length slack and the indicator, about the indicator
  // itself there) then holds in the full check with margin, and the switch is located at least
  // as accurately as by the full group solve, which stops when its residual (the event row
  // included) is below the tolerance.
  constexpr double kIndicatorFraction = 0.1;
  // Indicator evaluations (each m Radau IIA steps of the field) before giving up.
  constexpr int kMaxEvaluations = 10;
  // Relays only. Elsewhere (one Stewart mode, free moving sets) the reduced group is as valid,
  // but the full group solve it replaces stops at its tolerance (F1, s = 2: the switch at pi
  // off by 2.8e-13, the reduced group's by 4e-16), so the fixed-step results would move by that
  // much (FesdTest.SmoothElementsAgreeWithTheFullSolve holds them to 1e-13 of the full solve).
  if (reduction_ != Reduction::kRelayModes) return false;
  internal::SmoothCollocationSolver* solver = SmoothFieldSolver(a_zero_);
  if (solver == nullptr || m > static_cast<int>(trial_w.size())) return false;
  const internal::CollocationStages& stages = group_.element(0);
  internal::SmoothCollocationSolver::Stopping stopping;
  stopping.tolerance = options_.newton.tolerance;
  stopping.max_iterations = options_.newton.max_iterations;
  const long factorizations_before = solver->num_factorizations();
  // Stage increments of the m elements, for the length z_h (first guess: the trial elements).
  std::vector<Matrix> z(static_cast<std::size_t>(m), Matrix(ny_, s_));
  for (int e = 0; e < m; ++e) {
    for (int i = 0; i < s_; ++i) {
      z[static_cast<std::size_t>(e)].col(i) =
          trial_w[static_cast<std::size_t>(e)].segment(stages.state_offset(i), ny_);
    }
  }
  double z_h = h_trial;
  Vector level = v(), solved_v, y_end;
  IndicatorEvaluation& indicator = indicators_;
  // A continuous free side is a function of the state (the velocity level does not enter it
  // for the blocks at hand, and where it would, the last iterate is checked with it below):
  // the iteration then evaluates it at v() without solving the velocity level.
  bool solve_level = FreeSideIsJump(pair);
  // Scaled indicator at the end state y_end (velocity level from `level`, which is updated).
  auto scaled_indicator = [&](double h) {
    if (solve_level) {
      if (!system_.SolveVelocityLevel(y_end, a_zero_, level, &solved_v)) {
        return std::numeric_limits<double>::quiet_NaN();
      }
      level = solved_v;
    }
    system_.EvaluateEventIndicators(y_end, level, a_zero_, Derivatives::kNone, &indicator);
    return weight * indicator.values[pair] / std::pow(h / h_trial, power);
  };
  // The m elements of length h from y_start (increments rescaled from z_h as a guess).
  // Increments for the length h from those for z_h: the collocation polynomial of each
  // element evaluated at the new stage times c_i h / z_h (a guess accurate to the change in h
  // times the element's local error, where rescaling the increments is accurate to first order
  // only; the secant steps change h by ever less).
  Matrix rescale(s_, s_);
  auto solve = [&](double h) {
    for (int i = 0; i < s_; ++i) {
      rescale.col(i) = tableau_.InterpolationWeights(tableau_.c[i] * h / z_h);
    }
    y_end = y_start;
    for (int e = 0; e < m; ++e) {
      Matrix& ze = z[static_cast<std::size_t>(e)];
      ze = ze * rescale;
      int its = 0;
      const auto outcome = solver->Solve(h, y_end, stopping, &ze, &its);
      *iterations += its;
      if (outcome != internal::SmoothCollocationSolver::Outcome::kConverged) {
        z_h = h;
        return std::numeric_limits<double>::quiet_NaN();
      }
      y_end += ze.col(s_ - 1);
    }
    z_h = h;
    return scaled_indicator(h);
  };
  *iterations = 0;
  // h_trial: the trial elements themselves (the same equations from the same start).
  y_end = y_start;
  for (int e = 0; e < m; ++e) y_end += z[static_cast<std::size_t>(e)].col(s_ - 1);
  double a = h_trial, fa = scaled_indicator(h_trial);
  double b = CrossingGuess(trial_w, y_start, h_trial, element, pair, m, h_guess), fb = solve(b);
  const double tolerance = kIndicatorFraction * options_.newton.tolerance;
  bool found = false;
  for (int evaluation = 1; evaluation <= kMaxEvaluations; ++evaluation) {
    if (!std::isfinite(fa) || !std::isfinite(fb)) break;
    if (std::fabs(fb) <= tolerance) {
      if (solve_level) {
        found = true;
        break;
      }
      // The root with the consistent velocity level at the end state (the group's v_end).
      solve_level = true;
      fb = scaled_indicator(b);
      continue;
    }
    if (fa == fb) break;
    const double c = b - fb * (b - a) / (fb - fa);
    if (!(c > 0.0 && c <= group_.setup().h_max)) break;
    const bool bracket = (fa < 0.0) != (fb < 0.0);
    const double fc = solve(c);
    if (bracket && (fc < 0.0) == (fb < 0.0)) {
      fa *= 0.5;  // Illinois: the retained end's value halved
    } else {
      a = b;
      fa = fb;
    }
    b = c;
    fb = fc;
  }
  *factorizations = solver->num_factorizations() - factorizations_before;
  if (!found) return false;
  if (z_h != b) solve(b);  // z holds the last evaluation's elements
  // The group's unknowns at h = b.
  w->setZero(group_.num_unknowns());
  Vector y0 = y_start;
  for (int e = 0; e < m; ++e) {
    const Matrix& ze = z[static_cast<std::size_t>(e)];
    auto unknowns = w->segment(group_.element_offset(e), group_.element_size());
    for (int i = 0; i < s_; ++i) {
      unknowns.segment(stages.state_offset(i), ny_) = ze.col(i);
      stage_y_ = y0 + ze.col(i);
      unknowns.segment(stages.algebraic_offset(i), nz_) = ConsistentGuess(stage_y_, z_guess_);
    }
    y0 += ze.col(s_ - 1);
  }
  w->segment(group_.v_offset(), nz_) = level;
  (*w)[group_.h_index()] = b;
  return true;
}

double FesdRun::CrossingGuess(const std::vector<Vector>& trial_w, const Vector& y_start,
                              double h_trial, int element, int pair, int m, double h_guess) {
  // Bisection steps on the interpolant (no system evaluations): 2^-40 of a gap.
  constexpr int kBisections = 40;
  if (FreeSideIsJump(pair) || element >= static_cast<int>(trial_w.size())) return h_guess;
  const internal::CollocationStages& stages = group_.element(0);
  const Vector& w = trial_w[static_cast<std::size_t>(element)];
  Vector y0 = y_start;
  for (int e = 0; e < element; ++e) {
    y0 += trial_w[static_cast<std::size_t>(e)].segment(stages.state_offset(s_ - 1), ny_);
  }
  std::vector<double> nodes = {0.0}, values;
  IndicatorEvaluation& at = indicators_;
  system_.EvaluateEventIndicators(y0, v(), a_zero_, Derivatives::kNone, &at);
  values.push_back(at.values[pair]);
  for (int i = 0; i < s_; ++i) {
    stage_y_ = y0 + w.segment(stages.state_offset(i), ny_);
    system_.EvaluateEventIndicators(stage_y_, v(), a_zero_, Derivatives::kNone, &at);
    nodes.push_back(tableau_.c[i]);
    values.push_back(at.values[pair]);
  }
  auto interpolant = [&](double theta) {
    double sum = 0.0;
    for (std::size_t j = 0; j < nodes.size(); ++j) {
      double basis = 1.0;
      for (std::size_t l = 0; l < nodes.size(); ++l) {
        if (l != j) basis *= (theta - nodes[l]) / (nodes[j] - nodes[l]);
      }
      sum += basis * values[j];
    }
    return sum;
  };
  for (std::size_t j = 1; j < nodes.size(); ++j) {
    if (!(values[j - 1] >= 0.0 && values[j] < 0.0)) continue;
    double low = nodes[j - 1], high = nodes[j];
    for (int k = 0; k < kBisections; ++k) {
      const double middle = 0.5 * (low + high);
      (interpolant(middle) >= 0.0 ? low : high) = middle;
    }
    const double h = (element + 0.5 * (low + high)) * h_trial / m;
    return h > 0.0 && h <= group_.setup().h_max ? h : h_guess;
  }
  return h_guess;
}

// Guess of a group of m elements of length h_guess from the trial elements.
Vector FesdRun::GroupGuess(const std::vector<Vector>& trial_w, const Vector& y_start,
                           double h_trial, int m, double h_guess, const Vector& v_end) {
  Vector w = Vector::Zero(group_.num_unknowns());
  const internal::CollocationStages& stages = group_.element(0);
  for (int e = 0; e < m; ++e) {
    Vector element;
    if (e < static_cast<int>(trial_w.size())) {
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

// True if pair k's free side (the side its status does not keep at zero) is a jump variable
// (an active constraint's multiplier, a sliding mode's theta or alpha). Stage values of those
// are order-s approximations of the consistent (velocity-level) values; they are never
// used for sign decisions.
bool FesdRun::FreeSideIsJump(int k) const {
  const ContinuousSide side = system_.pairs()[static_cast<std::size_t>(k)].continuous;
  if (side == ContinuousSide::kBoth) return false;  // index-1 pairs: both sides continuous
  const bool continuous_a = side == ContinuousSide::kA;
  return a_zero_[static_cast<std::size_t>(k)] == continuous_a;
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
    Vector solved;
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
