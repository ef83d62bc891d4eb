#include "moreau/newton/semismooth_newton.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "moreau/core/error.hpp"

namespace moreau {

void MixedComplementaritySystem::ResidualScale(const Vector& /*w*/, Vector* scale) {
  scale->setOnes(num_unknowns());
}

double MixedComplementaritySystem::EstimatedJacobianNonzeros() const {
  const double n = num_unknowns();
  return n * n;
}

void SemismoothNewtonOptions::Validate() const {
  RequireArgument(std::isfinite(tolerance) && tolerance > 0.0,
                  "Newton tolerance must be positive, got ", tolerance);
  RequireArgument(std::isfinite(smoothing) && smoothing >= 0.0,
                  "smoothing must be non-negative, got ", smoothing);
  RequireArgument(max_iterations >= 1, "max Newton iterations must be >= 1, got ", max_iterations);
  RequireArgument(armijo > 0.0 && armijo < 0.5, "Armijo constant must be in (0, 0.5), got ",
                  armijo);
  RequireArgument(backtrack > 0.0 && backtrack < 1.0, "backtracking factor must be in (0, 1), got ",
                  backtrack);
  RequireArgument(min_step > 0.0 && min_step < 1.0, "min step must be in (0, 1), got ", min_step);
  RequireArgument(descent_rho > 0.0 && descent_power > 2.0,
                  "descent test needs rho > 0 and power > 2, got ", descent_rho, " and ",
                  descent_power);
  RequireArgument(stagnation_window >= 2, "stagnation window must be >= 2, got ",
                  stagnation_window);
  RequireArgument(polish_ratio > 0.0 && polish_ratio < 1.0, "polish ratio must be in (0, 1), got ",
                  polish_ratio);
}

namespace {
// The status's name (a literal: FailureMessage appends it without a temporary string).
const char* StatusName(NewtonStatus status) {
  switch (status) {
    case NewtonStatus::kConverged:
      return "converged";
    case NewtonStatus::kMaxIterations:
      return "max_iterations";
    case NewtonStatus::kLineSearchFailed:
      return "line_search_failed";
    case NewtonStatus::kStagnated:
      return "stagnated";
    case NewtonStatus::kStationaryPoint:
      return "stationary_point";
    case NewtonStatus::kNonFinite:
      return "non_finite";
  }
  return "?";
}
}  // namespace

std::string ToString(NewtonStatus status) { return StatusName(status); }

SemismoothNewtonStats& SemismoothNewtonStats::operator+=(const SemismoothNewtonStats& other) {
  iterations += other.iterations;
  residual_evaluations += other.residual_evaluations;
  jacobian_evaluations += other.jacobian_evaluations;
  factorizations += other.factorizations;
  backtracks += other.backtracks;
  gradient_steps += other.gradient_steps;
  polish_steps += other.polish_steps;
  singular_jacobians += other.singular_jacobians;
  return *this;
}

std::string SemismoothNewtonStats::Summary() const {
  std::ostringstream s;
  s << iterations << " iterations, " << factorizations << " factorizations, " << backtracks
    << " backtracks, " << gradient_steps << " gradient steps, " << polish_steps
    << " active-set steps, " << singular_jacobians << " singular Jacobians";
  return s.str();
}

namespace {

// "<status> after <n> iterations: <reason> (||S Phi||_inf = <norm>)", the norm as an ostream
// with precision 6 prints it (%.6g). Built with snprintf rather than an ostringstream: failed
// solves are routine (the velocity-level enumeration's rejected trials, the FESD trial
// elements), and the stream's construction cost more than the solve of a small system.
// Written into *message in place: a result kept across solves keeps the string's capacity, so
// that a routine failure in a step loop does not allocate once the capacity suffices.
void FailureMessage(NewtonStatus status, long iterations, std::string_view reason, double norm,
                    std::string* message) {
  char number[32];
  std::snprintf(number, sizeof(number), "%.6g", norm);
  char count[24];
  std::snprintf(count, sizeof(count), "%ld", iterations);
  message->clear();
  *message += StatusName(status);
  *message += " after ";
  *message += count;
  *message += " iterations: ";
  *message += reason;
  *message += " (||S Phi||_inf = ";
  *message += number;
  *message += ')';
}

// Relative decrease of the merit below which a window of iterations counts as no progress.
constexpr double kStagnationDecrease = 1e-3;

// Consecutive steepest-descent steps after which a solve counts as stagnated. Where the
// generalized Newton direction is not a descent direction of the merit, steepest descent
// decreases it at a linear rate that does not reach a 1e-12 tolerance within max_iterations:
// over the whole test suite no converged solve took more than 3 such steps in a row, while
// solves without a solution (a FESD event group whose statuses admit none, the crowd's jammed
// contacts) took 40 of them, each with its backtracking, before max_iterations ended them.
// Twice the longest streak seen in a converged solve, plus margin.
constexpr int kMaxGradientStreak = 8;

// One evaluated point: residual Phi = [r; phi(a, b)], its scaled norms and the NCP derivatives.
struct Point {
  Vector w, r, a, b;
  Vector phi;                                              // full residual [r; phi]
  Vector da, db;                                           // NCP generalized derivatives
  Vector scale;                                            // row scales S
  double merit = std::numeric_limits<double>::infinity();  // 1/2 ||S Phi||^2
  double norm = std::numeric_limits<double>::infinity();   // ||S Phi||_inf
  bool valid = false;
};

}  // namespace

// Linear solvers kept for systems of other sizes than the current one (most recently used
// last). A caller that alternates between two systems, as FESD's fixed steps do between the
// step's element group and its error estimate's comparison element, then finds each size's
// solver with its symbolic analysis, instead of making a new solver at every switch (a new
// symbolic analysis and, with sparse storage, new UMFPACK objects twice per step). The
// factorizations are the same: each solver refactorizes at every Newton iteration and
// reuses only what depends on the pattern.
constexpr std::size_t kMaxSpareSolvers = 2;

struct SemismoothNewton::Workspace {
  Point current, trial;
  Vector scaled_phi, gradient, direction, trial_w;
  Vector da_min, db_min, rhs;  // the active-set step's
  std::vector<double> history, merits;
  struct SpareSolver {
    int size = 0;
    std::unique_ptr<LinearSolver> solver;
  };
  std::vector<SpareSolver> spare_solvers;
};

SemismoothNewton::SemismoothNewton(const SemismoothNewtonOptions& options)
    : options_(options), workspace_(std::make_unique<Workspace>()) {
  options_.Validate();
}

SemismoothNewton::~SemismoothNewton() = default;

SemismoothNewtonResult SemismoothNewton::Solve(MixedComplementaritySystem& system,
                                               const Vector& initial_guess) {
  SemismoothNewtonResult result;
  Solve(system, initial_guess, &result);
  return result;
}

void SemismoothNewton::Solve(MixedComplementaritySystem& system, const Vector& initial_guess,
                             SemismoothNewtonResult* result_out) {
  const int n = system.num_unknowns();
  const int n_eq = system.num_equations();
  const int n_pairs = system.num_pairs();
  MOREAU_ASSERT(n_eq + n_pairs == n, "mixed complementarity system is not square");
  MOREAU_ASSERT(initial_guess.size() == n, "initial guess has the wrong size");
  if (solver_ == nullptr || solver_size_ != n) {
    // A kept solver of this size and of the kind a new one would be, else a new one.
    std::vector<Workspace::SpareSolver>& spare = workspace_->spare_solvers;
    const double nonzeros = system.EstimatedJacobianNonzeros();
    const LinearSolverKind kind = ResolveLinearSolverKind(options_.linear_solver, n, nonzeros);
    std::unique_ptr<LinearSolver> solver;
    for (auto it = spare.begin(); it != spare.end(); ++it) {
      if (it->size == n && it->solver->kind() == kind) {
        solver = std::move(it->solver);
        spare.erase(it);
        break;
      }
    }
    // (Made from the option, not the resolved kind: kAutomatic's KLU guards its fill.)
    if (solver == nullptr) solver = MakeLinearSolver(options_.linear_solver, n, nonzeros);
    if (solver_ != nullptr) {
      if (spare.size() == kMaxSpareSolvers) spare.erase(spare.begin());
      spare.push_back({solver_size_, std::move(solver_)});
    }
    solver_ = std::move(solver);
    solver_size_ = n;
  }
  SemismoothNewtonResult& result = *result_out;
  result.stats = {};
  result.message.clear();
  SemismoothNewtonStats& stats = result.stats;

  // Evaluates the residual with a given NCP function (the line search always measures the
  // merit with options_.ncp_function).
  auto evaluate = [&](const Vector& w, bool with_jacobian, NcpFunctionKind kind, Point* p) {
    p->w = w;
    ++stats.residual_evaluations;
    if (with_jacobian) ++stats.jacobian_evaluations;
    p->valid = system.Evaluate(w, with_jacobian, &p->r, &p->a, &p->b);
    if (!p->valid) {
      p->merit = p->norm = std::numeric_limits<double>::infinity();
      return;
    }
    p->phi.resize(n);
    p->da.resize(n_pairs);
    p->db.resize(n_pairs);
    p->phi.head(n_eq) = p->r;
    for (int k = 0; k < n_pairs; ++k) {
      const NcpValue v = kind == NcpFunctionKind::kFischerBurmeister && options_.smoothing > 0.0
                             ? SmoothedFischerBurmeister(p->a[k], p->b[k], options_.smoothing)
                             : EvaluateNcp(kind, p->a[k], p->b[k]);
      p->phi[n_eq + k] = v.value;
      p->da[k] = v.da;
      p->db[k] = v.db;
    }
    system.ResidualScale(w, &p->scale);
    double merit = 0.0, norm = 0.0;
    for (int i = 0; i < n; ++i) {
      const double scaled = p->scale[i] * p->phi[i];
      merit += scaled * scaled;
      norm = std::max(norm, std::fabs(scaled));
    }
    p->valid = std::isfinite(merit);
    p->merit = p->valid ? 0.5 * merit : std::numeric_limits<double>::infinity();
    p->norm = p->valid ? norm : std::numeric_limits<double>::infinity();
  };
  Workspace& ws = *workspace_;
  std::vector<double>& history = ws.history;
  std::vector<double>& merits = ws.merits;
  history.clear();
  merits.clear();
  // One entry per iterate: sized for the longest solve at the first, so that no later solve
  // of a step loop grows them (nor the result's copy of the history). Capped, so that a huge
  // max_iterations does not reserve megabytes up front: longer solves grow them as they go.
  constexpr std::size_t kReservedIterates = 1024;
  const auto most_iterates =
      std::min(static_cast<std::size_t>(options_.max_iterations) + 1, kReservedIterates);
  history.reserve(most_iterates);
  merits.reserve(most_iterates);
  result.residual_history.reserve(most_iterates);
  auto finish = [&](NewtonStatus status, const Point& p, std::string_view reason) {
    result.status = status;
    result.solution = p.w;
    result.residual_history = history;
    result.residual_norm = p.norm;
    result.complementarity_residual = 0.0;
    if (p.valid) {
      for (int k = 0; k < n_pairs; ++k) {
        result.complementarity_residual =
            std::max(result.complementarity_residual, ComplementarityResidual(p.a[k], p.b[k]));
      }
    }
    if (status != NewtonStatus::kConverged) {
      FailureMessage(status, stats.iterations, reason, p.norm, &result.message);
    }
  };
  // Factorizes the generalized Jacobian for derivatives (da, db) at the last evaluated point.
  auto factorize = [&](const Vector& da, const Vector& db) {
    jacobian_.Reset(n, solver_->wants_sparse());
    system.AssembleJacobian(da, db, &jacobian_);
    jacobian_.Finalize();
    ++stats.factorizations;
    const FactorizationStatus status = solver_->Factorize(jacobian_);
    if (status != FactorizationStatus::kSuccess) ++stats.singular_jacobians;
    return status == FactorizationStatus::kSuccess;
  };

  Point& current = ws.current;
  const bool defer = options_.defer_initial_jacobian && options_.min_iterations == 0 &&
                     !options_.factorize_at_solution;
  evaluate(initial_guess, !defer, options_.ncp_function, &current);
  if (defer && current.valid && current.norm <= options_.tolerance) {
    history.push_back(current.norm);
    return finish(NewtonStatus::kConverged, current, "");
  }
  // The first Newton step needs the derivatives at the guess (the values again, too: the
  // system's derivatives belong to its last evaluation with them).
  if (defer && current.valid) evaluate(initial_guess, true, options_.ncp_function, &current);
  if (!current.valid) {
    return finish(NewtonStatus::kNonFinite, current,
                  "the residual at the initial point is not finite or not defined");
  }
  history.push_back(current.norm);
  merits.push_back(current.merit);
  double previous_norm = std::numeric_limits<double>::infinity();
  bool last_step_full = false;  // the previous Newton step was taken with length 1
  int gradient_streak = 0;      // consecutive steepest-descent steps (kMaxGradientStreak)
  Point& trial = ws.trial;
  Vector& scaled_phi = ws.scaled_phi;
  Vector& gradient = ws.gradient;
  Vector& direction = ws.direction;
  Vector& trial_w = ws.trial_w;
  scaled_phi.resize(n);
  gradient.resize(n);
  direction.resize(n);
  trial_w.resize(n);

  for (int k = 0;; ++k) {
    if (current.norm <= options_.tolerance && k >= options_.min_iterations) {
      // Leave the Jacobian at the solution factorized for sensitivity computations.
      if (options_.factorize_at_solution) factorize(current.da, current.db);
      return finish(NewtonStatus::kConverged, current, "");
    }
    if (k >= options_.max_iterations) {
      return finish(NewtonStatus::kMaxIterations, current, "iteration limit reached");
    }
    const int window = options_.stagnation_window;
    // Judged on the merit, which the line search decreases monotonically (the infinity
    // norm of the residual need not decrease at every step).
    if (static_cast<int>(merits.size()) > window &&
        current.merit > (1.0 - kStagnationDecrease) *
                            merits[merits.size() - 1 - static_cast<std::size_t>(window)]) {
      char reason[96];  // (on the stack: no temporary string)
      std::snprintf(reason, sizeof(reason),
                    "merit fell by less than a relative 1e-3 over %d iterations", window);
      return finish(NewtonStatus::kStagnated, current, reason);
    }
    // Checked before the next factorization, which a crawl would not use.
    if (gradient_streak >= kMaxGradientStreak) {
      char reason[96];
      std::snprintf(reason, sizeof(reason),
                    "no Newton descent direction in %d consecutive iterations (steepest descent "
                    "only)",
                    kMaxGradientStreak);
      return finish(NewtonStatus::kStagnated, current, reason);
    }
    ++stats.iterations;

    // Active-set (min-map) step when FB-Newton contracts only linearly.
    const bool slow = last_step_full && current.norm > options_.polish_ratio * previous_norm;
    if (options_.active_set_polish && slow && n_pairs > 0) {
      Vector& da_min = ws.da_min;
      Vector& db_min = ws.db_min;
      Vector& rhs = ws.rhs;
      da_min.resize(n_pairs);
      db_min.resize(n_pairs);
      rhs.resize(n);
      rhs.head(n_eq) = -current.r;
      for (int i = 0; i < n_pairs; ++i) {
        const NcpValue v = MinMap(current.a[i], current.b[i]);
        da_min[i] = v.da;
        db_min[i] = v.db;
        rhs[n_eq + i] = -v.value;
      }
      if (factorize(da_min, db_min)) {
        solver_->Solve(rhs);
        if (rhs.allFinite()) {
          // Values only: the system's derivatives must stay those of `current` unless the
          // step is accepted (AssembleJacobian uses the last point evaluated with them).
          trial_w.noalias() = current.w + rhs;
          evaluate(trial_w, false, options_.ncp_function, &trial);
          if (trial.valid && trial.norm < options_.polish_ratio * current.norm) {
            evaluate(trial.w, true, options_.ncp_function, &trial);
            ++stats.polish_steps;
            gradient_streak = 0;
            previous_norm = current.norm;
            std::swap(current, trial);
            history.push_back(current.norm);
            merits.push_back(current.merit);
            continue;
          }
        }
      }
    }

    // Newton direction on the FB (or min) reformulation.
    const bool nonsingular = factorize(current.da, current.db);
    scaled_phi.noalias() = current.scale.cwiseProduct(current.scale).cwiseProduct(current.phi);
    jacobian_.MultiplyTransposed(scaled_phi, &gradient);  // grad theta = J^T S^2 Phi
    direction.noalias() = -current.phi;
    bool use_gradient = !nonsingular;
    if (nonsingular) {
      solver_->Solve(direction);
      const double slope = gradient.dot(direction);
      use_gradient =
          !direction.allFinite() ||
          slope > -options_.descent_rho * std::pow(direction.norm(), options_.descent_power);
      // The descent test compares the slope with |d|^p in absolute terms: unknowns of very
      // different sizes (multipliers of 1e3 to 1e6 beside states of order 1, as for stiff
      // dynamics in a moving set) give a long Newton step with a small slope even on a linear
      // system. A descent direction whose full step decreases the merit sufficiently is kept.
      if (use_gradient && direction.allFinite() && slope < 0.0) {
        trial_w.noalias() = current.w + direction;
        evaluate(trial_w, true, options_.ncp_function, &trial);
        if (trial.valid && (trial.merit <= current.merit + options_.armijo * slope ||
                            trial.norm <= options_.tolerance)) {
          previous_norm = current.norm;
          last_step_full = true;
          gradient_streak = 0;
          std::swap(current, trial);
          history.push_back(current.norm);
          merits.push_back(current.merit);
          continue;
        }
      }
    }
    gradient_streak = use_gradient ? gradient_streak + 1 : 0;
    if (use_gradient) {
      ++stats.gradient_steps;
      if (gradient.lpNorm<Eigen::Infinity>() <=
          1e-14 * std::max(1.0, jacobian_.InfinityNorm()) * current.norm) {
        return finish(NewtonStatus::kStationaryPoint, current,
                      "the merit gradient J^T S^2 Phi vanishes while Phi does not");
      }
      direction = -gradient;
    }
    // Armijo backtracking on theta.
    const double slope = gradient.dot(direction);
    double t = 1.0;
    bool accepted = false;
    while (t >= options_.min_step) {
      trial_w.noalias() = current.w + t * direction;
      evaluate(trial_w, true, options_.ncp_function, &trial);
      // A trial point that meets the tolerance is taken even without sufficient decrease:
      // below the tolerance the merit is round-off (a correction forced by min_iterations).
      if (trial.valid && (trial.merit <= current.merit + options_.armijo * t * slope ||
                          trial.norm <= options_.tolerance)) {
        accepted = true;
        break;
      }
      ++stats.backtracks;
      t *= options_.backtrack;
    }
    if (!accepted) {
      char reason[96];  // std::to_string's %f, on the stack
      std::snprintf(reason, sizeof(reason), "no step length >= %f decreases the merit sufficiently",
                    options_.min_step);
      return finish(NewtonStatus::kLineSearchFailed, current, reason);
    }
    previous_norm = current.norm;
    last_step_full = t == 1.0 && !use_gradient;
    std::swap(current, trial);
    history.push_back(current.norm);
    merits.push_back(current.merit);
  }
}

}  // namespace moreau
