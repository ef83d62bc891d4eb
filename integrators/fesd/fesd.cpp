#include "moreau/integrators/fesd.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "../common/sensitivity_arguments.hpp"
#include "fesd_run.hpp"
#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/clock.hpp"
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
  RequireArgument(std::isfinite(step_size) && step_size >= 0.0,
                  "step size h must be positive and finite (or 0: error-controlled steps), got ",
                  step_size);
  RequireArgument(std::isfinite(initial_step_size) && initial_step_size >= 0.0,
                  "initial step h0 must be positive and finite (or 0: automatic), got ",
                  initial_step_size);
  RequireArgument(max_steps >= 1, "max_steps must be >= 1, got ", max_steps);
  RequireArgument(finite_elements >= 1, "finite elements per step must be >= 1, got ",
                  finite_elements);
  RequireArgument(std::isfinite(event_tolerance) && event_tolerance > 0.0,
                  "event tolerance must be positive, got ", event_tolerance);
  RequireArgument(min_element_fraction > 0.0 && min_element_fraction <= 0.5,
                  "min element fraction must be in (0, 0.5], got ", min_element_fraction);
  RequireArgument(max_event_retries >= 1, "max event retries must be >= 1, got ",
                  max_event_retries);
  RequireArgument(std::isfinite(relative_tolerance) && relative_tolerance > 0.0,
                  "relative tolerance rtol must be positive and finite, got ", relative_tolerance);
  RequireArgument(std::isfinite(absolute_tolerance) && absolute_tolerance >= 0.0,
                  "absolute tolerance atol must be positive and finite (or 0: rtol times each "
                  "state's scale), got ",
                  absolute_tolerance);
  RequireArgument(std::isfinite(min_step_size) && min_step_size > 0.0,
                  "min step size must be positive and finite, got ", min_step_size);
  RequireArgument(std::isfinite(max_step_size) && max_step_size >= 0.0 &&
                      (max_step_size == 0.0 || max_step_size >= min_step_size),
                  "max step size must be 0 (no bound) or at least min_step_size, got ",
                  max_step_size);
  RequireArgument(std::isfinite(output_step) && output_step >= 0.0,
                  "output step must be nonnegative and finite (0: none), got ", output_step);
  for (double t : output_times) {
    RequireArgument(std::isfinite(t), "output times must be finite, got ", t);
  }
  RequireArgument(step_sequence.empty() || !adaptive,
                  "step_sequence replays the steps of an adaptive run without error control; it "
                  "cannot be combined with adaptive");
  for (double h : step_sequence) {
    RequireArgument(std::isfinite(h) && h >= 0.0,
                    "step_sequence entries must be finite and >= 0 (0: to the segment end), got ",
                    h);
  }
  for (double t : stop_times) {
    RequireArgument(std::isfinite(t), "stop times (tstops) must be finite, got ", t);
  }
  RequireArgument(std::isfinite(filter_safety) && filter_safety >= 1.0,
                  "filter safety must be >= 1, got ", filter_safety);
  internal::ValidateSensitivityOptions(*this);
  RequireArgument(threads >= 0, "threads must be >= 0 (0: every hardware thread), got ", threads);
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
    case FesdStatus::kStepSizeTooSmall:
      return "step_size_too_small";
    case FesdStatus::kNonFinite:
      return "non_finite";
    case FesdStatus::kMaxStepsReached:
      return "max_steps_reached";
    case FesdStatus::kSensitivityFailure:
      return "sensitivity_failure";
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
  num_rejected_steps += other.num_rejected_steps;
  num_failed_steps += other.num_failed_steps;
  max_cross_complementarity = std::max(max_cross_complementarity, other.max_cross_complementarity);
  max_complementarity = std::max(max_complementarity, other.max_complementarity);
  min_element_length = std::min(min_element_length, other.min_element_length);
  frozen_time += other.frozen_time;
  num_filter_rechecks += other.num_filter_rechecks;
  max_working_pairs = std::max(max_working_pairs, other.max_working_pairs);
  num_reduced_elements += other.num_reduced_elements;
  num_inside_crossings += other.num_inside_crossings;
  num_unresolved_crossings += other.num_unresolved_crossings;
  num_bound_evaluations += other.num_bound_evaluations;
  if (other.error_estimate >= 0.0)
    error_estimate = std::max(error_estimate, 0.0) + other.error_estimate;
  num_unestimated_steps += other.num_unestimated_steps;
  adjoint_memory_bytes = std::max(adjoint_memory_bytes, other.adjoint_memory_bytes);
  adjoint_file_bytes = std::max(adjoint_file_bytes, other.adjoint_file_bytes);
  adjoint_cpu_seconds += other.adjoint_cpu_seconds;
  cpu_seconds += other.cpu_seconds;
  return *this;
}

std::string FesdStats::Summary() const {
  std::ostringstream s;
  s << num_steps << " steps";
  if (num_rejected_steps + num_failed_steps > 0) {
    s << " (" << num_rejected_steps << " rejected, " << num_failed_steps << " failed and retried)";
  }
  s << ", " << num_elements << " elements, " << num_switches << " switches, "
    << num_newton_iterations << " Newton iterations, max cross complementarity "
    << max_cross_complementarity;
  if (error_estimate >= 0.0) s << ", estimated error " << error_estimate;
  s << ", " << cpu_seconds << " s";
  return s.str();
}

namespace internal {
namespace {
// Characters reserved for a kept Newton result's failure message (the longest, a line search
// failure with its reason and residual, has about 110).
constexpr std::size_t kNewtonMessageCapacity = 256;
}  // namespace

FesdResult FesdRun::Run() {
  RunClock run_clock;
  system_.SetThreads(options_.threads);
  const double worker_seconds_start = system_.worker_cpu_seconds();
  // The system's worker threads (a lowered system may outlive a run) spent this run's share
  // since the start; it joins the run's CPU time.
  auto finish = [&] {
    run_clock.AddWorkerSeconds(system_.worker_cpu_seconds() - worker_seconds_start);
    return Finish(run_clock);
  };
  const Scene& scene = system_.scene();
  y_ = system_.InitialState();
  if (options_.initial_state.size() > 0) {
    RequireArgument(options_.initial_state.size() == ny_, "FESD initial lowered state needs ", ny_,
                    " entries (", nx_, " scene states, ", ny_ - nx_ - 1,
                    " relay memories, the clock), got ", options_.initial_state.size());
    RequireArgument(options_.initial_state.allFinite(),
                    "FESD initial lowered state must be finite");
    y_ = options_.initial_state;
  }
  tau_ = scene.initial_time;
  // With the near-active filter the system's unknowns change; trajectories keep every
  // declared one (zeros for constraints left out).
  const std::vector<std::string> algebraic_names =
      filter_.enabled() ? system_.declared_algebraic_names() : system_.algebraic_names();
  for (Trajectory* t : {&result_.trajectory, &result_.stage_trajectory}) {
    t->state_names = scene.state_names;
    t->algebraic_names = algebraic_names;
  }
  if (system_.time_freezing()) {
    result_.numerical_trajectory.state_names = system_.state_names();
    result_.numerical_trajectory.algebraic_names = algebraic_names;
    for (const std::string& name : system_.relay_names()) {
      RelaySignal signal;
      signal.relay = name;
      signal.initial_value = static_cast<int>(y_[RelayMemoryIndex(signal)]);
      result_.relays.push_back(signal);
    }
  }
  result_.stats.min_element_length = std::numeric_limits<double>::infinity();
  control_starts_ = SegmentEnds(scene.initial_time, scene.final_time, scene.ControlBreakpoints());
  control_starts_.pop_back();
  segment_ends_ = StretchEnds(scene.initial_time, scene.final_time, scene.ControlBreakpoints(),
                              options_.stop_times, &segment_control_);
  const bool error_control = options_.ErrorControlled();
  const bool replay = !options_.step_sequence.empty();
  // A fixed grid longer than max_steps is refused before any work (with a speed of time the
  // horizon is numerical time as well; with time-freezing the frozen steps come on top).
  if (!error_control && !replay) {
    RequireFixedStepsWithin(segment_ends_, options_.step_size, options_.max_steps);
  }
  if (options_.sensitivities) InitializeSensitivities();
  PrepareOutputTimes();
  // Storage first used deep in the run (the first crossing search that halves, the first
  // comparison element with the full system), sized now: the step loop allocates nothing.
  // (Every declared pair: with the near-active filter np_ changes with the working set.)
  inside_.search.Reserve(system_.num_declared_pairs());
  inside_.watched.reserve(static_cast<std::size_t>(system_.num_declared_pairs()));
  comparison_.setup.a_zero.reserve(static_cast<std::size_t>(np_));
  comparison_.setup.y_start.resize(ny_);
  // A comparison element's unknowns (one element, no event).
  comparison_.guess.resize(group_.element_size());
  comparison_.solved.solution.resize(group_.element_size());
  // The kept Newton results: a failed solve (routine for trial elements and comparisons)
  // writes its message in place, and a solve's history has at most max_iterations + 1 entries.
  for (SemismoothNewtonResult* kept : {&advance_.solved, &comparison_.solved}) {
    kept->message.reserve(kNewtonMessageCapacity);
    kept->residual_history.reserve(static_cast<std::size_t>(options_.newton.max_iterations) + 1);
  }
  estimating_ = !error_control && !replay && options_.estimate_error;
  if (error_control || estimating_) result_.stats.error_estimate = 0.0;
  keep_polynomials_ = error_control || dense_output_ || estimating_;
  check_jump_stages_ = error_control || replay;
  system_.ClearNonFinite();
  if ((options_.initial_state.size() > 0 || options_.project_initial_state) &&
      !ProjectInitialState()) {
    return finish();
  }
  scale_.Reset(y_);

  // The near-active filter's first working set (no statuses or multipliers yet).
  UpdateWorkingSet(options_.step_size > 0.0 ? options_.step_size
                                            : 1e-2 * (scene.final_time - scene.initial_time));
  // Statuses at the initial state: the slow solution if x0 lies on a switching surface or
  // on the boundary of a moving set.
  if (Decide(y_[system_.clock_index()], nullptr)) {
    z_guess_ = ConsistentGuess(y_, v());
    PointEvaluation initial;
    system_.Evaluate(y_, z_guess_, Derivatives::kNone, &initial);
    boundary_a_ = initial.A;
    boundary_b_ = initial.B;
    result_.trajectory.Append(scene.initial_time, y_.head(nx_), Vector(), 0.0);
    if (system_.time_freezing()) {
      result_.numerical_trajectory.Append(tau_, y_, TrajectoryAlgebraic(z_guess_), 0.0);
    }
    // With a speed of time the horizon is in numerical time: the fixed-grid loop.
    const bool clock_targets = system_.time_freezing() && scene.time_scale_input < 0;
    if (error_control || replay) {
      IntegrateAdaptive(clock_targets);
    } else if (clock_targets) {
      IntegrateTimeFreezing();
    } else {
      Integrate();
    }
  }
  return finish();
}

SemismoothNewtonOptions FesdRun::NewtonOptions(const FesdOptions& options) {
  SemismoothNewtonOptions newton = options.newton;
  // The transfers of full and directional sensitivities solve with the factorization at the
  // solution; the adjoint sweep refactorizes at its checkpoints instead.
  newton.factorize_at_solution = options.sensitivities || options.sensitivity_directions.size() > 0;
  return newton;
}

SemismoothNewtonOptions FesdRun::ReducedNewtonOptions(const FesdOptions& options) {
  SemismoothNewtonOptions newton = NewtonOptions(options);
  newton.min_iterations = 0;
  // The reduced solution usually holds: check it on values, derivatives only if Newton must
  // go on (or for sensitivities, factorize_at_solution). Whatever reads the stage data after
  // a solve sees which it has (CollocationStages::derivatives()).
  newton.defer_initial_jacobian = true;
  return newton;
}

LoweringOptions FesdRun::Lowering(const FesdOptions& options) {
  LoweringOptions lowering;
  lowering.switching_form = options.switching_form;
  // A given initial state may lie outside the moving sets: it is projected (Run).
  lowering.require_feasible_initial_state =
      options.initial_state.size() == 0 && !options.project_initial_state;
  lowering.storage = StorageForLinearSolver(options.newton.linear_solver);
  return lowering;
}

void FesdRun::Integrate() {
  const Scene& scene = system_.scene();
  const double nominal = options_.step_size / options_.finite_elements;
  for (std::size_t segment = 0; segment + 1 < segment_ends_.size() && !failed(); ++segment) {
    segment_ = segment_control_[segment];
    system_.SetInputs(scene.InputValues(segment_ends_[segment]));
    if (StartsControlSegment(segment) && !smooth_ && !DecideAtBreakpoint()) break;
    const std::vector<double> grid =
        FixedStepGrid(segment_ends_[segment], segment_ends_[segment + 1], options_.step_size);
    // Twice the nominal elements of the segment (switch groups add some): no regrowth per
    // element (doubling would reach that capacity anyway).
    result_.elements.reserve(result_.elements.size() +
                             2 * (grid.size() - 1) *
                                 static_cast<std::size_t>(options_.finite_elements));
    for (std::size_t index = 1; index < grid.size() && !failed(); ++index) {
      double step_end = grid[index];
      int remaining = options_.finite_elements;
      if (smooth_) {
        BeginFixedAdvance();
        AdvanceSmooth(step_end, remaining);
        EndFixedAdvance();
        ++result_.stats.num_steps;
        continue;
      }
      while (remaining > 0 && !failed()) {
        BeginFixedAdvance();
        const bool switched = Advance(step_end, &remaining);
        EndFixedAdvance();
        const double rest = step_end - tau_;
        // A remainder too short for an element (a switch just before the step end) joins
        // the next step, unless the step ends at a breakpoint or the final time.
        if (switched && rest < options_.min_element_fraction * nominal && index + 1 < grid.size()) {
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
void FesdRun::IntegrateTimeFreezing() {
  const Scene& scene = system_.scene();
  const int clock = system_.clock_index();
  for (std::size_t segment = 0; segment + 1 < segment_ends_.size() && !failed(); ++segment) {
    segment_ = segment_control_[segment];
    system_.SetInputs(scene.InputValues(segment_ends_[segment]));
    if (StartsControlSegment(segment) && !DecideAtBreakpoint()) break;
    const double target = segment_ends_[segment + 1];
    const double tolerance = kClockTolerance * std::max(1.0, std::fabs(target));
    // Twice the nominal elements of the segment in physical time (frozen steps and switch
    // groups add some; doubling would reach that capacity anyway; capped): little regrowth.
    const double nominal_steps =
        std::clamp(std::ceil((target - y_[clock]) / options_.step_size), 0.0, 1e6);
    result_.elements.reserve(result_.elements.size() +
                             2 * static_cast<std::size_t>(nominal_steps) *
                                 static_cast<std::size_t>(options_.finite_elements));
    while (!failed() && target - y_[clock] > tolerance) {
      double length = options_.step_size;
      if (!system_.TimeFrozen(a_zero_)) {
        const double rest = target - y_[clock];
        const double n = std::max(1.0, std::ceil(rest / options_.step_size - 1e-9));
        length = rest / n;
        if (options_.sensitivities) TrackClock(clock, n);
      } else if (options_.sensitivities) {
        TrackClock(clock, 0.0);
      }
      const double step_end = tau_ + length;
      int remaining = options_.finite_elements;
      while (remaining > 0 && !failed()) {
        BeginFixedAdvance();
        const bool switched = Advance(step_end, &remaining);
        EndFixedAdvance();
        if (switched) break;  // a switch: a new step from the clock
      }
      ++result_.stats.num_steps;
    }
  }
}

void FesdRun::BeginFixedAdvance() {
  system_.ClearNonFinite();
  if (!estimating_) return;
  estimate_from_ = result_.elements.size();
  estimate_tau_ = tau_;
  RecyclePolynomials(&piece_);
  capture_piece_ = true;
}

void FesdRun::EndFixedAdvance() {
  if (failed() || !estimating_) return;
  capture_piece_ = false;
  const double length = tau_ - estimate_tau_;
  if (piece_.empty() || !(length > 0.0)) return;
  const double horizon = system_.scene().final_time - system_.scene().initial_time;
  // The comparison solves must not change the run's state: they use the piece and group_
  // only (and the Newton counters, which count their work).
  const ErrorEstimate estimate = EstimateError(length / horizon, estimate_from_);
  if (std::isfinite(estimate.proposal)) {
    result_.stats.error_estimate +=
        options_.relative_tolerance * (length / horizon) * estimate.proposal;
  } else {
    ++result_.stats.num_unestimated_steps;
  }
  scale_.Update(y_);
}

FesdResult FesdRun::Finish(const RunClock& run_clock) {
  // The clock reaches tf up to round-off (collocation of t' = 1, or kClockTolerance with
  // time-freezing); a run that reached it ends exactly there.
  const Scene& scene = system_.scene();
  const int clock = system_.clock_index();
  const double tf = scene.final_time;
  if (!failed() && scene.time_scale_input < 0 &&
      std::fabs(y_[clock] - tf) <= kClockTolerance * std::max(1.0, std::fabs(tf))) {
    if (!result_.trajectory.t.empty() && result_.trajectory.t.back() == y_[clock]) {
      result_.trajectory.t.back() = tf;
    }
    Trajectory& numerical = result_.numerical_trajectory;  // (time-freezing: tau, clock last)
    if (!numerical.x.empty() && numerical.x.back()[clock] == y_[clock]) {
      numerical.x.back()[clock] = tf;
    }
    y_[clock] = tf;
  }
  if (estimating_ && result_.stats.num_unestimated_steps > 0) {
    result_.warnings.push_back("the error of " +
                               std::to_string(result_.stats.num_unestimated_steps) +
                               " fixed steps could not be estimated (a comparison solve did not "
                               "converge); error_estimate leaves them out");
  }
  if (estimating_) {
    const std::string warning =
        ErrorEstimateWarning(result_.stats.error_estimate, options_.relative_tolerance);
    if (!warning.empty()) result_.warnings.push_back(warning);
  }
  result_.final_time = y_[system_.clock_index()];
  result_.final_state = y_.head(nx_);
  result_.final_lowered_state = y_;
  result_.final_algebraic = TrajectoryAlgebraic(z_last_);
  // With dense output an output time at tf is the final point (the clock may differ from tf
  // by round-off).
  const bool final_output = dense_output_ && !result_.trajectory.t.empty() &&
                            std::fabs(result_.trajectory.t.back() - result_.final_time) <=
                                kClockTolerance * std::max(1.0, std::fabs(result_.final_time));
  if (!final_output &&
      (result_.trajectory.t.empty() || result_.trajectory.t.back() != result_.final_time)) {
    result_.trajectory.Append(result_.final_time, result_.final_state, TrajectoryAlgebraic(z_last_),
                              0.0);
  }
  if (options_.sensitivities) FinishSensitivities();
  if (result_.stats.num_unresolved_crossings > 0) {
    std::ostringstream warning;
    warning.precision(10);
    warning << result_.stats.num_unresolved_crossings
            << (result_.stats.num_unresolved_crossings == 1 ? " element" : " elements")
            << " (the first at t = " << first_unresolved_time_
            << ") where an event indicator may cross zero between the element's nodes (its bounds "
               "admit it, or a crossing found there could not be located) and the search could "
               "not resolve it: a switch may have been stepped over; bound the step (h_max, or a "
               "smaller h) or give its time as a breakpoint (tstops)";
    result_.warnings.push_back(warning.str());
  }
  if (result_.elements.empty()) result_.stats.min_element_length = 0.0;
  // Error-controlled runs reserved their results for kReservedSteps steps
  // (IntegrateAdaptive): a shorter run gives the rest back.
  result_.elements.shrink_to_fit();
  result_.step_sequence.shrink_to_fit();
  result_.stats.num_factorizations = factorizations_;
  result_.stats.cpu_seconds = run_clock.CpuSeconds();
  return std::move(result_);
}

void FesdRun::Fail(FesdStatus status, double t, const std::string& reason) {
  // A solve that met a non-finite model value failed because of it: name the function, its
  // output and the point (a runaway, not a solver failure).
  std::string cause = reason;
  const bool solve_failure = status == FesdStatus::kNewtonFailure ||
                             status == FesdStatus::kEventLocationFailure ||
                             status == FesdStatus::kStatusDecisionFailure;
  if (solve_failure && system_.non_finite_seen()) {
    const std::string named = system_.DescribeNonFinite(system_.non_finite_state());
    status = FesdStatus::kNonFinite;
    cause = (named.empty() ? std::string("the lowered system is not finite at a point of the step")
                           : named) +
            " (the step's solve failed there: " + reason + ")";
  }
  result_.status = status;
  std::ostringstream s;
  s.precision(17);
  s << ToString(status) << " at t = " << t << ": " << cause;
  result_.message = s.str();
}

}  // namespace internal

FesdResult SimulateFesd(const Scene& scene, const FesdOptions& options,
                        const ProgressCallback& progress) {
  options.Validate();
  RequireSupportedEffects(scene, "fesd");
  auto run = std::make_shared<internal::FesdRun>(scene, options, progress);
  FesdResult result = run->Run();
  if (options.keep_adjoint && result.status == FesdStatus::kSuccess) {
    result.adjoint = std::make_shared<FesdAdjoint>(run);
  }
  return result;
}

FesdIntegrator::FesdIntegrator(const Scene& scene, const FesdOptions& options) : options_(options) {
  options_.Validate();
  RequireSupportedEffects(scene, "fesd");
  LoweringOptions lowering;
  lowering.switching_form = options_.switching_form;
  lowering.require_feasible_initial_state = !options_.project_initial_state;
  lowering.storage = StorageForLinearSolver(options_.newton.linear_solver);
  system_ = std::make_shared<LoweredSystem>(scene, lowering);
}

FesdIntegrator::~FesdIntegrator() = default;

FesdResult FesdIntegrator::Simulate(const Scene& values, const ProgressCallback& progress) {
  // As SimulateFesd (x0 in the moving sets unless projected, finite values, ...).
  ValidateScene(values, options_.initial_state.size() == 0 && !options_.project_initial_state);
  system_->UpdateValues(values);
  auto run = std::make_shared<internal::FesdRun>(system_.get(), options_, progress);
  FesdResult result = run->Run();
  if (options_.keep_adjoint && result.status == FesdStatus::kSuccess) {
    run->ShareSystem(system_);
    result.adjoint = std::make_shared<FesdAdjoint>(run);
  }
  return result;
}

}  // namespace moreau