#pragma once
/// @file
/// Optimal control of scenes by direct multiple shooting (or single shooting) with exact
/// sensitivities of the FESD integrator, solved by IPOPT (docs/ocp.md).
///
/// Problem (OcpProblem): a scene whose decision inputs are piecewise constant on N equal
/// intervals of its time axis,
///
///   min   Phi(x(T), T) + int_0^T L(x, u, t) dt
///   s.t.  the scene's dynamics and effects (sweeping, Filippov, hysteresis),
///         u_k in [u_lo, u_hi] on interval k,  free initial states within bounds,
///         g(x(T), T) = 0,  h(x(T), T) <= 0,  c(x_k, u_k, t_k) <= 0 at the grid points,
///
/// and, for free final times, a speed of time s_k in [s_lo, s_hi] per interval (the scene's
/// axis becomes numerical time, physical time t = clock runs at s; Scene::time_scale_input).
/// The running cost is integrated by a quadrature state appended to the scene (q' = L, scaled
/// like every physical rate), so T and L are in physical time.
///
/// Transcription: every interval is one FESD integration (N_fe finite elements, s stages;
/// switches inside intervals land on element boundaries). Multiple shooting takes the lowered
/// node states y_k = (x, q, relay memories, clock) as NLP variables with continuity
/// constraints y_{k+1} = Phi_k(y_k, u_k, s_k); single shooting chains the intervals. The
/// derivatives of Phi_k are FESD's exact sensitivities (implicit function theorem on the
/// converged element systems, switch-determined element lengths included): no finite
/// differences. IPOPT gets them as a sparse Jacobian (blocks per interval: memory linear in
/// N) and a Hessian approximation (OcpOptions::hessian): IPOPT's L-BFGS, or a block-structured
/// one: per interval a quasi-Newton
/// approximation of the curvature of lambda_k^T Phi_k from these first derivatives, and the
/// exact second derivatives (automatic differentiation) of the terminal and path functions.
///
/// Homotopy (OcpOptions::homotopy): a sequence of easier problems, each warm-started (primal
/// and dual) from the previous one, ending on the exact transcription: smoothed dynamics
/// (every complementarity pair a b = mu^2 instead of 0 <= a ⟂ b >= 0, integrated by the
/// time-stepping scheme, so that contacts act at a distance and the NLP is smooth) and relaxed
/// terminal equalities |g| <= eps (docs/ocp.md, "Homotopy").
///
/// Verification: the optimal controls (in physical time) are re-simulated by IDA at
/// rtol = 1e-12 and by FESD on a fine grid, and the terminal-constraint error of those
/// simulations is reported; a solve whose re-simulations both end farther from its x(T) than
/// kOcpVerificationTolerance is OcpStatus::kNotVerified, not solved.

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "moreau/core/smooth_function.hpp"
#include "moreau/core/types.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "moreau/model/events.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// An optimal control problem (see file comment). Functions take (x, u, t, p) like scene
/// functions: x the scene states (without the quadrature state), u all scene inputs, t the
/// physical time, p the scene parameters.
struct OcpProblem {
  /// The problem's name (output directories, messages).
  std::string name;
  /// One line for `moreau list`.
  std::string description;
  /// The dynamics, effects, horizon, inputs and parameters.
  Scene scene;
  /// N >= 1 control intervals of equal length on [initial_time, final_time] of the scene.
  int intervals = 10;
  /// Indices of the scene's control inputs that are decisions (piecewise constant, bounds
  /// InputSpec::lower/upper, initial guess the signal's first value). Other inputs keep their
  /// signals.
  std::vector<int> controls;
  /// Optional initial guess of the controls: N rows, one column per decision control (empty:
  /// every interval starts from the signal's first value).
  Matrix initial_controls;
  /// Initial states that are decisions (the others are the scene's x0).
  struct FreeInitialState {
    /// Index of the state in x.
    int state = 0;
    /// Lower bound of its initial value.
    double lower = -1e20;
    /// Upper bound of its initial value.
    double upper = 1e20;
  };
  /// The initial states that are decisions.
  std::vector<FreeInitialState> free_initial_states;
  SmoothFunction running_cost;           ///< L: 1 output (empty: none)
  SmoothFunction terminal_cost;          ///< Phi at (x(T), u_{N-1}, T): 1 output (empty: none)
  SmoothFunction terminal_equalities;    ///< g(x(T), u_{N-1}, T) = 0 (empty: none)
  SmoothFunction terminal_inequalities;  ///< h(x(T), u_{N-1}, T) <= 0 (empty: none)
  /// c(x_k, u_k, t_k) <= 0 at the grid points k = 0..N (u_N := u_{N-1}) (empty: none).
  SmoothFunction path_constraints;
  /// Free final time: a speed of time per interval (a control input is added to the scene).
  struct SpeedOfTime {
    /// True for a free final time.
    bool enabled = false;
    /// Lower bound of the speed of time s (> 0).
    double lower = 0.1;
    /// Upper bound of the speed of time.
    double upper = 10.0;
    /// Initial guess of the speed on every interval.
    double initial_guess = 1.0;
  };
  /// The speed of time (free final time), disabled by default.
  SpeedOfTime speed;
};

/// Throws std::invalid_argument naming the first problem found (unknown indices, function
/// output sizes, bounds, an invalid scene).
void ValidateOcp(const OcpProblem& problem);

/// The transcription (docs/ocp.md, "Transcription").
enum class OcpTranscription {
  kMultipleShooting,  ///< FESD per interval, node states as variables (the default)
  kSingleShooting,    ///< FESD chained over the intervals
  /// The FESD equations as NLP constraints: stage states, moving-set multipliers and element
  /// lengths are variables, complementarity is relaxed (Scholtes) on the homotopy levels and
  /// exact on the last level, whose pieces (per element, which constraints are active) come
  /// from the last relaxed solution. Moving sets only (sweeping processes), no speed of time.
  kCollocation,
};
/// "multiple_shooting", "single_shooting" or "collocation".
std::string ToString(OcpTranscription transcription);
/// Parses the names of ToString; throws std::invalid_argument otherwise.
OcpTranscription ParseOcpTranscription(const std::string& name);

/// The discretization of every control interval.
enum class OcpIntegrator {
  kFesd,          ///< FESD Radau IIA: switches on element boundaries (the default)
  kTimeStepping,  ///< standard time-stepping, N_fe fixed steps: for comparisons only (its
                  ///< NLP is only piecewise smooth in the controls; no hysteresis, no free T)
};
/// "fesd" or "timestepping".
std::string ToString(OcpIntegrator integrator);
/// Parses the names of ToString; throws std::invalid_argument otherwise.
OcpIntegrator ParseOcpIntegrator(const std::string& name);

/// Second-order information for IPOPT (docs/ocp.md, "Second-order information").
enum class OcpHessian {
  /// IPOPT's limited-memory BFGS of the whole Lagrangian (hessian_approximation
  /// limited-memory).
  kLimitedMemory,
  /// The Lagrangian's block structure: per shooting interval k a damped (Powell) BFGS
  /// approximation of the Hessian of lambda_k^T Phi_k(y_k, u_k) over the interval's variables,
  /// updated from the exact first derivatives at successive iterates; plus the exact Hessians
  /// (automatic differentiation) of the terminal cost, the terminal constraints and the path
  /// constraints. Single shooting has one block over all variables (no exact part).
  kBlockBfgs,
  /// As kBlockBfgs with symmetric rank-one updates (may be indefinite; IPOPT corrects the
  /// inertia).
  kBlockSr1,
  /// Collocation transcription only: the Hessian of the Lagrangian from the exact second
  /// derivatives (automatic differentiation) of the dynamics, the moving-set constraints, the
  /// costs and the terminal and path constraints, except one term: the (x, t) curvature of
  /// Lambda^T grad_x c(x, t) P w in the collocation equations, which needs third derivatives
  /// of c, is left out (zero for constraints quadratic in x and independent of t).
  kSecondOrder,
};
/// The name as the command line's --hessian takes it.
std::string ToString(OcpHessian hessian);
/// Parses the names of ToString; throws std::invalid_argument otherwise.
OcpHessian ParseOcpHessian(const std::string& name);

/// One level of a homotopy (OcpOptions::homotopy): an easier problem solved before the exact
/// one: smoothed dynamics, relaxed terminal equalities, other values of scene parameters
/// (natural-parameter continuation), or a combination.
struct OcpHomotopyLevel {
  /// mu >= 0. With mu > 0 every interval is integrated by the time-stepping scheme
  /// (OcpOptions::finite_elements fixed Radau IIA steps) with smoothed complementarity
  /// a b = mu^2 (a, b > 0) at every stage (Kanzow's smoothed Fischer-Burmeister function):
  /// constraints push at a distance and the shooting map is smooth. Needs a scene the
  /// time-stepping scheme supports (moving sets, switching surfaces; no hysteresis, no free
  /// final time). 0: the transcription's own integrator, unsmoothed.
  double smoothing = 0.0;
  /// eps >= 0: the terminal equalities are imposed as -eps <= g <= eps. 0: g = 0.
  double relaxation = 0.0;
  /// Scene parameters (by name) and their values on this level; the others, and every
  /// parameter on the exact level, keep the problem's values.
  std::vector<std::pair<std::string, double>> parameters;
  /// sigma >= 0, collocation transcription only: the complementarity products of every
  /// element and constraint are relaxed to <= sigma (Scholtes). Every level of the
  /// collocation transcription needs sigma > 0; the exact level is sigma = 0 with the pieces
  /// fixed.
  double complementarity = 0.0;
};

/// Multipliers of an NLP solution (IPOPT's sign conventions), for warm starts.
struct OcpMultipliers {
  Vector constraints;   ///< one per NLP constraint
  Vector lower_bounds;  ///< one per NLP variable (z_L >= 0)
  Vector upper_bounds;  ///< one per NLP variable (z_U >= 0)
  /// True if no multipliers are held (a cold start).
  bool empty() const { return constraints.size() == 0; }
};

/// Progress report, after every IPOPT iteration of every level.
struct OcpProgress {
  int level = 0;   ///< 0-based; levels - 1 is the exact problem
  int levels = 1;  ///< homotopy levels + 1
  int stages = 0;  ///< Radau IIA stages of the transcription solved (refinement: more)
  /// The values of the level being solved.
  OcpHomotopyLevel parameters;
  int iteration = 0;  ///< IPOPT's iteration counter within the level
  /// Objective at the iterate.
  double objective = 0.0;
  /// Constraint violation at the iterate (IPOPT's inf_pr).
  double primal_infeasibility = 0.0;
  /// Dual infeasibility at the iterate (IPOPT's inf_du).
  double dual_infeasibility = 0.0;
};

/// Options of SolveOcp (docs/ocp.md); defaults are the values below.
struct OcpOptions {
  /// The transcription (multiple shooting by default).
  OcpTranscription transcription = OcpTranscription::kMultipleShooting;
  /// The integrator of every control interval (FESD by default).
  OcpIntegrator integrator = OcpIntegrator::kFesd;
  /// Per interval: Radau IIA stages and finite elements (FESD; the step is the interval) or
  /// fixed steps (time-stepping); the other integrator settings are their defaults.
  int stages = 3;
  /// Finite elements (FESD) or fixed steps (time-stepping) per control interval.
  int finite_elements = 3;
  /// IPOPT: convergence tolerance of the exact (last) level (tol, also used as
  /// constr_viol_tol), iterations per level, log level (0: silent, 5: IPOPT's default output
  /// on stdout).
  double tolerance = 1e-10;
  /// IPOPT iterations allowed per level.
  int max_iterations = 1000;
  /// IPOPT's output level (0: silent).
  int print_level = 0;
  /// Second-order information (docs/ocp.md, "Second-order information": measured on the
  /// example problems, IPOPT's limited-memory BFGS is the most robust).
  OcpHessian hessian = OcpHessian::kLimitedMemory;
  /// Quasi-Newton history: IPOPT's limited-memory BFGS pairs (kLimitedMemory); the block
  /// updates rebuild every block from its last this many pairs.
  int lbfgs_memory = 20;
  /// IPOPT's permanent regularization of the constraint linearization (perturb_always_cd):
  /// the KKT systems get -delta_c I in the constraint block at every iteration instead of
  /// only after a wrong inertia. Keeps the multipliers bounded when the constraint Jacobian
  /// is rank deficient at the solution (the wave-rider's x1(T) = 1, docs/ocp.md).
  bool regularize_constraints = true;
  /// Homotopy levels solved, in order, before the exact problem (empty: the exact problem
  /// only). Each level starts from the previous level's primal-dual solution.
  std::vector<OcpHomotopyLevel> homotopy;
  /// IPOPT tolerance of the homotopy levels (their solutions are only starting points).
  double level_tolerance = 1e-6;
  /// Collocation transcription, relaxed levels: weight w of the penalty
  /// w / N sum_k,n ((h_kn - H/N_fe) / (H/N_fe))^2 that keeps element lengths near equal where
  /// nothing switches (where lengths are otherwise free); the exact level imposes equal
  /// lengths between switches instead. >= 0.
  double step_equilibration_weight = 1e-2;
  /// Collocation transcription: also require c >= 0 at s check points per element, midway
  /// between consecutive collocation nodes of the collocation polynomial (on inactive
  /// pieces), so that a trajectory cannot pass through a constraint between the nodes (a
  /// discrete optimum that "tunnels" through a wall is not a trajectory of the dynamics).
  bool collocation_check_points = true;
  /// Collocation transcription: after the exact level, solve it again from its solution with
  /// the same pieces and, per element and inactive (free) constraint m, the minimum over the
  /// element of c_m(X(theta), t(theta)) / phi(theta) >= 0 instead of the check points (X the
  /// collocation polynomial, theta in [0, 1]; phi = 1, or the distance to an end that an
  /// active neighbour pins to c_m = 0). The minimiser is located at every evaluation; the
  /// row's gradient at fixed minimiser is exact (envelope theorem) and the second-order
  /// Hessian includes the minimiser's dependence. Without it an optimum can cut a corner
  /// between the check points, and its controls then produce a contact the NLP does not have
  /// (docs/ocp.md, "Collocation transcription" and "Doorway").
  bool collocation_element_minima = true;
  /// Collocation transcription: 0 (no refinement), or S with stages < S <= kMaxRadauStages:
  /// after the exact level (and its element-minima solve) succeeds, solve the exact level
  /// once more on the transcription with S Radau IIA stages per element (order 2S - 1
  /// instead of 2s - 1; same N, N_fe, pieces and element minima), started from the solution
  /// interpolated onto it (the collocation polynomials at the new nodes, element lengths and
  /// controls as they are, IPOPT's multipliers where a row or bound exists in both). If it
  /// solves, the result (decision, multipliers, trajectory) is that of the refined
  /// transcription, so a warm start from it needs stages = S; if not, the s-stage solution is
  /// returned with its status, the message says so and OcpResult::levels holds the
  /// refinement's outcome. Reduces the discretization error of the NLP's trajectory against
  /// the re-simulation of its controls (docs/ocp.md, "Doorway"). The shooting transcriptions
  /// ignore it.
  int collocation_refinement_stages = 0;
  /// IPOPT's relative relaxation of variable bounds (bound_relax_factor); the solution may
  /// exceed a bound by this fraction, never more (it is returned as converged, not clipped).
  double bound_relaxation = 1e-12;
  /// Mesh continuation (shooting): interval counts solved first, coarsest first (increasing;
  /// counts >= OcpProblem::intervals are skipped, so one list serves every N). The first is
  /// solved with every homotopy level; each later count, and finally the problem's N, starts
  /// from the previous solution prolongated (fine interval k takes the decisions of the coarse
  /// interval containing its midpoint; node states by forward simulation) and solves the
  /// exact problem only (docs/ocp.md, "Scaling in N"). Empty: no continuation.
  std::vector<int> mesh_continuation;
  /// Warm start: a previous OcpResult::decision (same problem and transcription); empty for a
  /// cold start from the initial guesses and a forward simulation. With
  /// warm_start_multipliers (a previous OcpResult::multipliers) IPOPT starts from the
  /// primal-dual point.
  Vector warm_start;
  /// Their multipliers (a previous OcpResult::multipliers), or empty.
  OcpMultipliers warm_start_multipliers;
  /// Re-simulate the optimal controls with IDA (reference settings) and report the
  /// terminal-constraint error.
  bool verify = true;
  /// Progress: called after every IPOPT iteration (may be empty).
  std::function<void(const OcpProgress&)> progress;

  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Largest gap between the optimum's x(T) and a verification re-simulation of its controls
/// for which the result counts as solved: |x_sim(T) - x(T)|_inf <= this times
/// max(1, |x(T)|_inf), for the closer of the two re-simulations (IDA at its reference
/// settings, FESD on a grid ten times finer than the controls'). The default accuracy of a
/// simulation (docs/accuracy.md): an optimum whose own trajectory is not reproduced to it
/// is an optimum of the discretization, not of the problem.
inline constexpr double kOcpVerificationTolerance = 1e-5;

/// Outcome of an OCP solve; the criterion is IPOPT's (tol on the scaled KKT error), and with
/// OcpOptions::verify the re-simulation of the controls (kOcpVerificationTolerance).
enum class OcpStatus {
  kSolved,              ///< IPOPT: optimal solution found (and verified, with verify)
  kSolvedToAcceptable,  ///< IPOPT: solved to its acceptable tolerances (and verified)
  kInfeasible,          ///< IPOPT: locally infeasible
  kMaxIterations,       ///< IPOPT: iteration limit
  kSimulationFailure,   ///< an interval integration failed at the initial point
  kSolverFailure,       ///< any other IPOPT failure (the message names it)
  kNotVerified,         ///< IPOPT solved the NLP (solved or acceptable), but no re-simulation
                        ///< of its controls ends within kOcpVerificationTolerance of its x(T)
                        ///< (OcpResult::verification_gap; infinite if none succeeded): the
                        ///< discretization is too coarse for the trajectory it claims
};
/// The status as text (snake case, as in summary.json).
std::string ToString(OcpStatus status);

/// One IPOPT iteration.
struct OcpIteration {
  int level = 0;  ///< homotopy level (the last one is the exact problem)
  /// IPOPT's iteration counter within the level.
  int iteration = 0;
  /// Objective at the iterate.
  double objective = 0.0;
  /// Constraint violation (IPOPT's inf_pr).
  double primal_infeasibility = 0.0;
  /// Dual infeasibility (IPOPT's inf_du).
  double dual_infeasibility = 0.0;
};

/// One level of the solve (the homotopy levels, then the exact problem).
struct OcpLevelResult {
  OcpHomotopyLevel parameters;  ///< (0, 0, none) for the exact problem
  int intervals = 0;            ///< N of this level (mesh continuation)
  int stages = 0;               ///< Radau IIA stages s of this level's transcription (refinement)
  /// How the level ended.
  OcpStatus status = OcpStatus::kSolverFailure;
  std::string message;  ///< IPOPT's return status
  /// IPOPT iterations of the level.
  int iterations = 0;
  /// Objective at the level's solution.
  double objective = 0.0;
  /// CPU time of the level (this thread's, not elapsed time).
  double seconds = 0.0;
};

/// Counters and sizes of an OCP solve.
struct OcpStats {
  int iterations = 0;    ///< IPOPT iterations, all levels
  long simulations = 0;  ///< interval integrations (each with sensitivities)
  /// FESD finite elements of all interval integrations.
  long fesd_elements = 0;
  /// CPU time of the solve (this thread's, not elapsed time).
  double cpu_seconds = 0.0;
  /// CPU time of the verification re-simulations.
  double verification_seconds = 0.0;
  /// Memory of the NLP's derivative data: structural nonzeros of the constraint Jacobian
  /// and of the Hessian approximation (lower triangle; 0 for limited memory).
  long jacobian_nonzeros = 0;
  /// Structural nonzeros of the Hessian approximation (lower triangle; 0 for limited memory).
  long hessian_nonzeros = 0;
};

/// Result of SolveOcp: the status, the optimal controls and states, the solver's log and the
/// verification by re-simulation.
struct OcpResult {
  /// Status of the exact (last) level; the homotopy levels are in `levels`.
  OcpStatus status = OcpStatus::kSolverFailure;
  /// IPOPT's return status or the failure's reason.
  std::string message;
  /// Objective at the returned point.
  double objective = 0.0;
  Vector decision;                       ///< the NLP variables (for warm starts)
  OcpMultipliers multipliers;            ///< their multipliers (for warm starts)
  Vector initial_state;                  ///< x0 (free components optimized)
  Matrix controls;                       ///< N x (number of decision controls)
  Vector speeds;                         ///< N speeds of time (free final time), else empty
  std::vector<double> grid;              ///< physical times of the grid points (N + 1)
  std::vector<Vector> node_states;       ///< x at the grid points (N + 1)
  double final_time = 0.0;               ///< physical T
  Vector final_state;                    ///< x(T) of the discretized optimum
  double running_cost = 0.0;             ///< int L dt at the optimum (0 without L)
  double terminal_equality_error = 0.0;  ///< max |g| at the discretized optimum
  /// Collocation transcription: the largest |cross-complementarity product| of the returned
  /// point over elements and constraints (0 up to the constraint tolerance on a solved exact
  /// level); -1 for the shooting transcriptions, where the integrator enforces it.
  double complementarity_residual = -1.0;
  Trajectory trajectory;            ///< FESD at the optimum, physical time
  std::vector<Event> events;        ///< switches of that trajectory
  std::vector<RelaySignal> relays;  ///< relay memories of that trajectory
  /// Every IPOPT iteration of every level.
  std::vector<OcpIteration> log;
  /// One entry per level (homotopy levels, then the exact problem).
  std::vector<OcpLevelResult> levels;
  /// Verification by re-simulation (IDA at rtol 1e-12, controls piecewise constant in
  /// physical time): x(T) of the re-simulation, max(|g|, h^+) there, and |x_sim(T) - x(T)|.
  bool verified = false;
  /// Why the IDA re-simulation failed (empty if verified).
  std::string verification_message;
  /// x(T) of the IDA re-simulation.
  Vector resimulated_final_state;
  /// max(|g|, h^+) of the terminal constraints at the re-simulated x(T).
  double resimulated_terminal_error = 0.0;
  /// |x_sim(T) - x(T)| (infinity norm).
  double resimulated_state_difference = 0.0;
  /// The same by FESD with switch detection (s = 3, 3 elements, steps a tenth of a control
  /// interval), a second reference where IDA's is unreliable (docs/ocp.md, "Verification").
  bool fesd_verified = false;
  /// Why the FESD re-simulation failed (empty if verified).
  std::string fesd_verification_message;
  /// x(T) of the FESD re-simulation.
  Vector fesd_resimulated_final_state;
  /// max(|g|, h^+) at the FESD-re-simulated x(T).
  double fesd_resimulated_terminal_error = 0.0;
  /// |x_fesd(T) - x(T)| (infinity norm).
  double fesd_resimulated_state_difference = 0.0;
  /// With verify: the smaller of the two re-simulations' |x_sim(T) - x(T)|_inf (infinity if
  /// neither succeeded); above kOcpVerificationTolerance max(1, |x(T)|_inf) a solved status
  /// becomes kNotVerified. -1 without verification.
  double verification_gap = -1.0;
  /// Counters and sizes.
  OcpStats stats;
};

/// Solves the problem. Throws std::invalid_argument for an invalid problem or options.
OcpResult SolveOcp(const OcpProblem& problem, const OcpOptions& options = {});

/// The NLP of the transcription, for solvers and tests: variables, bounds and constraint
/// bounds, the objective, the constraints and their exact first derivatives (a sparse
/// Jacobian), and the Hessian approximation of OcpOptions::hessian. Layout in docs/ocp.md.
class ShootingNlp {
 public:
  /// The NLP of `problem` with `options` (validated; throws std::invalid_argument).
  ShootingNlp(const OcpProblem& problem, const OcpOptions& options);
  ~ShootingNlp();
  ShootingNlp(const ShootingNlp&) = delete;
  ShootingNlp& operator=(const ShootingNlp&) = delete;

  /// Number of NLP variables.
  int num_variables() const;
  /// Number of NLP constraints.
  int num_constraints() const;
  /// Lower bounds of the variables.
  const Vector& variable_lower() const;
  /// Upper bounds of the variables.
  const Vector& variable_upper() const;
  /// Constraint bounds of the current level (relaxed terminal equalities: [-eps, eps]).
  const Vector& constraint_lower() const;
  /// Upper constraint bounds of the current level.
  const Vector& constraint_upper() const;
  /// Selects the problem of a homotopy level (default: the exact problem, (0, 0), the
  /// problem's parameters). Throws std::invalid_argument if the scene does not allow
  /// smoothing (see OcpHomotopyLevel) or has no parameter of a given name.
  void SetLevel(const OcpHomotopyLevel& level);
  /// The level selected last.
  const OcpHomotopyLevel& level() const;
  /// The initial guess: controls and speeds from the problem, node states from a forward
  /// simulation with them.
  Vector InitialGuess();
  /// Objective, constraints and (with non-null outputs) the objective gradient and the
  /// constraint Jacobian's values in JacobianStructure() order. Returns false with a message
  /// if an interval integration fails (the NLP is not defined there).
  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Vector* jacobian_values, std::string* message);
  /// Structural nonzeros of the constraint Jacobian (row, column): dense blocks per interval
  /// (multiple shooting; linear in N) or per constraint group (single shooting).
  const std::vector<std::pair<int, int>>& JacobianStructure() const;
  /// The Jacobian as a sparse matrix from values in JacobianStructure() order.
  SparseMatrix JacobianMatrix(const Vector& jacobian_values) const;
  /// Structural nonzeros (row >= column) of the Hessian approximation (empty for
  /// OcpHessian::kLimitedMemory).
  const std::vector<std::pair<int, int>>& HessianStructure() const;
  /// Values (HessianStructure() order) of the approximation of the Hessian of
  /// objective_factor * f + lambda^T c at z. Stateful: at a point other than the previous
  /// call's, the quasi-Newton blocks are first updated with the step between the two points
  /// (the previous call's Jacobian values are kept for that). `jacobian_values` and
  /// `gradient` are Evaluate's at z. Returns false if the exact parts cannot be evaluated.
  bool HessianApproximation(const Vector& z, double objective_factor, const Vector& lambda,
                            const Vector& gradient, const Vector& jacobian_values,
                            Vector* hessian_values);
  /// Forgets the quasi-Newton updates (blocks back to their initial scaling).
  void ResetHessian();
  /// Unpacks a solution into the result fields (controls, grid, node states, trajectory),
  /// re-integrating with the exact integrator.
  void Describe(const Vector& z, OcpResult* result);
  /// The point with these decisions (N rows: the controls, then the speed of time; clamped to
  /// their bounds) and free initial states, node states from a forward simulation.
  Vector PointFromDecisions(const Matrix& decisions, const Vector& free_initial);
  /// Interval integrations so far.
  long simulations() const;
  /// FESD finite elements of those integrations.
  long fesd_elements() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace moreau
