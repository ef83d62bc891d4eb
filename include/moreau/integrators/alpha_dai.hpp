#pragma once
/// @file
/// alpha-method stepper for differential-algebraic inequalities (DAI), with an active-set
/// SQP per step and regularization by the parameter rho.
///
/// Problem (Peter, Parida & Raha, "The alpha method for solving differential algebraic
/// inequality (DAI) systems", IJNAM 2011; docs/alpha-method.md):
///   x' = f(x, u, t, p),   phi(x, u, t, p) <= 0,   bounds on x and on the algebraic u,
/// where u holds the scene's algebraic inputs (InputSpec::Kind::kAlgebraic, unknowns with
/// bounds); known functions of time enter f through t or as piecewise-constant control inputs,
/// and an algebraic input's signal is its user input function w(t) (paper Sec. 2), which the
/// reference objective follows wherever no active constraint needs the input. Constraints and
/// state bounds come from the scene's PathConstraints effects.
///
/// Discretization (paper eqs. 2a-2d, 3a-3b), with gamma = 2/(rho+1) - 1/2,
/// beta = 1/(rho+1)^2 and rho in [0, 1):
///   x_{n+1} = x_n + (1 - beta/gamma) h f_n + (beta/gamma) h f_{n+1} + (1/2 - beta/gamma) h^2 a_n
///   a_{n+1} = (f_{n+1} - f_n) / (h gamma) + (1 - 1/gamma) a_n
///   phi(x_{n+1}, u_{n+1}, t_{n+1}) <= 0,   bounds at t_{n+1},
/// with a_0 = df/dt(t_0) = f_x f + f_t from exact derivatives (algebraic inputs are taken as
/// stationary at t_0, du/dt = 0; a is restarted the same way after a control breakpoint).
/// Order: 2 in x (Lemma 1, Theorem 1); algebraic variables of active constraints of index
/// > 1 are first order (Lemma 3). Stability: A-stable; rho is the spectral radius of the
/// amplification matrix (eq. 12) at infinity (rho = 0: asymptotic annihilation).
///
/// Per step, a dense SQP (Gauss-Newton Hessian, exact Jacobians by automatic
/// differentiation, l1 merit function with backtracking, elastic mode when the linearized
/// constraints are inconsistent) solves the paper's local problem subject to (2a)-(2d), with J
/// = 0 (the paper's feasibility problem), the least change ||u - u_n||^2 or the distance
/// ||u - w(t_{n+1})||^2 to the user inputs (default). Its QP subproblems are solved by the
/// Goldfarb-Idnani dual active-set method. The working set of every QP (active path
/// constraints and state bounds) defines the basis matrix B of eq. (14), whose basic
/// algebraic columns are chosen by column pivoting for the least condition number; when the
/// scaled B (Sec. 6.1.1) has a singular value <= rank_tolerance (numerical rank deficiency,
/// typical of active constraints of index 3 at small steps), the step is retried with rho
/// lowered by 0.1 (Theorems 2-3: the smallest singular values grow), and with h = h_max once
/// rho = 0 (Sec. 7, Step 2b). Other failures retry from new initial guesses (Step 2c) until
/// max_retries is used up.
///
/// Step size. Without a fixed step (AlphaDaiOptions::step_size = 0, the default, as through
/// moreau::Simulate without h): error control by step doubling (Hairer, Norsett & Wanner,
/// "Solving Ordinary Differential Equations I", 1993, Sec. II.4): every step of length h is
/// also taken as two steps of h/2 from the same start, and the Richardson estimate
/// (x_{h/2,h/2} - x_h) / (2^2 - 1) of the order-2 method is the local error of the two half
/// steps, which are kept. Weighted per state by atol_i + rtol max(|x_n,i|, |x_{n+1},i|)
/// (atol = 0: atol_i = rtol times the largest |x_i| so far), it must stay below h / (tf - t0)
/// (error per unit step, as FESD and Radau IIA do, so that the error at tf is about rtol of
/// the solution's scale); while an index-3 constraint is active, the states its basic inputs
/// drive (velocities) are judged per step instead, as RADAU5 scales index-2 variables' error
/// by h (Hairer & Wanner, "Solving Ordinary Differential Equations II", 1996, Sec. VII.8):
/// the constraint fixes their integral, so their step errors do not add up. A step in which the
/// working set changes (an event: a constraint or bound becomes active or inactive; its local error
/// is only O(h)) is instead accepted only when h <= rtol (tf - t0), which locates the event time to
/// rtol of the horizon. The next step is h min(5, max(0.2, 0.9 err^{-1/2})); a step whose SQP fails
/// is retried with h/4 down to min_step_size. Active index-3 constraints are tested for rank
/// deficiency by the sensitivity of the active constraints to the basic algebraic inputs through
/// one step, S = C (I - c1 h A)^{-1} c1 h D + G with unit rows (independent of h for every index),
/// not by the scaled basis matrix, whose sigma_min is O(h) for index 3 (Sec. 6.1.1) and would
/// refuse every step below about 0.1.
/// With a fixed step h (step_size > 0): the paper's rule (Sec. 7, Step 2): h_i = sqrt(min{h^2,
/// h_{i-1}^2, ERRTOL / (2.25 max_{j <= i} ||a_j||_inf)}); ERRTOL = infinity gives fixed steps
/// h. Steps are shortened to end exactly on control breakpoints and on t_f (equal steps
/// within each segment). With estimate_error (default), every fixed step's error is estimated
/// by the same step doubling and summed into AlphaDaiStats::error_estimate, with a warning
/// when it exceeds kErrorWarningFactor rtol: a fixed-step answer is never silently wrong.
///
/// Assumptions: scaled units (states and algebraic inputs of order one; the rank test
/// compares singular values of the scaled basis matrix with an absolute tolerance);
/// x_0 within the state bounds; a DAI solution is in general not unique, and the one found
/// depends on the objective, rho and h. Scenes with other effects (moving sets, switching
/// surfaces, hysteresis relays) are refused.

#include <complex>
#include <limits>
#include <string>
#include <vector>

#include "moreau/integrators/simulation.hpp"
#include "moreau/model/events.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// The method's coefficients for a given rho (paper eqs. 3a-3b).
struct AlphaCoefficients {
  /// The regularization parameter in [0, 1).
  double rho = 0.0;
  double gamma = 1.5;  ///< 2/(rho+1) - 1/2
  double beta = 1.0;   ///< 1/(rho+1)^2
  /// Throws std::invalid_argument unless rho is in [0, 1).
  static AlphaCoefficients FromRho(double rho);
};

/// Amplification matrix of (2a-2b) on y' = lambda y for Omega = lambda h:
/// (y_{n+1}, h^2 a_{n+1}) = A(Omega) (y_n, h^2 a_n) (paper eq. 12), computed from the
/// coefficients in a form without cancellation for large |Omega|.
Eigen::Matrix2cd AlphaAmplificationMatrix(double rho, std::complex<double> omega);

/// The basis matrix B of paper eq. (14) for the unknowns (x_{n+1}, a_{n+1}, u_b) of one step:
///   [ I - (beta/gamma) h A      0   -(beta/gamma) h D ]
///   [ -A / (gamma h)            I   -D / (gamma h)    ]
///   [ C                         0    G                ]
/// with A = df/dx, D = df/du_b (basic algebraic columns), C = dg/dx and G = dg/du_b for the
/// active constraints g. Sizes: A m x m, D m x r, C r x m, G r x r (r may be 0).
Matrix AlphaBasisMatrix(const Matrix& a, const Matrix& d, const Matrix& c, const Matrix& g,
                        double h, double rho);
/// dB/drho of AlphaBasisMatrix (Theorem 3's B-dot up to sign), from the exact derivatives
/// d(beta/gamma)/drho = -4 (1 - rho) / ((rho+1)^2 (3-rho)^2) and d(1/gamma)/drho = 8/(3-rho)^2.
Matrix AlphaBasisMatrixRhoDerivative(const Matrix& a, const Matrix& d, const Matrix& c,
                                     const Matrix& g, double h, double rho);
/// The scaled basis matrix used for the rank test (Sec. 6.1.1): B with rows (13b) multiplied
/// by h^2, columns a divided by h^2 (unknown h^2 a) and u_b by h (unknown h u_b), and every
/// constraint row scaled to unit 2-norm. Its singular values are O(1), independent of h, for
/// active constraints of index <= 2, and O(h) for index 3.
Matrix AlphaScaledBasisMatrix(const Matrix& a, const Matrix& d, const Matrix& c, const Matrix& g,
                              double h, double rho);

/// Local objective J of the per-step problem (paper Sec. 7 and Remark 7.1); sums run over
/// the algebraic inputs.
enum class AlphaDaiObjective {
  kFeasibility,  ///< J = 0: the paper's constraint-satisfaction problem (each SQP step is the
                 ///< minimum-norm correction, so the point found is near the guess)
  kLeastChange,  ///< J = 1/2 sum_j (u_j - u_{n,j})^2: the feasible u closest to the previous
                 ///< one (a KKT point of this objective)
  kReference,    ///< J = 1/2 sum_j (u_j - w_j(t_{n+1}))^2 with w_j the input's signal (the
                 ///< paper's user input functions w(t), Sec. 2): u_j = w_j(t) unless an active
                 ///< constraint needs u_j
};
/// "feasibility", "least-change" or "reference".
std::string ToString(AlphaDaiObjective objective);
/// Parses "feasibility", "least-change" or "reference"; throws std::invalid_argument otherwise.
AlphaDaiObjective ParseAlphaDaiObjective(const std::string& name);

/// Options of the alpha-method DAI stepper (docs/alpha-method.md); defaults are the values below.
struct AlphaDaiOptions {
  /// Regularization parameter rho in [0, 1) (paper eq. 3): spectral radius at infinity;
  /// lowered by 0.1 per retry when the basis matrix is rank deficient.
  double rho = 0.5;
  /// Fixed step h > 0 (time units; the paper's h_max of the ERRTOL rule); 0 (the default): no
  /// fixed step, error-controlled steps (ErrorControlled()). The paper's examples use 0.1 to
  /// 0.5; with the default rank_tolerance, active index-3 constraints are numerically rank
  /// deficient in the scaled basis matrix for every rho at much smaller fixed steps.
  double step_size = 0.0;
  /// Error-controlled steps even with a step_size given (it is then the initial step).
  bool adaptive = false;
  /// Initial step of error-controlled runs, > 0; 0: step_size if positive, else automatic:
  /// (tf - t0) sqrt(rtol) (the order-2 error per unit step is then about rtol), at most h_max.
  double initial_step_size = 0.0;
  /// Tolerances of the error-controlled steps (see the file comment): rtol > 0; atol > 0 one
  /// absolute tolerance for every state, or 0 (the default): atol_i = rtol times the largest
  /// |x_i| of the run so far (initial value included), each state relative to its own scale.
  double relative_tolerance = kDefaultRelativeTolerance;
  double absolute_tolerance = 0.0;  ///< atol: > 0 for every state, 0 per state (see above)
  /// Largest error-controlled step, >= 0 (0: no bound but the segment).
  double max_step_size = 0.0;
  /// ERRTOL > 0 of the paper's step-size rule with a fixed step (units of x): h^2 <= ERRTOL /
  /// (2.25 max ||a_j||_inf). +infinity (default) disables the rule: fixed steps h, as in the
  /// paper's examples. Needs step_size > 0.
  double error_tolerance = std::numeric_limits<double>::infinity();
  /// Fixed steps: estimate every step's local error by step doubling (two more SQP solves per
  /// step) into AlphaDaiStats::error_estimate, with a warning in AlphaDaiResult::warnings
  /// above kErrorWarningFactor times relative_tolerance.
  bool estimate_error = true;
  /// Smallest step of the ERRTOL rule and of the error control, > 0; below it:
  /// AlphaDaiStatus::kStepSizeTooSmall (or the status of the failed step).
  double min_step_size = 1e-12;
  /// TOL of the paper: the path constraints must satisfy phi <= constraint_tolerance at every
  /// accepted step (units of phi), > 0. Bounds are enforced exactly.
  double constraint_tolerance = 1e-8;
  /// The discretized dynamics (2a) must hold with |residual_i| <= dynamics_tolerance
  /// (1 + |x_{n,i}|), > 0.
  double dynamics_tolerance = 1e-10;
  /// Stationarity of the local problem: ||grad J - J_c^T lambda||_inf <= optimality_tolerance
  /// at the accepted SQP iterate (dimensionless in scaled units), > 0.
  double optimality_tolerance = 1e-8;
  /// Cut-off on the singular values of the scaled basis matrix (AlphaScaledBasisMatrix):
  /// sigma_min <= rank_tolerance counts as numerical rank deficiency, in (0, 1). The default
  /// flags active index-3 constraints at steps of about 0.1 and below in scaled units.
  double rank_tolerance = 1e-2;
  /// MAXIT: SQP (major) iterations per try, >= 1. Each QP is limited to a number of
  /// active-set changes proportional to its size.
  int max_sqp_iterations = 50;
  /// MAXTRY: retries per step after the first try (rho reductions and new initial guesses),
  /// >= 0.
  int max_retries = 5;
  /// Local objective (see AlphaDaiObjective). The reference objective makes the algebraic
  /// inputs follow the scene's user input functions (zero where none are given) and leave them
  /// only where an active constraint needs them; kFeasibility is the paper's J = 0.
  AlphaDaiObjective objective = AlphaDaiObjective::kReference;
  /// Accepted steps before the run stops with kMaxStepsReached, >= 1.
  long max_steps = 10'000'000;
  /// Record every accepted step in the trajectory and the step certificates (false: only
  /// the initial and final points in the trajectory, no step records).
  bool record_trajectory = true;

  /// Whether the steps are error-controlled: adaptive, or no fixed step (step_size == 0).
  bool ErrorControlled() const { return adaptive || step_size == 0.0; }
  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of an alpha-method run; each value is documented by its criterion.
enum class AlphaDaiStatus {
  kSuccess,                ///< reached the final time
  kInfeasibleConstraints,  ///< at some step every try ended at a stationary point of the l1
                           ///< violation of (2a), phi <= 0 and the bounds with violation >
                           ///< the tolerances (elastic SQP: the linearized constraints could
                           ///< not reduce it), i.e. the constraints are locally infeasible
  kRegularizationFailed,   ///< the last try of a step had a scaled basis matrix with
                           ///< sigma_min <= rank_tolerance after rho was lowered as far as
                           ///< max_retries allowed (or to 0 with h = h_max)
  kRetriesExhausted,       ///< max_retries retries used and the SQP of the last try did not
                           ///< converge within max_sqp_iterations (or its line search failed)
  kStepSizeTooSmall,       ///< the ERRTOL rule or the error control needed h < min_step_size
  kMaxStepsReached,        ///< max_steps accepted steps before the final time
  kNonFinite,              ///< NaN or infinity in f or a at an accepted point
};
/// The status as text (snake case, as in summary.json).
std::string ToString(AlphaDaiStatus status);

/// Certificates of one accepted step.
struct AlphaDaiStep {
  double t = 0.0;  ///< t_{n+1}
  double h = 0.0;  ///< step length
  /// Step from the step-size rule (Sec. 7, Step 2; h_max after a regularization at rho = 0)
  /// before it is shortened to end on a control breakpoint or t_f (h <= h_rule).
  double h_rule = 0.0;
  double rho = 0.0;                   ///< rho used (after reductions)
  int tries = 1;                      ///< SQP solves for this step (1: first try succeeded)
  int sqp_iterations = 0;             ///< of the accepted try
  double constraint_violation = 0.0;  ///< max(0, max_i phi_i, bound violations)
  double dynamics_residual = 0.0;     ///< max_i |(2a)_i| / (1 + |x_{n,i}|)
  double acceleration_norm = 0.0;     ///< ||a_{n+1}||_inf (enters the step-size rule)
  double kkt_residual = 0.0;          ///< stationarity and complementarity of the local problem
  int num_active = 0;                 ///< r_a: active path constraints and state bounds
  int num_active_input_bounds = 0;    ///< algebraic inputs at a bound (non-basic)
  double basis_sigma_min = 0.0;       ///< smallest singular value of the scaled basis matrix
  double basis_condition = 0.0;       ///< its condition number sigma_max / sigma_min
  std::vector<int> active;            ///< indices into AlphaDaiResult::constraint_names
};

/// Counters and extreme certificates of an alpha-method run.
struct AlphaDaiStats {
  long num_steps = 0;           ///< accepted steps
  long num_tries = 0;           ///< SQP solves (first tries and retries)
  long num_rho_reductions = 0;  ///< retries with rho lowered (Step 2b)
  long num_guess_retries = 0;   ///< retries from new initial guesses (Step 2c)
  long num_rank_deficient = 0;  ///< tries stopped by a rank-deficient basis matrix
  long num_infeasible = 0;      ///< tries that ended locally infeasible
  /// SQP iterations of the accepted tries.
  long num_sqp_iterations = 0;
  long num_qp_iterations = 0;             ///< active-set changes in all QPs
  long num_elastic_qps = 0;               ///< QPs re-solved in elastic mode
  long num_jacobian_evaluations = 0;      ///< evaluations of f and phi with Jacobians
  long num_function_evaluations = 0;      ///< evaluations without Jacobians (line search)
  long num_basis_factorizations = 0;      ///< SVDs of basis matrices
  double max_constraint_violation = 0.0;  ///< over accepted steps
  double max_dynamics_residual = 0.0;     ///< over accepted steps
  double max_kkt_residual = 0.0;          ///< over accepted steps
  double min_basis_sigma = std::numeric_limits<double>::infinity();  ///< over accepted steps
  double min_rho = std::numeric_limits<double>::infinity();          ///< smallest rho used
  double min_step = std::numeric_limits<double>::infinity();         ///< smallest step taken
  /// Error control: steps rejected by the error test (per unit step), by the event rule
  /// (working set changed in a step longer than rtol (tf - t0)), and retried shorter because
  /// their SQP failed.
  long num_rejected_steps = 0;
  long num_event_rejections = 0;  ///< see num_rejected_steps
  long num_failed_steps = 0;      ///< see num_rejected_steps
  /// Estimated error of the run relative to the solution's scale: rtol sum_k (h_k / (tf - t0))
  /// err_k over the accepted (pairs of) steps, err_k the step-doubling estimate per unit step
  /// in the tolerance weights. -1 where not estimated (fixed steps without estimate_error).
  double error_estimate = -1.0;
  /// Fixed steps whose error could not be estimated (a half step failed); not in
  /// error_estimate.
  long num_unestimated_steps = 0;
  /// Path constraints inactive at both ends of a step are bounded over the step's continuous
  /// extension (interval arithmetic; docs/alpha-method.md, "Constraints between step ends"):
  /// steps in which a constraint was found above constraint_tolerance between the ends
  /// (error control: the step was retried ending on the crossing), ...
  long num_inside_crossings = 0;
  /// ... steps accepted although a constraint may exceed constraint_tolerance between their
  /// ends (fixed steps, which are not shortened; steps already at the event resolution rtol
  /// (tf - t0) or retried 8 times in a row; searches the bounds could not decide), with
  /// a warning in AlphaDaiResult::warnings naming the first time, ...
  long num_unresolved_crossings = 0;
  /// ... and the interval evaluations of the constraints this took.
  long num_bound_evaluations = 0;
  /// CPU time of the run.
  double cpu_seconds = 0.0;

  /// Sums counters and times; takes the max/min of the extreme values.
  AlphaDaiStats& operator+=(const AlphaDaiStats& other);
  /// One line for the command line's summary.
  std::string Summary() const;
};

/// Result of SimulateAlphaDai: status, final values, trajectory, per-step certificates, events and
/// statistics.
struct AlphaDaiResult {
  /// kSuccess, or why the run stopped.
  AlphaDaiStatus status = AlphaDaiStatus::kSuccess;
  std::string message;      ///< time and reason when status != kSuccess
  double final_time = 0.0;  ///< time reached
  Vector final_state;       ///< x at final_time
  Vector final_inputs;      ///< algebraic inputs u at final_time (scene order of algebraic inputs)
  Vector final_acceleration;  ///< the algorithmic variable a at final_time
  /// Accepted steps; `algebraic` holds the algebraic inputs (names: the inputs' names).
  Trajectory trajectory;
  /// Path constraints ("<effect>.<name>"), then state bounds ("<state>.lower"/".upper"),
  /// then input bounds ("<input>.lower"/".upper"); AlphaDaiStep::active indexes this list.
  std::vector<std::string> constraint_names;
  std::vector<AlphaDaiStep> steps;  ///< one per accepted step (with record_trajectory)
  std::vector<Event> events;        ///< kEnter/kLeave when constraints join/leave the working set
  /// Counters and extreme certificates.
  AlphaDaiStats stats;
  /// What the caller should know although the run succeeded (a fixed-step run whose estimated
  /// error exceeds kErrorWarningFactor rtol; steps in which a path constraint may exceed its
  /// tolerance between the ends, AlphaDaiStats::num_unresolved_crossings), one sentence each.
  std::vector<std::string> warnings;
};

/// Simulates `scene` over [t0, tf]. Throws std::invalid_argument for invalid options, an
/// invalid scene, an unsupported effect (naming it), an initial state outside the state
/// bounds, or path constraints that no algebraic input satisfies at t0 (inconsistent
/// initial values, with the violation found).
AlphaDaiResult SimulateAlphaDai(const Scene& scene, const AlphaDaiOptions& options,
                                const ProgressCallback& progress = {});

}  // namespace moreau
