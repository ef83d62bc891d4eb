#include "moreau/integrators/radau.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "../common/smooth_collocation.hpp"
#include "../common/step_size.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/radau_tableau.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/lowered_system.hpp"

namespace moreau {

void RadauOptions::Validate() const {
  RequireArgument(stages >= 1 && stages <= kMaxRadauStages, "Radau stages must be in [1, ",
                  kMaxRadauStages, "], got ", stages);
  RequireArgument(std::isfinite(step_size) && step_size >= 0.0,
                  "step size h must be positive and finite (or 0: error-controlled steps), got ",
                  step_size);
  RequireArgument(std::isfinite(initial_step_size) && initial_step_size >= 0.0,
                  "initial step h0 must be positive and finite (or 0: automatic), got ",
                  initial_step_size);
  RequireArgument(std::isfinite(relative_tolerance) && relative_tolerance > 0.0,
                  "relative tolerance must be positive, got ", relative_tolerance);
  RequireArgument(std::isfinite(absolute_tolerance) && absolute_tolerance >= 0.0,
                  "absolute tolerance must be positive (or 0: rtol times each state's scale), got ",
                  absolute_tolerance);
  RequireArgument(min_step_size > 0.0 && max_step_size >= min_step_size,
                  "step-size bounds need 0 < min_step_size <= max_step_size, got ", min_step_size,
                  " and ", max_step_size);
  RequireArgument(std::isfinite(newton_tolerance) && newton_tolerance > 0.0,
                  "Newton tolerance must be positive, got ", newton_tolerance);
  RequireArgument(max_newton_iterations >= 1, "max Newton iterations must be >= 1, got ",
                  max_newton_iterations);
  RequireArgument(max_steps >= 1, "max steps must be >= 1, got ", max_steps);
  for (double t : stop_times) {
    RequireArgument(std::isfinite(t), "stop times (tstops) must be finite, got ", t);
  }
}

std::string ToString(RadauStatus status) {
  switch (status) {
    case RadauStatus::kSuccess:
      return "success";
    case RadauStatus::kNewtonFailure:
      return "newton_failure";
    case RadauStatus::kStepSizeTooSmall:
      return "step_size_too_small";
    case RadauStatus::kMaxStepsReached:
      return "max_steps_reached";
    case RadauStatus::kNonFinite:
      return "non_finite";
  }
  return "?";
}

RadauStats& RadauStats::operator+=(const RadauStats& other) {
  num_steps += other.num_steps;
  num_rejected_steps += other.num_rejected_steps;
  num_newton_iterations += other.num_newton_iterations;
  num_factorizations += other.num_factorizations;
  num_function_evaluations += other.num_function_evaluations;
  num_jacobian_evaluations += other.num_jacobian_evaluations;
  if (other.error_estimate >= 0.0)
    error_estimate = std::max(error_estimate, 0.0) + other.error_estimate;
  cpu_seconds += other.cpu_seconds;
  return *this;
}

std::string RadauStats::Summary() const {
  std::ostringstream s;
  s << num_steps << " steps (" << num_rejected_steps << " rejected), " << num_newton_iterations
    << " Newton iterations, " << num_factorizations << " factorizations, "
    << num_function_evaluations << " F evaluations";
  if (error_estimate >= 0.0) s << ", estimated error " << error_estimate;
  s << ", " << cpu_seconds << " s";
  return s.str();
}

namespace {

using SolveOutcome = internal::SmoothCollocationSolver::Outcome;

// Steps below this many units in the last place of t (10 eps |t|) no longer advance t
// reliably: an error-controlled run stops there with kStepSizeTooSmall.
constexpr double kMinStepUlps = 10.0;
// Error weights are never below this many eps (1 + |y|): what floating point resolves.
constexpr double kNoise = 10.0;

class RadauRun {
 public:
  RadauRun(const Scene& scene, const RadauOptions& options, const ProgressCallback& progress)
      : options_(options),
        progress_(progress),
        system_(scene),
        tableau_(RadauIIA(options.stages)),
        n_(system_.num_states()),
        s_(options.stages),
        stage_solver_(&system_, options.stages, options.linear_solver) {
    filter_solver_ = MakeLinearSolver(options.linear_solver, n_, system_.EstimatedNonzerosFy());
  }

  RadauResult Run() {
    const RunClock run_clock;
    const Scene& scene = system_.scene();
    RadauResult result;
    result.trajectory.state_names = scene.state_names;
    Vector y = system_.InitialState();
    const int nx = system_.num_scene_states();
    const std::vector<double> ends =
        StretchEnds(scene.initial_time, scene.final_time, scene.ControlBreakpoints(),
                    options_.stop_times, nullptr);
    const bool adaptive = options_.ErrorControlled();
    // A fixed grid longer than max_steps is refused before any work.
    if (!adaptive) RequireFixedStepsWithin(ends, options_.step_size, options_.max_steps);
    // The embedded estimate has local order s + 1, below the 2s - 1 of the solution at step
    // ends: summed over error-controlled steps it is about (number of steps) * rtol and says
    // nothing the tolerance does not; for fixed steps it is the error statement there is.
    estimating_ = !adaptive && options_.estimate_error;
    if (estimating_) stats_.error_estimate = 0.0;
    scale_.Reset(y);
    result.trajectory.Append(scene.initial_time, y.head(nx), Vector(), 0.0);

    double h_next =
        options_.initial_step_size > 0.0 ? options_.initial_step_size : options_.step_size;
    for (std::size_t segment = 0; segment + 1 < ends.size(); ++segment) {
      const double t_begin = ends[segment];
      const double t_end = ends[segment + 1];
      system_.SetInputs(scene.InputValues(t_begin));
      have_previous_ = false;  // no extrapolation across a breakpoint
      const bool ok = adaptive ? RunAdaptive(t_begin, t_end, &y, &h_next, &result)
                               : RunFixed(t_begin, t_end, &y, &result);
      if (!ok) break;
    }
    if (!adaptive && estimating_) {
      const std::string warning =
          ErrorEstimateWarning(stats_.error_estimate, options_.relative_tolerance);
      if (!warning.empty()) result.warnings.push_back(warning);
    }
    result.final_time = y[system_.clock_index()];
    result.final_state = y.head(nx);
    if (!options_.record_trajectory && result.trajectory.t.back() != result.final_time) {
      result.trajectory.Append(result.final_time, result.final_state, Vector(), last_step_);
    }
    stats_.num_factorizations =
        stage_solver_.num_factorizations() + filter_solver_->num_factorizations();
    stats_.num_newton_iterations = stage_solver_.num_newton_iterations();
    stats_.num_function_evaluations += stage_solver_.num_function_evaluations();
    stats_.num_jacobian_evaluations += stage_solver_.num_function_evaluations();
    stats_.cpu_seconds = run_clock.CpuSeconds();
    result.stats = stats_;
    return result;
  }

 private:
  bool RunFixed(double t_begin, double t_end, Vector* y, RadauResult* result) {
    const std::vector<double> grid = FixedStepGrid(t_begin, t_end, options_.step_size);
    Matrix z(n_, s_);
    for (std::size_t k = 0; k + 1 < grid.size(); ++k) {
      const double h = grid[k + 1] - grid[k];
      if (stats_.num_steps >= options_.max_steps) {
        return Fail(result, RadauStatus::kMaxStepsReached, grid[k], "reached max_steps");
      }
      InitialGuess(h, &z);
      int iterations = 0;
      system_.ClearNonFinite();
      const SolveOutcome outcome = SolveStages(h, *y, &z, &iterations);
      if (outcome != SolveOutcome::kConverged) {
        return FailSolve(result, grid[k], Describe(outcome, iterations, h),
                         outcome == SolveOutcome::kNonFinite);
      }
      if (options_.estimate_error) {
        const double error = ErrorNorm(h, *y, z, false);
        if (std::isfinite(error)) stats_.error_estimate += options_.relative_tolerance * error;
      }
      Accept(h, z, grid[k + 1], y, result);
      if (progress_) progress_(grid[k + 1]);
    }
    return true;
  }

  bool RunAdaptive(double t_begin, double t_end, Vector* y, double* h_next, RadauResult* result) {
    double h = *h_next > 0.0 ? *h_next : StartingStep(*y, t_end - t_begin);
    h = std::clamp(h, options_.min_step_size, options_.max_step_size);
    // Steps below 10 eps |t| no longer advance t reliably: the run stops there.
    auto minimum = [this](double t) {
      return std::max(options_.min_step_size,
                      kMinStepUlps * std::numeric_limits<double>::epsilon() * std::fabs(t));
    };
    Matrix z(n_, s_);
    bool last_rejected = false;
    bool first = true;
    double t = t_begin;
    while (t < t_end) {
      if (stats_.num_steps >= options_.max_steps) {
        return Fail(result, RadauStatus::kMaxStepsReached, t, "reached max_steps");
      }
      bool lands = false;
      if (t + h >= t_end - 0.01 * h) {  // land exactly on the segment end
        h = t_end - t;
        lands = true;
      }
      InitialGuess(h, &z);
      int iterations = 0;
      system_.ClearNonFinite();
      const SolveOutcome outcome = SolveStages(h, *y, &z, &iterations);
      if (outcome != SolveOutcome::kConverged) {
        // Retried with half the step; a step that fails at its minimum ends the run, named
        // by the non-finite model value it met if any.
        ++stats_.num_rejected_steps;
        const std::string reason = Describe(outcome, iterations, h);
        h *= 0.5;
        last_rejected = true;
        have_previous_ = false;
        if (h < minimum(t)) {
          std::ostringstream text;
          text.precision(3);
          text << reason << "; retried with the step halved below its minimum " << minimum(t);
          return FailSolve(result, t, text.str(), outcome == SolveOutcome::kNonFinite,
                           RadauStatus::kStepSizeTooSmall);
        }
        continue;
      }
      const double error = ErrorNorm(h, *y, z, first || last_rejected);
      if (!std::isfinite(error)) {
        std::ostringstream text;
        text.precision(3);
        text << "non-finite error estimate with h = " << h;
        return FailSolve(result, t, text.str(), true);
      }
      const double exponent = 1.0 / (s_ + 1.0);
      double factor = 0.9 * std::pow(std::max(error, 1e-10), -exponent);
      if (error <= 1.0) {
        t = lands ? t_end : t + h;
        Accept(h, z, t, y, result);
        if (last_rejected) factor = std::min(factor, 1.0);
        last_rejected = false;
        first = false;
        if (progress_) progress_(t);
        h = std::clamp(h * std::clamp(factor, 0.2, 5.0), options_.min_step_size,
                       options_.max_step_size);
        if (!lands) *h_next = h;
      } else {
        ++stats_.num_rejected_steps;
        last_rejected = true;
        have_previous_ = false;
        h *= std::clamp(factor, 0.2, 0.9);
        if (h < minimum(t)) {
          std::ostringstream text;
          text.precision(3);
          text << "the error test calls for a step below max(min_step_size, 10 eps |t|) = "
               << minimum(t);
          return Fail(result, RadauStatus::kStepSizeTooSmall, t, text.str());
        }
      }
    }
    return true;
  }

  // Hairer, Norsett & Wanner's starting step (../common/step_size.hpp) on the scene states.
  double StartingStep(const Vector& y, double span) {
    constexpr double kQuietStart = 1e-3;  // of the span, where nothing moves at t0
    const int nx = system_.num_scene_states();
    const double rtol = options_.relative_tolerance;
    Vector weights(nx);
    for (int i = 0; i < nx; ++i) {
      weights[i] =
          scale_.AbsoluteTolerance(i, options_.absolute_tolerance, rtol) + rtol * std::fabs(y[i]);
    }
    Evaluate(y, Derivatives::kNone);
    const Vector f0 = eval_.F;
    const double h =
        internal::StartingStep(y, f0, weights, nx, 2 * s_ - 1, span, kQuietStart * span,
                               [this](const Vector& y1, Vector* f1) {
                                 Evaluate(y1, Derivatives::kNone);
                                 *f1 = eval_.F;
                               });
    system_.ClearNonFinite();  // trial evaluations beyond t0 are not the run's
    return h;
  }

  void Evaluate(const Vector& y, Derivatives derivatives) {
    system_.Evaluate(y, Vector(), derivatives, &eval_);
    ++stats_.num_function_evaluations;
    if (derivatives != Derivatives::kNone) ++stats_.num_jacobian_evaluations;
  }

  // Stage increments from the previous step's collocation polynomial (zero if none).
  void InitialGuess(double h, Matrix* z) {
    if (!have_previous_) {
      z->setZero();
      return;
    }
    for (int j = 0; j < s_; ++j) {
      const double theta = 1.0 + tableau_.c[j] * h / previous_h_;
      if (theta > 4.0) {  // too far to extrapolate
        z->setZero();
        return;
      }
      tableau_.InterpolationWeights(theta, &guess_weights_);
      guess_column_.noalias() = previous_z_ * guess_weights_;
      z->col(j) = guess_column_ - previous_z_.col(s_ - 1);
    }
  }

  // Full Newton on the collocation equations (shared kernel, see smooth_collocation.hpp).
  SolveOutcome SolveStages(double h, const Vector& y0, Matrix* z, int* iterations) {
    internal::SmoothCollocationSolver::Stopping stopping;
    stopping.weighted_rms = options_.ErrorControlled();
    // Adaptive: a small fraction of the error tolerance; fixed step: newton_tolerance.
    stopping.tolerance = options_.ErrorControlled() ? 1e-2 : options_.newton_tolerance;
    stopping.relative_tolerance = options_.relative_tolerance;
    const int nx = system_.num_scene_states();
    newton_atol_.resize(nx);
    for (int i = 0; i < nx; ++i) {
      newton_atol_[i] =
          scale_.AbsoluteTolerance(i, options_.absolute_tolerance, options_.relative_tolerance);
    }
    stopping.absolute_tolerances = &newton_atol_;
    stopping.max_iterations = options_.max_newton_iterations;
    return stage_solver_.Solve(h, y0, stopping, z, iterations);
  }

  // Embedded estimate (see header), filtered by (I - h gamma0 J(y0))^{-1}.
  double ErrorNorm(double h, const Vector& y0, const Matrix& z, bool refine) {
    const int nx = system_.num_scene_states();
    Evaluate(y0, Derivatives::kStates);
    // Kept vectors (no allocation per step); the arithmetic of the expressions they replace.
    Vector& f0 = error_f0_;
    f0 = eval_.F;
    filter_matrix_.Reset(n_, filter_solver_->wants_sparse());
    filter_matrix_.AddDiagonal(0, 0, n_, 1.0);
    filter_matrix_.AddDerivative(0, 0, eval_.F_y, -h * tableau_.gamma0);
    filter_matrix_.Finalize();
    if (filter_solver_->Factorize(filter_matrix_) != FactorizationStatus::kSuccess) {
      return std::numeric_limits<double>::infinity();
    }
    Vector& ez = error_ez_;
    ez.noalias() = z * tableau_.error_weights;
    Vector& err = error_;
    err = tableau_.gamma0 * h * f0 + ez;
    filter_solver_->Solve(err);
    Vector& y1 = error_y1_;
    y1 = y0 + z.col(s_ - 1);
    auto norm = [&](const Vector& e) {
      double sum = 0.0;
      for (int i = 0; i < nx; ++i) {
        const double size = std::max(std::fabs(y0[i]), std::fabs(y1[i]));
        // A state that has been exactly zero so far has no scale: its weight is never below
        // what floating point resolves there.
        const double w = std::max(
            scale_.AbsoluteTolerance(i, options_.absolute_tolerance, options_.relative_tolerance) +
                options_.relative_tolerance * size,
            kNoise * std::numeric_limits<double>::epsilon() * (1.0 + size));
        sum += (e[i] / w) * (e[i] / w);
      }
      return std::sqrt(sum / nx);
    };
    double error = norm(err);
    if (refine && error > 1.0) {
      // Hairer's refinement on first and rejected steps (avoids needless rejections for
      // stiff problems): use F(y0 + err) in place of F(y0).
      error_point_ = y0 + err;
      Evaluate(error_point_, Derivatives::kNone);
      err = tableau_.gamma0 * h * eval_.F + ez;
      filter_solver_->Solve(err);
      error = norm(err);
    }
    return error;
  }

  // Advances y by the last stage increment; the clock is set to the exact new time t_new so
  // that it does not accumulate round-off over many steps.
  void Accept(double h, const Matrix& z, double t_new, Vector* y, RadauResult* result) {
    *y += z.col(s_ - 1);
    (*y)[system_.clock_index()] = t_new;
    scale_.Update(*y);
    ++stats_.num_steps;
    previous_z_ = z;
    previous_h_ = h;
    have_previous_ = true;
    last_step_ = h;
    if (options_.record_trajectory) {
      result->trajectory.Append((*y)[system_.clock_index()], y->head(system_.num_scene_states()),
                                Vector(), h);
    }
  }

  // A failed solve: kNonFinite naming the model function if a non-finite value was met
  // (`non_finite`: the solver says so, or the witness of the lowered system saw one), else
  // `otherwise`.
  bool FailSolve(RadauResult* result, double t, const std::string& reason, bool non_finite,
                 RadauStatus otherwise = RadauStatus::kNewtonFailure) {
    if (!non_finite && !system_.non_finite_seen()) return Fail(result, otherwise, t, reason);
    const std::string named =
        system_.non_finite_seen() ? system_.DescribeNonFinite(system_.non_finite_state()) : "";
    return Fail(
        result, RadauStatus::kNonFinite, t,
        (named.empty() ? std::string("a non-finite value in the state or the dynamics") : named) +
            " (" + reason + ")");
  }

  bool Fail(RadauResult* result, RadauStatus status, double t, const std::string& reason) {
    result->status = status;
    std::ostringstream s;
    s.precision(17);
    s << ToString(status) << " at t = " << t << ": " << reason;
    result->message = s.str();
    return false;
  }

  std::string Describe(SolveOutcome outcome, int iterations, double h) const {
    std::ostringstream s;
    s << "Newton ";
    switch (outcome) {
      case SolveOutcome::kNotConverged:
        s << "did not converge in " << iterations << " iterations";
        break;
      case SolveOutcome::kSingular:
        s << "matrix numerically singular (rcond < " << kSingularRcond << ") at iteration "
          << iterations;
        break;
      case SolveOutcome::kNonFinite:
        s << "met a non-finite value at iteration " << iterations;
        break;
      case SolveOutcome::kConverged:
        s << "converged";
        break;
    }
    s << " with h = " << h;
    return s.str();
  }

  RadauOptions options_;
  ProgressCallback progress_;
  LoweredSystem system_;
  const RadauTableau& tableau_;
  int n_;
  int s_;
  internal::SmoothCollocationSolver stage_solver_;
  std::unique_ptr<LinearSolver> filter_solver_;
  SystemMatrix filter_matrix_;
  PointEvaluation eval_;
  Matrix previous_z_;
  // Scratch of InitialGuess and ErrorNorm, kept across steps.
  Vector guess_weights_, guess_column_, error_f0_, error_ez_, error_, error_y1_, error_point_;
  double previous_h_ = 0.0;
  bool have_previous_ = false;
  double last_step_ = 0.0;
  bool estimating_ = false;  // error_estimate accumulated (error control or estimate_error)
  internal::StateScale scale_;
  Vector newton_atol_;  // per-state atol of the adaptive Newton's stopping test
  RadauStats stats_;
};

}  // namespace

RadauResult SimulateRadau(const Scene& scene, const RadauOptions& options,
                          const ProgressCallback& progress) {
  options.Validate();
  RequireSupportedEffects(scene, "radau");
  RadauRun run(scene, options, progress);
  return run.Run();
}

}  // namespace moreau
