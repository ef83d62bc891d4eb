#pragma once
/// @file
/// Semismooth Newton method for mixed complementarity systems
///
///   r(w) = 0                      (n_eq smooth equations)
///   0 <= a_k(w) ⟂ b_k(w) >= 0     (k = 1..n_pairs),        n_eq + n_pairs = dim w,
///
/// reformulated as Phi(w) = [r(w); phi(a_k(w), b_k(w))] = 0 with an NCP function phi
/// (Fischer-Burmeister by default, see ncp_function.hpp).
///
/// Iteration: d solves J d = -Phi with J an element of the generalized Jacobian
/// (rows dr/dw and phi_a da_k/dw + phi_b db_k/dw). Globalization: Armijo backtracking on the
/// scaled merit theta(w) = 1/2 ||S Phi(w)||^2 (continuously differentiable for
/// Fischer-Burmeister), with gradient grad theta = J^T S^2 Phi. If J is singular or d is not
/// a sufficient descent direction (grad theta . d > -rho ||d||^p, De Luca, Facchinei &
/// Kanzow 1996) the steepest-descent direction -grad theta is used instead. When the
/// residual contracts only linearly after a full step (ratio > polish_ratio, typical at
/// degenerate solutions where a = b = 0), a min-map Newton step (a primal-dual active-set
/// step) is tried and kept if it lowers the residual by polish_ratio: for linear problems it
/// lands on the solution once the active set is right. Row scales S come from the system (residual
/// scaling), so that blocks with different units weigh alike in the merit and the stopping test.
///
/// Stopping: converged when ||S Phi||_inf <= tolerance. Every other outcome is a status with
/// its reason (never an exception or abort).

#include <memory>
#include <string>
#include <vector>

#include "moreau/complementarity/ncp_function.hpp"
#include "moreau/core/types.hpp"
#include "moreau/linalg/linear_solver.hpp"

namespace moreau {

/// The problem solved by SemismoothNewton (see file comment).
class MixedComplementaritySystem {
 public:
  virtual ~MixedComplementaritySystem() = default;
  /// Number of unknowns w (n_eq + n_pairs).
  virtual int num_unknowns() const = 0;
  virtual int num_equations() const = 0;  ///< n_eq
  virtual int num_pairs() const = 0;      ///< n_pairs = num_unknowns() - n_eq
  /// Values r, a, b at w. With with_jacobian, also prepares the derivatives that
  /// AssembleJacobian uses. Returns false if w is outside the system's domain.
  virtual bool Evaluate(const Vector& w, bool with_jacobian, Vector* r, Vector* a, Vector* b) = 0;
  /// Adds the generalized Jacobian at the last Evaluate(.., true) point into `jacobian`
  /// (already Reset to the right size and storage): rows 0..n_eq-1 hold dr/dw, row n_eq + k
  /// holds da[k] * d a_k/dw + db[k] * d b_k/dw.
  virtual void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) = 0;
  /// Positive scale of every residual row ([r; phi]); the default is 1.
  virtual void ResidualScale(const Vector& w, Vector* scale);
  /// Structural nonzeros of the Jacobian (for choosing dense or sparse LU).
  virtual double EstimatedJacobianNonzeros() const;
};

/// Options of the semismooth Newton method; defaults are the values below.
struct SemismoothNewtonOptions {
  /// NCP function for the pairs (Fischer-Burmeister: smooth merit, recommended).
  NcpFunctionKind ncp_function = NcpFunctionKind::kFischerBurmeister;
  /// Converged when ||S Phi(w)||_inf <= tolerance, > 0.
  double tolerance = 1e-12;
  /// Smoothing mu >= 0 of the Fischer-Burmeister function (SmoothedFischerBurmeister): with
  /// mu > 0 the pairs solve a b = mu^2 instead of a b = 0 (continuation stages only).
  double smoothing = 0.0;
  /// Newton iterations before kMaxIterations, >= 1.
  int max_iterations = 100;
  /// Iterations taken even if the initial guess already meets the tolerance, in
  /// [0, max_iterations]. Integrators use 1: an accepted extrapolated guess carries its
  /// round-off into every later step, while one Newton correction removes it (linear rows,
  /// like the clock, are then satisfied to round-off).
  int min_iterations = 0;
  /// Armijo constant sigma in theta(w + t d) <= theta(w) + sigma t grad theta . d, in (0, 1/2).
  double armijo = 1e-4;
  /// Backtracking factor for the step length t, in (0, 1).
  double backtrack = 0.5;
  /// Smallest step length before kLineSearchFailed, in (0, 1).
  double min_step = 1e-10;
  /// Sufficient-descent test grad theta . d <= -descent_rho ||d||^descent_power; a Newton
  /// direction that fails it but descends (slope < 0) and whose full step satisfies the
  /// Armijo condition is still taken (the test is not scale invariant: large multipliers
  /// beside small states make a good Newton step fail it).
  double descent_rho = 1e-10;
  /// Exponent p of the descent test grad . d <= -rho ||d||^p (with descent_rho).
  double descent_power = 2.1;
  /// kStagnated when the merit decreased by less than a relative 1e-3 over this many
  /// iterations (no progress; slow but steady progress ends at max_iterations instead).
  int stagnation_window = 12;
  /// After a full Newton step that contracted ||S Phi|| by less than polish_ratio, try a
  /// min-map (active-set) step.
  bool active_set_polish = true;
  /// Contraction ratio below which no min-map polish step is tried (see active_set_polish).
  double polish_ratio = 0.2;
  /// Dense or sparse LU of the generalized Jacobian (automatic: by size and density).
  LinearSolverKind linear_solver = LinearSolverKind::kAutomatic;
  /// On convergence, factorize the generalized Jacobian at the solution (one more
  /// factorization) so that last_jacobian_solver() serves sensitivity computations.
  bool factorize_at_solution = false;
  /// Evaluate the initial guess without derivatives first (for guesses that usually are
  /// solutions already): if it meets the tolerance the solve returns at once and the system's
  /// last evaluation, at the solution, is values-only; otherwise the guess is evaluated again
  /// with derivatives and the iteration proceeds as without this option (same iterates). Has
  /// no effect with min_iterations > 0 or factorize_at_solution (both need the derivatives).
  bool defer_initial_jacobian = false;

  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of a solve, each documented by its criterion.
enum class NewtonStatus {
  kConverged,         ///< ||S Phi(w)||_inf <= tolerance
  kMaxIterations,     ///< max_iterations iterations without convergence
  kLineSearchFailed,  ///< no step length >= min_step satisfies the Armijo condition
  /// the merit fell by less than a relative 1e-3 over stagnation_window, or 8 consecutive
  /// iterations found no Newton descent direction (steepest descent only)
  kStagnated,
  kStationaryPoint,  ///< grad theta = J^T S^2 Phi vanishes (to round-off) while Phi != 0
  kNonFinite,        ///< the residual at the initial point is not finite or not defined
};
/// The status as text (snake case).
std::string ToString(NewtonStatus status);

/// Counters of a Newton solve.
struct SemismoothNewtonStats {
  /// Newton iterations.
  long iterations = 0;
  /// Residual evaluations (line search included).
  long residual_evaluations = 0;
  /// Evaluations with the Jacobian.
  long jacobian_evaluations = 0;
  /// LU factorizations.
  long factorizations = 0;
  long backtracks = 0;          ///< step-length reductions in the line search
  long gradient_steps = 0;      ///< steepest-descent fallbacks
  long polish_steps = 0;        ///< accepted min-map (active-set) steps
  long singular_jacobians = 0;  ///< generalized Jacobians found singular

  /// Sums the counters.
  SemismoothNewtonStats& operator+=(const SemismoothNewtonStats& other);
  /// One line of counters.
  std::string Summary() const;
};

/// Result of a SemismoothNewton solve.
struct SemismoothNewtonResult {
  /// kConverged, or why the solve stopped.
  NewtonStatus status = NewtonStatus::kConverged;
  std::string message;                    ///< reason when not converged
  Vector solution;                        ///< last iterate
  double residual_norm = 0.0;             ///< ||S Phi||_inf at the solution
  double complementarity_residual = 0.0;  ///< max_k |min(a_k, b_k)| at the solution
  std::vector<double> residual_history;   ///< ||S Phi||_inf at every iterate
  /// Counters of the solve.
  SemismoothNewtonStats stats;
  /// True if status is NewtonStatus::kConverged.
  bool converged() const { return status == NewtonStatus::kConverged; }
};

/// Reusable solver: keeps its linear solver (and the sparse symbolic analysis) across
/// solves of systems with the same structure.
class SemismoothNewton {
 public:
  /// A solver with these options.
  explicit SemismoothNewton(const SemismoothNewtonOptions& options = {});
  ~SemismoothNewton();
  SemismoothNewton(const SemismoothNewton&) = delete;
  SemismoothNewton& operator=(const SemismoothNewton&) = delete;

  /// The options it was made with.
  const SemismoothNewtonOptions& options() const { return options_; }
  /// Solves from `initial_guess`. With options().factorize_at_solution the generalized
  /// Jacobian at the solution stays factorized (see last_jacobian_solver).
  SemismoothNewtonResult Solve(MixedComplementaritySystem& system, const Vector& initial_guess);
  /// The same solve into `result`, whose members are overwritten (the same values as the
  /// returned result of the overload above) but keep their storage: a step loop that holds one
  /// result across solves of one size allocates nothing per solve (unless it fails: the
  /// message is built then).
  void Solve(MixedComplementaritySystem& system, const Vector& initial_guess,
             SemismoothNewtonResult* result);
  /// The linear solver holding the last factorization (at the solution after a converged solve
  /// with factorize_at_solution).
  const LinearSolver* last_jacobian_solver() const { return solver_.get(); }

 private:
  SemismoothNewtonOptions options_;
  std::unique_ptr<LinearSolver> solver_;
  int solver_size_ = -1;
  SystemMatrix jacobian_;
  struct Workspace;  // iterates and work vectors, kept across solves (no allocation per solve)
  std::unique_ptr<Workspace> workspace_;
};

}  // namespace moreau
