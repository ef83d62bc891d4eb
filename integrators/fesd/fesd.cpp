#include "moreau/integrators/fesd.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>

#include "../common/smooth_collocation.hpp"
#include "group_system.hpp"
#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/projection.hpp"

namespace moreau {

SemismoothNewtonOptions FesdOptions::DefaultNewtonOptions() {
  SemismoothNewtonOptions newton;
  newton.tolerance = 1e-12;
  newton.min_iterations = 1;
  newton.max_iterations = 40;
  return newton;
}

void FesdOptions::Validate() const {
  RequireArgument(stages >= 1 && stages <= kMaxRadauStages, "stages must be in [1, ",
                  kMaxRadauStages, "], got ", stages);
  RequireArgument(std::isfinite(step_size) && step_size > 0.0,
                  "step size h must be positive and finite, got ", step_size);
  RequireArgument(finite_elements >= 1, "finite elements per step must be >= 1, got ",
                  finite_elements);
  RequireArgument(std::isfinite(event_tolerance) && event_tolerance > 0.0,
                  "event tolerance must be positive, got ", event_tolerance);
  RequireArgument(min_element_fraction > 0.0 && min_element_fraction <= 0.5,
                  "min element fraction must be in (0, 0.5], got ", min_element_fraction);
  RequireArgument(max_event_retries >= 1, "max event retries must be >= 1, got ",
                  max_event_retries);
  newton.Validate();
}

std::string ToString(FesdStatus status) {
  switch (status) {
    case FesdStatus::kSuccess:
      return "success";
    case FesdStatus::kNewtonFailure:
      return "newton_failure";
    case FesdStatus::kEventLocationFailure:
      return "event_location_failure";
    case FesdStatus::kStatusDecisionFailure:
      return "status_decision_failure";
  }
  return "?";
}

FesdStats& FesdStats::operator+=(const FesdStats& other) {
  num_steps += other.num_steps;
  num_elements += other.num_elements;
  num_groups += other.num_groups;
  num_switches += other.num_switches;
  num_newton_iterations += other.num_newton_iterations;
  num_factorizations += other.num_factorizations;
  num_event_retries += other.num_event_retries;
  max_cross_complementarity = std::max(max_cross_complementarity, other.max_cross_complementarity);
  max_complementarity = std::max(max_complementarity, other.max_complementarity);
  min_element_length = std::min(min_element_length, other.min_element_length);
  frozen_time += other.frozen_time;
  cpu_seconds += other.cpu_seconds;
  return *this;
}

std::string FesdStats::Summary() const {
  std::ostringstream s;
  s << num_steps << " steps, " << num_elements << " elements, " << num_switches << " switches, "
    << num_newton_iterations << " Newton iterations, max cross complementarity "
    << max_cross_complementarity << ", " << cpu_seconds << " s";
  return s.str();
}

namespace {

using internal::GroupSetup;
using internal::GroupSystem;

// Where a free side first turned negative in a solved element: the fraction of the element at
// which it crossed zero (linear interpolation between the last nonnegative sample and the first
// negative one).
struct Violation {
  bool found = false;
  int element = 0;
  double fraction = 1.0;
};

// The local transfer of one solved element or group: [dy_end; dtau_end] as a linear map of
// [dy_start; dtau_start] (state), of dp and of du (implicit function theorem).
struct Transfer {
  Matrix state;       // (n_y + 1) x (n_y + 1)
  Matrix parameters;  // (n_y + 1) x n_p
  Matrix inputs;      // (n_y + 1) x n_u
};

// Everything a solved element or group contributes to the result, captured while its stage
// data and Newton factorization are available; committed if the solution is kept.
struct SolveRecord {
  std::vector<FesdElement> elements;
  std::vector<Vector> ends;       // state y at every element end (with record_trajectory)
  std::vector<Vector> algebraic;  // last-stage algebraic values of every element (idem)
  Trajectory stage_points;        // every stage (with record_stages)
  Vector y_end;
  Vector z_last;
  Vector a_last, b_last;  // pair sides at the last stage (next boundary values)
  double length = 0.0;    // total integration time covered
  bool frozen = false;    // physical time frozen (a relay jumping): not in physical outputs
  Transfer transfer;
};

class FesdRun {
 public:
  FesdRun(const Scene& scene, const FesdOptions& options, const ProgressCallback& progress)
      : FesdRun(nullptr, scene, options, progress) {}
  // Runs on an existing lowered system (FesdIntegrator: lowered once, run many times).
  FesdRun(LoweredSystem* system, const FesdOptions& options, const ProgressCallback& progress)
      : FesdRun(system, system->scene(), options, progress) {}

 private:
  FesdRun(LoweredSystem* external, const Scene& scene, const FesdOptions& options,
          const ProgressCallback& progress)
      : options_(options),
        progress_(progress),
        owned_(external ? std::nullopt
                        : std::make_optional<LoweredSystem>(scene, Lowering(options))),
        system_(external ? *external : *owned_),
        group_(&system_, options.stages),
        newton_(NewtonOptions(options)),
        tableau_(RadauIIA(options.stages)),
        s_(options.stages),
        nx_(scene.num_states()),
        ny_(system_.num_states()),
        nz_(system_.num_algebraic()),
        np_(system_.num_pairs()) {
    if (nz_ == 0 && !options.sensitivities) {
      smooth_ = std::make_unique<internal::SmoothCollocationSolver>(&system_, options.stages,
                                                                    options.newton.linear_solver);
    }
  }

 public:
  FesdResult Run() {
    const auto start = std::chrono::steady_clock::now();
    const Scene& scene = system_.scene();
    y_ = system_.InitialState();
    if (options_.initial_state.size() > 0) {
      RequireArgument(options_.initial_state.size() == ny_, "FESD initial lowered state needs ",
                      ny_, " entries (", nx_, " scene states, ", ny_ - nx_ - 1,
                      " relay memories, the clock), got ", options_.initial_state.size());
      RequireArgument(options_.initial_state.allFinite(),
                      "FESD initial lowered state must be finite");
      y_ = options_.initial_state;
    }
    tau_ = scene.initial_time;
    for (Trajectory* t : {&result_.trajectory, &result_.stage_trajectory}) {
      t->state_names = scene.state_names;
      t->algebraic_names = system_.algebraic_names();
    }
    if (system_.time_freezing()) {
      result_.numerical_trajectory.state_names = system_.state_names();
      result_.numerical_trajectory.algebraic_names = system_.algebraic_names();
      for (const std::string& name : system_.relay_names()) {
        RelaySignal signal;
        signal.relay = name;
        signal.initial_value = static_cast<int>(y_[RelayMemoryIndex(signal)]);
        result_.relays.push_back(signal);
      }
    }
    result_.stats.min_element_length = std::numeric_limits<double>::infinity();
    segment_ends_ = SegmentEnds(scene.initial_time, scene.final_time, scene.ControlBreakpoints());
    if (options_.sensitivities) InitializeSensitivities();
    if (options_.initial_state.size() > 0 && !ProjectInitialState()) return Finish(start);

    // Statuses at the initial state: the slow solution if x0 lies on a switching surface or
    // on the boundary of a moving set.
    if (Decide(y_[system_.clock_index()], nullptr)) {
      z_guess_ = ConsistentGuess(y_, v_);
      PointEvaluation initial;
      system_.Evaluate(y_, z_guess_, Derivatives::kNone, &initial);
      boundary_a_ = initial.A;
      boundary_b_ = initial.B;
      result_.trajectory.Append(scene.initial_time, y_.head(nx_), Vector(), 0.0);
      if (system_.time_freezing()) result_.numerical_trajectory.Append(tau_, y_, z_guess_, 0.0);
      // With a speed of time the horizon is in numerical time: the fixed-grid loop.
      if (system_.time_freezing() && scene.time_scale_input < 0) {
        IntegrateTimeFreezing();
      } else {
        Integrate();
      }
    }
    return Finish(start);
  }

 private:
  static SemismoothNewtonOptions NewtonOptions(const FesdOptions& options) {
    SemismoothNewtonOptions newton = options.newton;
    newton.factorize_at_solution = options.sensitivities;
    return newton;
  }

  static LoweringOptions Lowering(const FesdOptions& options) {
    LoweringOptions lowering;
    lowering.switching_form = options.switching_form;
    // A given initial state may lie outside the moving sets: it is projected (Run).
    lowering.require_feasible_initial_state = options.initial_state.size() == 0;
    return lowering;
  }

  bool failed() const { return result_.status != FesdStatus::kSuccess; }

  void Integrate() {
    const Scene& scene = system_.scene();
    const double nominal = options_.step_size / options_.finite_elements;
    for (std::size_t segment = 0; segment + 1 < segment_ends_.size() && !failed(); ++segment) {
      segment_ = static_cast<int>(segment);
      system_.SetInputs(scene.InputValues(segment_ends_[segment]));
      const std::vector<double> grid =
          FixedStepGrid(segment_ends_[segment], segment_ends_[segment + 1], options_.step_size);
      for (std::size_t index = 1; index < grid.size() && !failed(); ++index) {
        double step_end = grid[index];
        int remaining = options_.finite_elements;
        if (smooth_) {
          AdvanceSmooth(step_end, remaining);
          ++result_.stats.num_steps;
          continue;
        }
        while (remaining > 0 && !failed()) {
          const bool switched = Advance(step_end, &remaining);
          const double rest = step_end - tau_;
          // A remainder too short for an element (a switch just before the step end) joins
          // the next step, unless the step ends at a breakpoint or the final time.
          if (switched && rest < options_.min_element_fraction * nominal &&
              index + 1 < grid.size()) {
            ++index;
            step_end = grid[index];
            remaining = options_.finite_elements;
          }
        }
        ++result_.stats.num_steps;
      }
    }
  }

  // Time-freezing (hysteresis relays): the integration variable is numerical time tau and the
  // clock runs at rate 1, or 0 while a relay jumps. A step that starts while physical time
  // runs has length (target - clock)/n, n = ceil((target - clock)/H), so that the clock lands
  // on the next control breakpoint (or tf) unless something switches; a step that starts
  // frozen has length H (the clock stands still). After a switch a new step starts from the
  // current clock. Sensitivities: row n_y of sensitivity_ tracks tau - step_end, whose
  // derivative at a step start is d(clock)/n (running) or 0 (frozen).
  void IntegrateTimeFreezing() {
    const Scene& scene = system_.scene();
    const int clock = system_.clock_index();
    for (std::size_t segment = 0; segment + 1 < segment_ends_.size() && !failed(); ++segment) {
      segment_ = static_cast<int>(segment);
      system_.SetInputs(scene.InputValues(segment_ends_[segment]));
      const double target = segment_ends_[segment + 1];
      const double tolerance = kClockTolerance * std::max(1.0, std::fabs(target));
      while (!failed() && target - y_[clock] > tolerance) {
        double length = options_.step_size;
        if (!system_.TimeFrozen(a_zero_)) {
          const double rest = target - y_[clock];
          const double n = std::max(1.0, std::ceil(rest / options_.step_size - 1e-9));
          length = rest / n;
          if (options_.sensitivities) sensitivity_.row(ny_) = sensitivity_.row(clock) / n;
        } else if (options_.sensitivities) {
          sensitivity_.row(ny_).setZero();
        }
        const double step_end = tau_ + length;
        int remaining = options_.finite_elements;
        while (remaining > 0 && !failed()) {
          if (Advance(step_end, &remaining)) break;  // a switch: a new step from the clock
        }
        ++result_.stats.num_steps;
      }
    }
  }

  // The clock counts as having reached a target within this relative distance (it lands on
  // it up to the Newton tolerance times the step length).
  static constexpr double kClockTolerance = 1e-11;

  FesdResult Finish(std::chrono::steady_clock::time_point start) {
    result_.final_time = y_[system_.clock_index()];
    result_.final_state = y_.head(nx_);
    result_.final_lowered_state = y_;
    result_.final_algebraic = z_last_;
    if (result_.trajectory.t.empty() || result_.trajectory.t.back() != result_.final_time) {
      result_.trajectory.Append(result_.final_time, result_.final_state, z_last_, 0.0);
    }
    if (options_.sensitivities) {
      const int np = system_.num_parameters();
      result_.sensitivities.initial_state = sensitivity_.topLeftCorner(nx_, nx_);
      result_.sensitivities.parameters = sensitivity_.block(0, ny_, nx_, np);
      result_.sensitivities.inputs =
          sensitivity_.topRightCorner(nx_, sensitivity_.cols() - ny_ - np);
      result_.sensitivities.lowered = sensitivity_.topRows(ny_);
      result_.sensitivities.segment_starts.assign(segment_ends_.begin(), segment_ends_.end() - 1);
    }
    if (result_.elements.empty()) result_.stats.min_element_length = 0.0;
    result_.stats.num_factorizations = factorizations_;
    result_.stats.cpu_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result_;
  }

  void Fail(FesdStatus status, double t, const std::string& reason) {
    result_.status = status;
    std::ostringstream s;
    s.precision(17);
    s << ToString(status) << " at t = " << t << ": " << reason;
    result_.message = s.str();
  }

  // Decides the statuses at y_ (the slow solution) and records the events against `previous`
  // (null at t0). Returns false, with the status set, if no continuation exists.
  bool Decide(double t, const std::vector<bool>* previous) {
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
      const std::vector<int> before = previous != nullptr ? system_.MemoryTargets(*previous)
                                                          : std::vector<int>(after.size(), -1);
      for (std::size_t i = 0; i < after.size(); ++i) {
        if (after[i] >= 0 && before[i] < 0) {
          result_.relays[i].jump_times.push_back(t);
          result_.relays[i].values.push_back(after[i]);
        }
      }
    }
    a_zero_ = decision.a_zero;
    v_ = decision.v;
    return true;
  }

  // A given initial state outside the moving sets jumps onto them (the sweeping process's
  // projection at t0); with sensitivities the transfer of the projection (implicit function
  // theorem on its complementarity system) starts the chain. Returns false on failure.
  bool ProjectInitialState() {
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
      // New rows x: dx/dx0 (x columns), dx/dclock (clock column), dx/dp, dx/du (segment 0).
      const int np = system_.num_parameters(), nu = system_.num_inputs();
      Matrix rows = Matrix::Zero(nx_, sensitivity_.cols());
      rows.leftCols(nx_) = projection.d_x0;
      rows.col(clock) = projection.d_t;
      rows.middleCols(ny_, np) = projection.d_p;
      rows.middleCols(ny_ + np, nu) = projection.d_u;
      sensitivity_.topRows(nx_) = rows;
    }
    return true;
  }

  // Index in y of a relay's memory state (relays follow the scene states in order).
  int RelayMemoryIndex(const RelaySignal& signal) const {
    const auto& names = system_.relay_names();
    const auto it = std::find(names.begin(), names.end(), signal.relay);
    return nx_ + static_cast<int>(it - names.begin());
  }

  // Algebraic guess at y: consistent values of the continuous variables from y, jump
  // variables (theta, alpha, multipliers) from the velocity-level values v.
  Vector ConsistentGuess(const Vector& y, const Vector& v) const {
    Vector z = system_.InitialAlgebraicGuess(y);
    for (int i = 0; i < nz_; ++i) {
      if (!system_.continuous_algebraic()[static_cast<std::size_t>(i)]) z[i] = v[i];
    }
    return z;
  }

  // Advances from tau_ towards step_end with `remaining` nominal elements: a trial pass of
  // fixed-length elements; if a free side turns negative, a group solve of equal elements that
  // ends on the switch. Returns true if a switch ended the advance.
  bool Advance(double step_end, int* remaining) {
    const double rest = step_end - tau_;
    const double h_trial = rest / *remaining;
    const Vector y_start = y_;
    // Indicator scales, and the pairs that start at zero (just switched): their indicators
    // are divided by tau^2 so that h -> 0 is not a root (zero-length elements are excluded).
    IndicatorEvaluation start;
    system_.EvaluateEventIndicators(y_start, v_, a_zero_, Derivatives::kNone, &start);
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
    Vector v_end = v_;
    Violation violation;
    std::string trial_failure;  // why the trial pass suspected a switch, if not by signs
    for (int e = 0; e < *remaining; ++e) {
      GroupSetup setup;
      setup.y_start = y;
      setup.a_zero = a_zero_;
      setup.h_fixed = h_trial;
      group_.Configure(setup);
      const Vector* previous = trial_w.empty() ? last_w_ptr() : &trial_w.back();
      const Vector guess = group_.element(0).InitialGuess(
          y, h_trial, previous, previous != nullptr ? h_trial : 0.0, z_guess_);
      const SemismoothNewtonResult solved = newton_.Solve(group_, guess);
      CountNewton(solved);
      if (!solved.converged()) {
        // A fixed-status element that does not converge: look for a switch inside it.
        trial_failure = "element " + std::to_string(e) +
                        " with the current statuses did not converge (" + ToString(solved.status) +
                        ": " + solved.message + "), so a switch was assumed";
        violation = {true, e, 0.5};
        break;
      }
      violation = StageViolation(group_.element(0), scales, e);
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
      for (const SolveRecord& record : records) Commit(record);
      last_w_ = trial_w.back();
      have_last_w_ = true;
      last_h_ = h_trial;
      *remaining = 0;
      tau_ = step_end;  // exact step end
      v_ = v_end;
      z_guess_ = z_last_;
      return DecideAtBoundary();
    }

    // A switch inside trial element `violation.element`: re-solve the first m elements as a
    // group of equal length ending on it (equilibration); if the switch is not confirmed the
    // group covers the rest of the step.
    const int e = violation.element;
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
      const Vector guess = GroupGuess(trial_w, y_start, h_trial, m, h_guess, v_end);
      const SemismoothNewtonResult solved = newton_.Solve(group_, guess);
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
      Vector v_inner = w.segment(group_.v_offset(), nz_);
      for (int k = 0; k < m && !inner.found; ++k) {
        inner = StageViolation(group_.element(k), scales, k);
        if (!inner.found && k + 1 < m) {
          inner =
              EndViolation(group_.element(k), group_.ElementStart(w, k + 1), scales, k, &v_inner);
        }
      }
      if (inner.found) {
        // An earlier switch inside the group: aim at it.
        const double offset = (inner.element + inner.fraction) * h;
        m = std::clamp(static_cast<int>(std::lround(offset / h_trial)), 1, e + 1);
        h_guess = offset / m;
        continue;
      }
      const bool switched = h < setup.h_max * (1.0 - 1e-12);
      Commit(Record(w, h, switched, solved, *remaining, boundary_a_, boundary_b_));
      last_w_ = w.segment(group_.element_offset(m - 1), group_.element_size());
      have_last_w_ = true;
      last_h_ = h;
      v_ = w.segment(group_.v_offset(), nz_);
      if (!switched) {
        *remaining = 0;
        tau_ = step_end;
        z_guess_ = z_last_;
        return DecideAtBoundary();
      }
      ++result_.stats.num_switches;
      *remaining = std::max(1, *remaining - m);
      const std::vector<bool> previous = a_zero_;
      if (!Decide(y_[system_.clock_index()], &previous)) return true;
      z_guess_ = ConsistentGuess(y_, v_);
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

  const Vector* last_w_ptr() const { return have_last_w_ ? &last_w_ : nullptr; }

  // A system without algebraic unknowns (no effects) and no sensitivities cannot switch: every
  // element is a plain Radau IIA step, solved by the same kernel as the smooth Radau IIA
  // integrator (stage increments extrapolated from the previous element's collocation
  // polynomial), and committed at once.
  void AdvanceSmooth(double step_end, int remaining) {
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
      if (options_.record_trajectory) {
        result_.trajectory.Append(y_[system_.clock_index()], y_.head(nx_), Vector(), h);
      }
      if (progress_) progress_(y_[system_.clock_index()]);
    }
    tau_ = step_end;
  }

  // Stage increments from the previous element's collocation polynomial (weights cached for
  // the step-length ratio).
  void ExtrapolatedIncrements(double h, Matrix* z) {
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

  // After a stretch without a switch: a free side that is zero at its end (a switch exactly
  // on a step boundary, or at the final time) is decided there.
  bool DecideAtBoundary() {
    if (np_ == 0) return false;
    IndicatorEvaluation end;
    system_.EvaluateEventIndicators(y_, v_, a_zero_, Derivatives::kNone, &end);
    Vector scaled(np_);
    for (int k = 0; k < np_; ++k)
      scaled[k] = end.values[k] / std::max(1.0, std::fabs(end.values[k]));
    Eigen::Index first = 0;
    if (scaled.minCoeff(&first) > options_.event_tolerance) return false;
    const std::vector<bool> previous = a_zero_;
    const Vector v_before = v_;
    if (!Decide(y_[system_.clock_index()], &previous)) return true;
    if (previous != a_zero_) {
      ++result_.stats.num_switches;
      z_guess_ = ConsistentGuess(y_, v_);
      have_last_w_ = false;
      if (options_.sensitivities) ApplySaltation(previous, v_before, static_cast<int>(first));
    }
    return false;
  }

  // A switch found exactly on a step boundary was not located by an event equation, so the
  // local transfers miss how its time moves with the data. The saltation matrix restores it:
  // with iota the indicator of pair k under the old statuses (its total derivative includes
  // the velocity-level values, v = v(y, p, u) from E(y, v, p, u) = 0), the switch time moves by
  // dtau_s = -(diota)/(diota/dtau), diota/dtau = iota_y F_-, and the state at the boundary by
  // (F_- - F_+) dtau_s, F_-/F_+ the fields before and after the switch.
  void ApplySaltation(const std::vector<bool>& before, const Vector& v_before, int k) {
    const int np = system_.num_parameters(), nu = system_.num_inputs();
    IndicatorEvaluation indicator;
    system_.EvaluateEventIndicators(y_, v_before, before, Derivatives::kAll, &indicator);
    VelocityLevelEvaluation velocity;
    system_.EvaluateVelocityLevel(y_, v_before, LoweredSystem::RolesFor(before), Derivatives::kAll,
                                  &velocity);
    Eigen::RowVectorXd g_y = indicator.d_y.row(k), g_p = indicator.d_p.row(k),
                       g_u = indicator.d_u.row(k);
    if (nz_ > 0 && indicator.d_v.row(k).lpNorm<Eigen::Infinity>() > 0.0) {
      const Eigen::PartialPivLU<Matrix> lu(velocity.equations_v.transpose());
      const Eigen::RowVectorXd weights =
          lu.solve(Vector(indicator.d_v.row(k).transpose())).transpose();
      g_y -= weights * velocity.equations_y;
      g_p -= weights * velocity.equations_p;
      g_u -= weights * velocity.equations_u;
    }
    PointEvaluation before_switch, after_switch;
    system_.Evaluate(y_, ConsistentGuess(y_, v_before), Derivatives::kNone, &before_switch);
    system_.Evaluate(y_, ConsistentGuess(y_, v_), Derivatives::kNone, &after_switch);
    const double rate = g_y.dot(before_switch.F);
    // A grazing switch (zero rate) has no derivative; leave the transfers as they are.
    if (std::fabs(rate) <= 1e-12 * (1.0 + g_y.norm() * before_switch.F.norm())) return;
    Eigen::RowVectorXd d_iota = g_y * sensitivity_.topRows(ny_);
    d_iota.segment(ny_, np) += g_p;
    d_iota.segment(ny_ + np + nu * segment_, nu) += g_u;
    sensitivity_.topRows(ny_) -= (before_switch.F - after_switch.F) * (d_iota / rate);
  }

  // Guess of a group of m elements of length h_guess from the trial elements.
  Vector GroupGuess(const std::vector<Vector>& trial_w, const Vector& y_start, double h_trial,
                    int m, double h_guess, const Vector& v_end) {
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
  bool FreeSideIsJump(int k) const {
    const bool continuous_a =
        system_.pairs()[static_cast<std::size_t>(k)].continuous == ContinuousSide::kA;
    return a_zero_[static_cast<std::size_t>(k)] == continuous_a;
  }

  // The first stage at which a continuous free side is negative beyond tolerance, with the
  // crossing fraction (jump free sides are checked at element ends, see EndViolation).
  Violation StageViolation(const internal::CollocationStages& stages, const Vector& scales,
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
            fraction = previous_c +
                       (tableau_.c[i] - previous_c) * previous_value / (previous_value - free);
          }
          fraction = std::clamp(fraction, 1e-3, 1.0);
          if (!first.found || fraction < first.fraction) first = {true, element, fraction};
          break;
        }
        previous_value = free;
        previous_c = tableau_.c[i];
      }
    }
    return first;
  }

  // Event indicators at the end state y of an element (velocity-level values solved from v,
  // which is updated): the first negative one beyond tolerance is a switch in the element.
  Violation EndViolation(const internal::CollocationStages& stages, const Vector& y,
                         const Vector& scales, int element, Vector* v) const {
    Violation violation;
    Vector solved;
    if (np_ == 0 || !system_.SolveVelocityLevel(y, a_zero_, *v, &solved)) return violation;
    *v = solved;
    IndicatorEvaluation end;
    system_.EvaluateEventIndicators(y, solved, a_zero_, Derivatives::kNone, &end);
    for (int k = 0; k < np_ && !violation.found; ++k) {
      if (end.values[k] < -options_.event_tolerance * scales[k]) {
        violation = {true, element,
                     FreeSideIsJump(k) ? 1.0 : EndCrossing(stages, k, end.values[k])};
      }
    }
    return violation;
  }

  // Crossing fraction of pair k between the second-to-last stage and a negative end value.
  double EndCrossing(const internal::CollocationStages& stages, int k, double end_value) const {
    if (s_ < 2) return 1.0;
    const bool a_zero = a_zero_[static_cast<std::size_t>(k)];
    const double before = a_zero ? stages.stage(s_ - 2).B[k] : stages.stage(s_ - 2).A[k];
    if (before <= end_value) return 1.0;
    const double c0 = tableau_.c[s_ - 2];
    return std::clamp(c0 + (1.0 - c0) * before / (before - end_value), 1e-3, 1.0);
  }

  void CountNewton(const SemismoothNewtonResult& solved) {
    result_.stats.num_newton_iterations += solved.stats.iterations;
    factorizations_ += solved.stats.factorizations;
  }

  // Captures the elements of the system just solved (group_ holds its stage data and Newton
  // its factorization). a0, b0: pair sides at the last stage before it (boundary values).
  // `remaining` is the element count that fixed the lengths (h = rest / remaining).
  SolveRecord Record(const Vector& w, double h, bool ends_at_switch,
                     const SemismoothNewtonResult& solved, int remaining, const Vector& a0,
                     const Vector& b0) {
    const GroupSetup& setup = group_.setup();
    const int m = setup.elements;
    SolveRecord record;
    record.frozen = system_.TimeFrozen(a_zero_);
    if (options_.sensitivities) record.transfer = LocalTransfer(w, m, remaining);
    Vector y0 = setup.y_start;
    Vector a_previous = a0, b_previous = b0;
    for (int e = 0; e < m; ++e) {
      const internal::CollocationStages& stages = group_.element(e);
      const auto w_e = w.segment(group_.element_offset(e), group_.element_size());
      FesdElement element;
      element.length = h;
      element.physical_start = y0[system_.clock_index()];
      element.frozen = record.frozen;
      element.ends_at_switch = ends_at_switch && e + 1 == m;
      element.newton_iterations = static_cast<int>(solved.stats.iterations);
      element.newton_residual = solved.residual_norm;
      Certificates(stages, y0, w_e, a_previous, b_previous, &element);
      record.elements.push_back(element);
      if (options_.record_stages && !record.frozen) {
        for (int i = 0; i < s_; ++i) {
          const Vector yi = y0 + w_e.segment(stages.state_offset(i), ny_);
          record.stage_points.Append(yi[system_.clock_index()], yi.head(nx_),
                                     stages.Algebraic(w_e, i), h);
        }
      }
      y0 = stages.EndState(y0, w_e);
      a_previous = stages.stage(s_ - 1).A;
      b_previous = stages.stage(s_ - 1).B;
      record.z_last = stages.Algebraic(w_e, s_ - 1);
      if (options_.record_trajectory && e + 1 < m) {
        record.ends.push_back(y0);
        record.algebraic.push_back(record.z_last);
      }
      record.length += h;
    }
    record.y_end = y0;
    record.a_last = a_previous;
    record.b_last = b_previous;
    return record;
  }

  void Commit(const SolveRecord& record) {
    for (std::size_t e = 0; e < record.elements.size(); ++e) {
      FesdElement element = record.elements[e];
      element.t_start = tau_;
      tau_ += element.length;
      if (record.frozen) result_.stats.frozen_time += element.length;
      result_.elements.push_back(element);
      result_.stats.max_cross_complementarity =
          std::max(result_.stats.max_cross_complementarity, element.cross_complementarity);
      result_.stats.max_complementarity =
          std::max(result_.stats.max_complementarity, element.complementarity);
      result_.stats.min_element_length = std::min(result_.stats.min_element_length, element.length);
      ++result_.stats.num_elements;
      if (options_.record_trajectory) {
        // Interior ends of a group were stored; the last end is the record's y_end. Frozen
        // elements leave the physical trajectory (x and the clock do not move).
        const bool last = e + 1 == record.elements.size();
        const Vector& y = last ? record.y_end : record.ends[e];
        const Vector& z = last ? record.z_last : record.algebraic[e];
        if (!record.frozen) {
          result_.trajectory.Append(y[system_.clock_index()], y.head(nx_), z, element.length);
        }
        if (system_.time_freezing()) {
          result_.numerical_trajectory.Append(tau_, y, z, element.length);
        }
      }
    }
    for (std::size_t i = 0; i < record.stage_points.size(); ++i) {
      result_.stage_trajectory.Append(record.stage_points.t[i], record.stage_points.x[i],
                                      record.stage_points.algebraic[i],
                                      record.stage_points.step[i]);
    }
    y_ = record.y_end;
    z_last_ = record.z_last;
    boundary_a_ = record.a_last;
    boundary_b_ = record.b_last;
    if (options_.sensitivities) ApplyTransfer(record.transfer);
    if (progress_) progress_(y_[system_.clock_index()]);
  }

  // Free side of every pair at a stage state: continuous sides from the stage values, jump
  // sides consistent with the stage state (velocity level), see FreeSideIsJump.
  Vector ConsistentFreeSides(const Vector& y, const PointEvaluation& stage, const Vector& z) const {
    Vector free(np_);
    bool jump = false;
    for (int k = 0; k < np_; ++k) {
      free[k] = a_zero_[static_cast<std::size_t>(k)] ? stage.B[k] : stage.A[k];
      jump |= FreeSideIsJump(k);
    }
    if (!jump) return free;
    Vector v;
    if (!system_.SolveVelocityLevel(y, a_zero_, z, &v)) {
      free.setConstant(-std::numeric_limits<double>::infinity());  // no consistent value
      return free;
    }
    IndicatorEvaluation indicators;
    system_.EvaluateEventIndicators(y, v, a_zero_, Derivatives::kNone, &indicators);
    for (int k = 0; k < np_; ++k) {
      if (FreeSideIsJump(k)) free[k] = indicators.values[k];
    }
    return free;
  }

  // Certificates of an element (see FesdElement): the enforced side of every pair at the
  // stages and at the start boundary (its continuous side) against the consistent free sides.
  void Certificates(const internal::CollocationStages& stages, const Vector& y0,
                    const ConstVectorRef& w_e, const Vector& a0, const Vector& b0,
                    FesdElement* element) const {
    double cross = 0.0, stage_residual = 0.0;
    std::vector<Vector> free(static_cast<std::size_t>(s_));
    for (int i = 0; i < s_; ++i) {
      const Vector yi = y0 + w_e.segment(stages.state_offset(i), ny_);
      free[static_cast<std::size_t>(i)] =
          ConsistentFreeSides(yi, stages.stage(i), stages.Algebraic(w_e, i));
    }
    for (int k = 0; k < np_; ++k) {
      const bool a_zero = a_zero_[static_cast<std::size_t>(k)];
      const bool continuous_a =
          system_.pairs()[static_cast<std::size_t>(k)].continuous == ContinuousSide::kA;
      const double boundary = continuous_a ? a0[k] : b0[k];
      for (int j = 0; j < s_; ++j) {
        const PointEvaluation& sj = stages.stage(j);
        const double free_j = free[static_cast<std::size_t>(j)][k];
        const double enforced_j = a_zero ? sj.A[k] : sj.B[k];
        stage_residual = std::max(stage_residual, ComplementarityResidual(enforced_j, free_j));
        // The jump side at stage j: enforced (zero) or free (consistent value).
        const double jump_j = FreeSideIsJump(k) ? free_j : enforced_j;
        cross = std::max(cross, ComplementarityResidual(boundary, jump_j));
        for (int i = 0; i < s_; ++i) {
          const double enforced_i = a_zero ? stages.stage(i).A[k] : stages.stage(i).B[k];
          cross = std::max(cross, ComplementarityResidual(enforced_i, free_j));
        }
      }
    }
    element->cross_complementarity = cross;
    element->complementarity = stage_residual;
  }

  // --- sensitivities ------------------------------------------------------------------------
  void InitializeSensitivities() {
    RequireArgument(!system_.scene().dynamics.has_sparse_state_jacobian(),
                    "FESD sensitivities need dense Jacobians (hand-written sparse dynamics are "
                    "not supported)");
    const int np = system_.num_parameters();
    const int nu = system_.num_inputs();
    const int segments = static_cast<int>(segment_ends_.size()) - 1;
    // Rows: y (n_y) and tau; columns: y0 (the lowered initial state), p, u of every segment.
    sensitivity_.setZero(ny_ + 1, ny_ + np + nu * segments);
    sensitivity_.topLeftCorner(ny_, ny_).setIdentity();
  }

  // Implicit function theorem on the converged system R(w; y_start, tau_start, p, u) = 0:
  // dw = -R_w^{-1} (R_y dy_start + R_tau dtau_start + R_p dp + R_u du), with R_w the generalized
  // Jacobian that Newton factorized at the solution. The element lengths depend on tau_start
  // through h = rest / count (fixed elements), h_max = rest / m and h_ref = rest / remaining.
  Transfer LocalTransfer(const Vector& w, int group_elements, int remaining) {
    const GroupSetup& setup = group_.setup();
    group_.EvaluateForSensitivities(w);
    double event_da = 0.0, event_db = 0.0;
    if (setup.with_event) {
      const NcpValue phi =
          FischerBurmeister((setup.h_max - group_.H(w)) / setup.h_max, group_.event_indicator());
      event_da = phi.da;
      event_db = phi.db;
    }
    GroupSystem::ParameterBlocks blocks;
    group_.SensitivityBlocks(w, event_da, event_db, &blocks);
    const int np = system_.num_parameters(), nu = system_.num_inputs();
    const Vector d_tau =
        setup.with_event ? Vector(-blocks.h_max / group_elements - blocks.h_reference / remaining)
                         : Vector(-blocks.h_fixed / remaining);
    Matrix rhs(blocks.y_start.rows(), ny_ + 1 + np + nu);
    rhs << blocks.y_start, d_tau, blocks.p, blocks.u;
    const LinearSolver* solver = newton_.last_jacobian_solver();
    MOREAU_ASSERT(solver != nullptr, "no factorized Jacobian for sensitivities");
    solver->SolveMatrix(rhs);
    const Matrix dw = -rhs;
    // y_end = y_start + sum_e Z_{e,s};  tau_end = tau_start + m h (h fixed: rest / remaining).
    Matrix local = Matrix::Zero(ny_ + 1, ny_ + 1 + np + nu);
    local.topLeftCorner(ny_, ny_).setIdentity();
    const int last = (s_ - 1) * (ny_ + nz_);
    for (int e = 0; e < setup.elements; ++e) {
      local.topRows(ny_) += dw.middleRows(group_.element_offset(e) + last, ny_);
    }
    local(ny_, ny_) = 1.0;
    if (setup.with_event) {
      local.row(ny_) += setup.elements * dw.row(group_.h_index());
    } else {
      local(ny_, ny_) -= 1.0 / remaining;
    }
    Transfer transfer;
    transfer.state = local.leftCols(ny_ + 1);
    transfer.parameters = local.middleCols(ny_ + 1, np);
    transfer.inputs = local.rightCols(nu);
    return transfer;
  }

  void ApplyTransfer(const Transfer& transfer) {
    const int np = system_.num_parameters(), nu = system_.num_inputs();
    sensitivity_ = transfer.state * sensitivity_;
    sensitivity_.middleCols(ny_, np) += transfer.parameters;
    sensitivity_.middleCols(ny_ + np + nu * segment_, nu) += transfer.inputs;
  }

  FesdOptions options_;
  ProgressCallback progress_;
  std::optional<LoweredSystem> owned_;  // empty when running on an external system
  LoweredSystem& system_;
  GroupSystem group_;
  SemismoothNewton newton_;
  const RadauTableau& tableau_;
  int s_, nx_, ny_, nz_, np_;
  FesdResult result_;
  Vector y_;
  double tau_ = 0.0;
  std::vector<bool> a_zero_;
  Vector v_;
  Vector z_guess_;  // algebraic guess for the next element
  Vector z_last_;
  Vector boundary_a_, boundary_b_;  // pair sides at the last stage of the previous element
  Vector last_w_;                   // last committed element (for extrapolated guesses)
  bool have_last_w_ = false;
  double last_h_ = 0.0;
  std::vector<double> segment_ends_;
  int segment_ = 0;
  long factorizations_ = 0;
  Matrix sensitivity_;                                         // d(y, tau) / d(x0, p, u)
  std::unique_ptr<internal::SmoothCollocationSolver> smooth_;  // elements without pairs
  Matrix smooth_z_, last_z_matrix_, extrapolation_;
  double extrapolation_ratio_ = -1.0;
};

}  // namespace

FesdResult SimulateFesd(const Scene& scene, const FesdOptions& options,
                        const ProgressCallback& progress) {
  options.Validate();
  RequireSupportedEffects(scene, "fesd");
  FesdRun run(scene, options, progress);
  return run.Run();
}

FesdIntegrator::FesdIntegrator(const Scene& scene, const FesdOptions& options) : options_(options) {
  options_.Validate();
  RequireSupportedEffects(scene, "fesd");
  LoweringOptions lowering;
  lowering.switching_form = options_.switching_form;
  system_ = std::make_unique<LoweredSystem>(scene, lowering);
}

FesdIntegrator::~FesdIntegrator() = default;

FesdResult FesdIntegrator::Simulate(const Scene& values, const ProgressCallback& progress) {
  ValidateScene(values);  // as SimulateFesd (x0 in the moving sets, finite values, ...)
  system_->UpdateValues(values);
  FesdRun run(system_.get(), options_, progress);
  return run.Run();
}

}  // namespace moreau
