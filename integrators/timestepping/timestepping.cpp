#include "moreau/integrators/timestepping.hpp"

#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <sstream>

#include "../common/collocation.hpp"
#include "../common/constraint_filter.hpp"
#include "../common/crossing_search.hpp"
#include "../common/sensitivity_arguments.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "timestepping_tape.hpp"

namespace moreau {

SemismoothNewtonOptions TimeSteppingOptions::DefaultNewtonOptions() {
  SemismoothNewtonOptions newton;
  newton.tolerance = 1e-12;
  newton.min_iterations = 1;
  newton.max_iterations = 50;
  return newton;
}

void TimeSteppingOptions::Validate() const {
  RequireArgument(stages >= 1 && stages <= kMaxRadauStages, "stages must be in [1, ",
                  kMaxRadauStages, "], got ", stages);
  RequireArgument(std::isfinite(step_size) && step_size > 0.0,
                  "step size h must be positive and finite, got ", step_size);
  RequireArgument(std::isfinite(filter_safety) && filter_safety >= 1.0,
                  "filter safety must be >= 1, got ", filter_safety);
  for (double t : stop_times) {
    RequireArgument(std::isfinite(t), "stop times (tstops) must be finite, got ", t);
  }
  RequireArgument(max_steps >= 1, "max_steps must be >= 1, got ", max_steps);
  internal::ValidateSensitivityOptions(*this);
  RequireArgument(threads >= 0, "threads must be >= 0 (0: every hardware thread), got ", threads);
  newton.Validate();
}

std::string ToString(TimeSteppingStatus status) {
  return status == TimeSteppingStatus::kSuccess ? "success" : "newton_failure";
}

TimeSteppingStats& TimeSteppingStats::operator+=(const TimeSteppingStats& other) {
  num_steps += other.num_steps;
  num_newton_iterations += other.num_newton_iterations;
  num_inside_crossings += other.num_inside_crossings;
  adjoint_memory_bytes += other.adjoint_memory_bytes;
  adjoint_file_bytes += other.adjoint_file_bytes;
  adjoint_cpu_seconds += other.adjoint_cpu_seconds;
  num_factorizations += other.num_factorizations;
  num_backtracks += other.num_backtracks;
  max_complementarity_residual =
      std::max(max_complementarity_residual, other.max_complementarity_residual);
  max_newton_residual = std::max(max_newton_residual, other.max_newton_residual);
  num_filter_rechecks += other.num_filter_rechecks;
  max_working_pairs = std::max(max_working_pairs, other.max_working_pairs);
  cpu_seconds += other.cpu_seconds;
  return *this;
}

std::string TimeSteppingStats::Summary() const {
  std::ostringstream s;
  s << num_steps << " steps, " << num_newton_iterations << " Newton iterations, "
    << num_factorizations << " factorizations, max complementarity residual "
    << max_complementarity_residual << ", " << cpu_seconds << " s";
  return s.str();
}

namespace {

// One time step as a mixed complementarity system (see the header): collocation and
// algebraic rows are smooth equations, stage pairs are complementarity pairs.
class StepSystem final : public MixedComplementaritySystem {
 public:
  explicit StepSystem(internal::CollocationStages* stages) : stages_(stages) {}
  void Prepare(const Vector& y0, double h) {
    y0_ = y0;
    h_ = h;
  }
  // The lowered system's layout changed (near-active filter) and the stages were resized:
  // the values-only copy is rebuilt at its next use.
  void LayoutChanged() { value_stages_.reset(); }
  int num_unknowns() const override { return stages_->unknowns(); }
  int num_equations() const override { return stages_->equation_rows(); }
  int num_pairs() const override { return stages_->pair_rows(); }
  bool Evaluate(const Vector& w, bool with_jacobian, Vector* r, Vector* a, Vector* b) override {
    // Values-only evaluations go to a separate stage set so that the derivatives of the last
    // with-Jacobian point stay available to AssembleJacobian.
    internal::CollocationStages& target = with_jacobian ? *stages_ : ValueStages();
    target.Evaluate(y0_, w, with_jacobian ? Derivatives::kStates : Derivatives::kNone);
    r->resize(num_equations());
    a->resize(num_pairs());
    b->resize(num_pairs());
    target.Residual(h_, w, *r, *a, *b);
    return r->allFinite() && a->allFinite() && b->allFinite();
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    stages_->AddJacobian(h_, da, db, 0, num_equations(), 0, jacobian);
  }
  double EstimatedJacobianNonzeros() const override { return stages_->EstimatedJacobianNonzeros(); }
  void ResidualScale(const Vector&, Vector* scale) override {
    scale->setOnes(num_unknowns());
    const int ny = stages_->num_states(), ng = stages_->num_equations();
    for (int i = 0; i < stages_->stages(); ++i) {
      for (int k = 0; k < ny; ++k)
        scale->coeffRef(i * (ny + ng) + k) = 1.0 / (1.0 + std::fabs(y0_[k]));
    }
  }

 private:
  internal::CollocationStages& ValueStages() {
    if (!value_stages_) value_stages_ = std::make_unique<internal::CollocationStages>(*stages_);
    return *value_stages_;
  }
  internal::CollocationStages* stages_;
  std::unique_ptr<internal::CollocationStages> value_stages_;
  Vector y0_;
  double h_ = 0.0;
};

void AddNewtonStats(const SemismoothNewtonResult& solved, TimeSteppingStats* stats) {
  stats->num_newton_iterations += solved.stats.iterations;
  stats->num_factorizations += solved.stats.factorizations;
  stats->num_backtracks += solved.stats.backtracks;
}

// Continuation on the smoothed Fischer-Burmeister function: mu = 1e-1, 1e-2, ..., 1e-8, then
// the problem itself (mu = base.smoothing, 0 unless the step is smoothed) from the last
// iterate. Each stage warm-starts the next; a stage that does not converge still passes its
// iterate on.
SemismoothNewtonResult SolveBySmoothing(MixedComplementaritySystem* system, const Vector& guess,
                                        const SemismoothNewtonOptions& base,
                                        TimeSteppingStats* stats) {
  Vector w = guess;
  for (double mu : {1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8}) {
    if (mu <= base.smoothing) break;
    SemismoothNewtonOptions options = base;
    options.smoothing = mu;
    options.tolerance = std::max(base.tolerance, 1e-3 * mu);
    SemismoothNewton newton(options);
    const SemismoothNewtonResult stage = newton.Solve(*system, w);
    AddNewtonStats(stage, stats);
    if (stage.solution.allFinite()) w = stage.solution;
  }
  SemismoothNewton newton(base);
  SemismoothNewtonResult result = newton.Solve(*system, w);
  AddNewtonStats(result, stats);
  return result;
}

// Implicit function theorem on a converged step R(w; y0, u, p) = 0: dw = -R_w^{-1} (R_y0 dy0 +
// R_u du + R_p dp) with R_w the generalized Jacobian (pair rows weighted by the NCP function's
// derivatives at the solution, as in Newton; the smoothed Fischer-Burmeister function's if
// the step was solved smoothed, whose derivatives are classical). Returns d y_end / d(y0, p,
// u) (n_y rows) with y_end = y0 + Z_s, or false if R_w is singular.
bool StepTransfer(internal::CollocationStages* stages, const Vector& y0, const Vector& w, double h,
                  const SemismoothNewtonOptions& newton, Matrix* transfer) {
  const int ny = stages->num_states(), s = stages->stages();
  // One evaluation with every derivative gives the pair sides and all Jacobian blocks.
  stages->Evaluate(y0, w, Derivatives::kAll);
  Vector r(stages->equation_rows()), a(stages->pair_rows()), b(stages->pair_rows());
  stages->Residual(h, w, r, a, b);
  Vector da(a.size()), db(b.size());
  for (Eigen::Index k = 0; k < a.size(); ++k) {
    const NcpValue phi =
        newton.smoothing > 0.0 && newton.ncp_function == NcpFunctionKind::kFischerBurmeister
            ? SmoothedFischerBurmeister(a[k], b[k], newton.smoothing)
            : EvaluateNcp(newton.ncp_function, a[k], b[k]);
    da[k] = phi.da;
    db[k] = phi.db;
  }
  const int n = stages->unknowns();
  SystemMatrix jacobian;
  jacobian.Reset(n, false);
  stages->AddJacobian(h, da, db, 0, stages->equation_rows(), 0, &jacobian);
  SystemMatrix start;
  start.Reset(std::max(n, ny), false);
  stages->AddStartJacobian(h, da, db, 0, stages->equation_rows(), 0, &start);
  Matrix d_u, d_p;
  stages->ParameterJacobian(h, da, db, &d_u, &d_p);
  Matrix rhs(n, ny + d_p.cols() + d_u.cols());
  rhs << start.dense().topLeftCorner(n, ny), d_p, d_u;
  const Eigen::PartialPivLU<Matrix> lu(jacobian.dense());
  const Matrix dw = -lu.solve(rhs);
  if (!dw.allFinite()) return false;
  *transfer = dw.middleRows(stages->state_offset(s - 1), ny);
  transfer->leftCols(ny) += Matrix::Identity(ny, ny);
  return true;
}

// Free sides that time-stepping's stage complementarity checks against zero: crossings deeper
// than this (relative to 1 + |value at the step start|) count, as FESD's default event
// tolerance (FesdOptions::event_tolerance) counts them.
constexpr double kInsideCrossingTolerance = 1e-9;

// CrossesInsideStep's work storage, kept across the steps of a run (a step allocates nothing
// once the sizes are met).
struct InsideCheck {
  internal::PolynomialPath path;
  std::vector<char> watched;
  IndicatorEvaluation at;
  Vector thresholds, point, box_lower, box_upper, end;
  Matrix increments;
  internal::CrossingWorkspace search;
};

// True if a continuous free side of a pair whose status did not change over the step (from
// `before` at its start to `after` at its end) falls below zero between the step's nodes, or
// may (bounds that the search could not resolve): the crossing search of FESD
// (common/crossing_search.hpp) on the step's collocation polynomial from y with the stage
// increments of w. Jump free sides (multipliers) are not watched.
bool CrossesInsideStep(const LoweredSystem& system, const internal::CollocationStages& stages,
                       const RadauTableau& tableau, const Vector& y, const Vector& w,
                       const Vector& z, const std::vector<bool>& before,
                       const std::vector<bool>& after, InsideCheck* check) {
  const int np = system.num_pairs(), ny = system.num_states(), s = tableau.stages;
  std::vector<char>& watched = check->watched;
  watched.assign(static_cast<std::size_t>(np), 0);
  bool any = false;
  IndicatorEvaluation& at = check->at;
  system.EvaluateEventIndicators(y, z, before, Derivatives::kNone, &at);
  Vector& thresholds = check->thresholds;
  thresholds.resize(np);
  for (int k = 0; k < np; ++k) {
    const auto i = static_cast<std::size_t>(k);
    const ContinuousSide side = system.pairs()[i].continuous;
    // The free side under the status: b if a is kept at zero.
    const bool continuous =
        side == ContinuousSide::kBoth || before[i] == (side == ContinuousSide::kB);
    thresholds[k] = kInsideCrossingTolerance * (1.0 + std::fabs(at.values[k]));
    if (continuous && before[i] == after[i] && at.values[k] >= -thresholds[k]) {
      watched[i] = 1;
      any = true;
    }
  }
  if (!any) return false;
  Matrix& increments = check->increments;
  increments.resize(ny, s);
  for (int i = 0; i < s; ++i) increments.col(i) = w.segment(stages.state_offset(i), ny);
  internal::PolynomialPath* path = &check->path;
  path->SetCollocation(tableau, y, increments);
  auto values_at = [&](double theta, Vector* values) {
    path->Point(theta, &check->point);
    system.EvaluateEventIndicators(check->point, z, before, Derivatives::kNone, &at);
    *values = at.values;
    return values->allFinite();
  };
  auto bounds_over = [&](double a, double c, Vector* lower, Vector* upper) {
    path->Box(a, c, &check->box_lower, &check->box_upper);
    system.BoundEventIndicators(check->box_lower, check->box_upper, before, lower, upper);
  };
  const internal::CrossingFunctionRefs functions{values_at, bounds_over};
  // The end of the step must be above the thresholds too (else the status would have changed).
  Vector& end = check->end;
  if (!functions.values(1.0, &end)) return false;
  for (int k = 0; k < np; ++k) {
    if (!(end[k] >= -thresholds[k])) watched[static_cast<std::size_t>(k)] = 0;
  }
  return internal::SearchCrossing(watched, thresholds, functions, {}, &check->search).outcome !=
         internal::CrossingOutcome::kNone;
}

// The pair statuses at an evaluated point into *status (its storage reused).
void PairStatuses(const PointEvaluation& e, std::vector<bool>* status) {
  status->resize(static_cast<std::size_t>(e.A.size()));
  for (Eigen::Index k = 0; k < e.A.size(); ++k) {
    (*status)[static_cast<std::size_t>(k)] = PairStatusIsAZero(e.A[k], e.B[k]);
  }
}
std::vector<bool> PairStatuses(const PointEvaluation& e) {
  std::vector<bool> status;
  PairStatuses(e, &status);
  return status;
}

}  // namespace

TimeSteppingResult SimulateTimeStepping(const Scene& scene, const TimeSteppingOptions& options,
                                        const ProgressCallback& progress) {
  options.Validate();
  RequireSupportedEffects(scene, "timestepping");
  // A grid longer than max_steps is refused before any work.
  RequireFixedStepsWithin(
      SegmentEnds(scene.initial_time, scene.final_time, scene.ControlBreakpoints()),
      options.step_size, options.max_steps);
  RunClock run_clock;
  LoweringOptions lowering;
  lowering.switching_form = options.switching_form;
  lowering.require_feasible_initial_state = options.initial_state.size() == 0;
  lowering.storage = StorageForLinearSolver(options.newton.linear_solver);
  LoweredSystem system(scene, lowering);
  system.SetThreads(options.threads);
  internal::CollocationStages stages(&system, options.stages);
  StepSystem step_system(&stages);
  SemismoothNewton newton(options.newton);

  TimeSteppingResult result;
  TimeSteppingStats& stats = result.stats;
  const int nx = scene.num_states();
  const int s = options.stages;
  Vector y = system.InitialState();
  if (options.initial_state.size() > 0) {
    RequireArgument(options.initial_state.size() == y.size(),
                    "time-stepping initial lowered state needs ", y.size(),
                    " entries (states, then the clock), got ", options.initial_state.size());
    RequireArgument(options.initial_state.allFinite(),
                    "time-stepping initial lowered state has a NaN or infinite entry");
    y = options.initial_state;
  }
  const double clock_offset = y[system.clock_index()] - scene.initial_time;
  Vector z = system.InitialAlgebraicGuess(y);
  const int ny = static_cast<int>(y.size());
  const int np = system.num_parameters(), nu = system.num_inputs();
  internal::NearActiveFilter filter(&system, options.constraint_filter, options.filter_safety);
  // With the filter the system's unknowns change: trajectories keep every declared one.
  auto declared = [&](const Vector& values) {
    return filter.enabled() ? system.DeclaredAlgebraic(values) : values;
  };
  result.trajectory.state_names = scene.state_names;
  result.trajectory.algebraic_names =
      filter.enabled() ? system.declared_algebraic_names() : system.algebraic_names();
  result.trajectory.Append(scene.initial_time, y.head(nx), Vector(), 0.0);
  PointEvaluation initial;
  system.Evaluate(y, z, Derivatives::kNone, &initial);
  std::vector<bool> statuses = PairStatuses(initial);

  Vector previous_w;
  Vector guess, stage_state;  // kept across steps (no allocation per step)
  double previous_h = 0.0;
  std::vector<int> control;  // the control segment of every stretch
  // Sample times are stretch ends (stop times) so that a step ends at each.
  for (double t : options.sample_times) {
    RequireArgument(t > scene.initial_time && t <= scene.final_time, "sample time ", t,
                    " is outside (t0, tf] = (", scene.initial_time, ", ", scene.final_time, "]");
  }
  std::vector<double> stops = options.stop_times;
  stops.insert(stops.end(), options.sample_times.begin(), options.sample_times.end());
  const std::vector<double> ends = StretchEnds(scene.initial_time, scene.final_time,
                                               scene.ControlBreakpoints(), stops, &control);
  std::size_t next_sample = 0;
  std::vector<double> control_starts =
      SegmentEnds(scene.initial_time, scene.final_time, scene.ControlBreakpoints());
  control_starts.pop_back();
  bool failed = false;
  Matrix& sensitivity = result.sensitivities;
  const int segments = static_cast<int>(control_starts.size());
  const int n_theta = np + nu * segments;
  if (options.sensitivities) {
    sensitivity.setZero(ny, ny + np + nu * segments);
    sensitivity.leftCols(ny).setIdentity();
  }
  // Directional: d = dy/dtheta V (n_y x k) and the parameter directions; adjoint: the step
  // transfers (the tape), applied transposed after the run.
  const bool directional = options.sensitivity_directions.size() > 0;
  const bool adjoint = options.adjoint_weights.size() > 0 ||
                       options.adjoint_sample_weights.size() > 0 || options.keep_adjoint;
  Matrix directions, parameter_directions;
  std::shared_ptr<internal::TimeSteppingTape> tape;
  if (adjoint) {
    tape = std::make_shared<internal::TimeSteppingTape>();
    tape->nx = nx;
    tape->ny = ny;
    tape->np = np;
    tape->nu = nu;
    tape->segments = segments;
    tape->memory_limit = static_cast<std::size_t>(options.adjoint_memory_limit_mb * 1024 * 1024);
    // The weights' shapes are checked before any work (the sweep reads them after the run).
    if (options.adjoint_weights.size() > 0 || options.adjoint_sample_weights.size() > 0) {
      Matrix final_shaped, sample_shaped;
      internal::ShapedAdjointWeights(options.adjoint_weights, options.adjoint_sample_weights, nx,
                                     ny, static_cast<int>(options.sample_times.size()),
                                     &final_shaped, &sample_shaped);
    }
  }
  if (directional) {
    bool lowered = false;
    const Matrix v =
        internal::ShapedSensitivityArgument(options.sensitivity_directions, nx + n_theta,
                                            ny + n_theta, 1, "sensitivity directions", &lowered);
    directions.setZero(ny, v.cols());
    directions.topRows(lowered ? ny : nx) = v.topRows(lowered ? ny : nx);
    parameter_directions = v.bottomRows(n_theta);
  }
  const bool derivatives = options.sensitivities || directional || adjoint;
  if (derivatives) result.segment_starts = control_starts;
  Matrix transfer;
  const RadauTableau& tableau = RadauIIA(s);
  InsideCheck inside_check;
  // Sized for every declared pair: with the near-active filter the pairs of the step systems
  // grow and shrink with the working set, and a search in a larger one allocates nothing.
  inside_check.search.Reserve(system.num_declared_pairs());
  inside_check.watched.reserve(static_cast<std::size_t>(system.num_declared_pairs()));
  // The step's Newton result and its end statuses, kept across steps (their storage reused).
  SemismoothNewtonResult solved;
  std::vector<bool> now;
  double first_inside_crossing = 0.0;
  for (std::size_t segment = 0; segment + 1 < ends.size() && !failed; ++segment) {
    system.SetInputs(scene.InputValues(ends[segment]));
    previous_h = 0.0;  // no extrapolation across a control breakpoint
    const std::vector<double> grid =
        FixedStepGrid(ends[segment], ends[segment + 1], options.step_size);
    // One certificate per step: no regrowth in the step loop.
    result.step_complementarity_residual.reserve(result.step_complementarity_residual.size() +
                                                 grid.size() - 1);
    for (std::size_t k = 0; k + 1 < grid.size(); ++k) {
      const double h = grid[k + 1] - grid[k];
      // Near-active filter: the working set for this step; the state moves to its layout.
      LoweredSystem::WorkingLayout previous;
      if (filter.Update(y, statuses, z, h, &previous)) {
        z = system.RemapAlgebraic(z, previous, 0.0);
        statuses = system.RemapStatuses(statuses, previous, false);
        stages.Resize();
        step_system.LayoutChanged();
        previous_h = 0.0;  // the previous step's unknowns are in the old layout
      }
      stats.max_working_pairs =
          std::max(stats.max_working_pairs, static_cast<long>(system.num_pairs()));
      step_system.Prepare(y, h);
      // First attempt: state-informed guess (stages predicted across a switching surface
      // start in their new mode). Second attempt: the previous step's algebraic values at
      // every stage, if the first did not converge.
      stages.InitialGuess(y, h, previous_h > 0.0 ? &previous_w : nullptr, previous_h, z, &guess);
      newton.Solve(step_system, guess, &solved);
      AddNewtonStats(solved, &stats);
      if (!solved.converged()) {
        Vector retry = guess;
        for (int i = 0; i < s; ++i) retry.segment(stages.algebraic_offset(i), z.size()) = z;
        if (retry != guess) {
          newton.Solve(step_system, retry, &solved);
          AddNewtonStats(solved, &stats);
        }
      }
      // Third attempt: smoothing continuation, a b = mu^2 with mu -> 0, warm-started.
      if (!solved.converged() && system.num_pairs() > 0) {
        solved = SolveBySmoothing(&step_system, guess, options.newton, &stats);
      }
      if (!solved.converged()) {
        std::ostringstream message;
        message.precision(17);
        message << "newton_failure at t = " << grid[k] << " (step of length " << h
                << "): " << solved.message;
        result.status = TimeSteppingStatus::kNewtonFailure;
        result.message = message.str();
        failed = true;
        break;
      }
      const Vector& w = solved.solution;
      // Left-out constraints must stay positive at every stage; if one does not, it joins the
      // working set and the step is solved again.
      double left_out = std::numeric_limits<double>::infinity();
      bool positive = true;
      for (int i = 0; i < s; ++i) {
        double value = 0.0;
        stage_state = y + w.segment(stages.state_offset(i), ny);
        positive &= filter.Check(stage_state, &value);
        left_out = std::min(left_out, value);
      }
      if (!positive) {
        ++stats.num_filter_rechecks;
        --k;  // the same step again (k + 1 after the loop's increment; unsigned wrap at 0)
        continue;
      }
      filter.StepAccepted();
      if (derivatives) {
        if (!StepTransfer(&stages, y, w, h, options.newton, &transfer)) {
          std::ostringstream message;
          message.precision(17);
          message << "newton_failure at t = " << grid[k]
                  << ": singular step Jacobian, no sensitivities";
          result.status = TimeSteppingStatus::kNewtonFailure;
          result.message = message.str();
          failed = true;
          break;
        }
        const int column = ny + np + nu * control[segment];
        if (options.sensitivities) {
          sensitivity.leftCols(ny + np) = transfer.leftCols(ny) * sensitivity.leftCols(ny + np);
          sensitivity.middleCols(ny, np) += transfer.middleCols(ny, np);
          sensitivity.rightCols(sensitivity.cols() - ny - np) =
              transfer.leftCols(ny) * sensitivity.rightCols(sensitivity.cols() - ny - np);
          sensitivity.middleCols(column, nu) += transfer.rightCols(nu);
        }
        if (directional) {
          Matrix next = transfer.leftCols(ny) * directions;
          if (np > 0) next += transfer.middleCols(ny, np) * parameter_directions.topRows(np);
          if (nu > 0) {
            next += transfer.rightCols(nu) * parameter_directions.middleRows(column - ny, nu);
          }
          directions = std::move(next);
        }
        if (adjoint) tape->Add(control[segment], transfer);
      }
      PairStatuses(stages.stage(s - 1), &now);
      if (system.num_pairs() > 0 &&
          CrossesInsideStep(system, stages, tableau, y, w, z, statuses, now, &inside_check)) {
        if (stats.num_inside_crossings == 0) first_inside_crossing = grid[k];
        ++stats.num_inside_crossings;
      }
      y += w.segment(stages.state_offset(s - 1), ny);  // EndState: y0 + Z_s, in place
      // The clock on the exact grid (shifted with a given initial clock, which the
      // sensitivities differentiate).
      y[system.clock_index()] = grid[k + 1] + clock_offset;
      z = w.segment(stages.algebraic_offset(s - 1), system.num_algebraic());  // Algebraic(w, s - 1)
      previous_w = w;
      previous_h = h;
      ++stats.num_steps;
      stats.max_newton_residual = std::max(stats.max_newton_residual, solved.residual_norm);
      stats.max_complementarity_residual =
          std::max(stats.max_complementarity_residual, solved.complementarity_residual);
      // Constraints left out (lambda = 0) enter the certificate as |min(c, 0)|.
      const double certificate =
          std::max(solved.complementarity_residual, std::max(0.0, -left_out));
      stats.max_complementarity_residual =
          std::max(stats.max_complementarity_residual, certificate);
      result.step_complementarity_residual.push_back(certificate);
      // Events: pair statuses at the last stage against the previous step's.
      for (Event& event : system.StatusEvents(grid[k + 1], statuses, now)) {
        result.events.push_back(std::move(event));
      }
      statuses = now;
      if (options.record_trajectory) {
        result.trajectory.Append(grid[k + 1], y.head(nx), declared(z), h);
      }
      if (progress) progress(grid[k + 1]);
    }
    // A sample time ends this stretch exactly (StretchEnds keeps the given values).
    for (; !failed && next_sample < options.sample_times.size() &&
           options.sample_times[next_sample] == ends[segment + 1];
         ++next_sample) {
      result.sample_states.push_back(y);
      if (directional) result.sample_directional.push_back(directions.topRows(nx));
      if (adjoint) tape->sample_positions.push_back(tape->transfers.size());
    }
  }
  result.final_time = y[system.clock_index()];
  result.final_state = y.head(nx);
  result.final_lowered_state = y;
  result.final_algebraic = declared(z);
  if (directional && !failed) {
    result.directional_lowered = directions;
    result.directional = directions.topRows(nx);
  }
  if (adjoint && !failed) {
    stats.adjoint_memory_bytes = static_cast<double>(tape->bytes);
    stats.adjoint_file_bytes = static_cast<double>(tape->file_bytes);
    auto sweep = std::make_shared<const TimeSteppingAdjoint>(tape);
    if (options.adjoint_weights.size() > 0 || options.adjoint_sample_weights.size() > 0) {
      TimeSteppingGradient gradient =
          sweep->Sweep(options.adjoint_weights, options.adjoint_sample_weights);
      result.adjoint_lowered = std::move(gradient.lowered);
      result.adjoint = std::move(gradient.theta);
      stats.adjoint_cpu_seconds = gradient.cpu_seconds;
    }
    if (options.keep_adjoint) result.adjoint_sweep = std::move(sweep);
  }
  if (!options.record_trajectory || failed) {
    if (result.trajectory.t.back() != result.final_time) {
      result.trajectory.Append(result.final_time, result.final_state, declared(z), previous_h);
    }
  }
  if (stats.num_inside_crossings > 0) {
    std::ostringstream warning;
    warning.precision(10);
    warning << stats.num_inside_crossings << (stats.num_inside_crossings == 1 ? " step" : " steps")
            << " (the first from t = " << first_inside_crossing
            << ") in which a free side falls below zero between the nodes and rises again, or "
               "may: time-stepping does not resolve such a switch; use a smaller h there "
               "(tstops to place a step boundary) or the fesd integrator";
    result.warnings.push_back(warning.str());
  }
  run_clock.AddWorkerSeconds(system.worker_cpu_seconds());  // its own system's threads
  stats.cpu_seconds = run_clock.CpuSeconds();
  return result;
}

}  // namespace moreau
