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
/// differences. IPOPT uses exact first derivatives and a limited-memory Hessian.
///
/// Verification: the optimal controls (in physical time) are re-simulated by IDA at
/// rtol = 1e-12 and the terminal-constraint error of that simulation is reported.

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
  std::string name;
  std::string description;
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
    int state = 0;
    double lower = -1e20;
    double upper = 1e20;
  };
  std::vector<FreeInitialState> free_initial_states;
  SmoothFunction running_cost;           ///< L: 1 output (empty: none)
  SmoothFunction terminal_cost;          ///< Phi at (x(T), u_{N-1}, T): 1 output (empty: none)
  SmoothFunction terminal_equalities;    ///< g(x(T), u_{N-1}, T) = 0 (empty: none)
  SmoothFunction terminal_inequalities;  ///< h(x(T), u_{N-1}, T) <= 0 (empty: none)
  /// c(x_k, u_k, t_k) <= 0 at the grid points k = 0..N (u_N := u_{N-1}) (empty: none).
  SmoothFunction path_constraints;
  /// Free final time: a speed of time per interval (a control input is added to the scene).
  struct SpeedOfTime {
    bool enabled = false;
    double lower = 0.1;
    double upper = 10.0;
    double initial_guess = 1.0;
  };
  SpeedOfTime speed;
};

/// Throws std::invalid_argument naming the first problem found (unknown indices, function
/// output sizes, bounds, an invalid scene).
void ValidateOcp(const OcpProblem& problem);

enum class OcpTranscription { kMultipleShooting, kSingleShooting };
std::string ToString(OcpTranscription transcription);
OcpTranscription ParseOcpTranscription(const std::string& name);

/// The discretization of every control interval.
enum class OcpIntegrator {
  kFesd,          ///< FESD Radau IIA: switches on element boundaries (the default)
  kTimeStepping,  ///< standard time-stepping, N_fe fixed steps: for comparisons only (its
                  ///< NLP is only piecewise smooth in the controls; no hysteresis, no free T)
};
std::string ToString(OcpIntegrator integrator);
OcpIntegrator ParseOcpIntegrator(const std::string& name);

struct OcpOptions {
  OcpTranscription transcription = OcpTranscription::kMultipleShooting;
  OcpIntegrator integrator = OcpIntegrator::kFesd;
  /// Per interval: Radau IIA stages and finite elements (FESD; the step is the interval) or
  /// fixed steps (time-stepping); the other integrator settings are their defaults.
  int stages = 3;
  int finite_elements = 3;
  /// IPOPT: convergence tolerance (tol, also used as constr_viol_tol), iterations, log level
  /// (0: silent, 5: IPOPT's default output on stdout).
  double tolerance = 1e-10;
  int max_iterations = 1000;
  int print_level = 0;
  /// Limited-memory Hessian history.
  int lbfgs_memory = 20;
  /// IPOPT's relative relaxation of variable bounds (bound_relax_factor); the solution may
  /// exceed a bound by this fraction, never more (it is returned as converged, not clipped).
  double bound_relaxation = 1e-12;
  /// Warm start: a previous OcpResult::decision (same problem and transcription); empty for a
  /// cold start from the initial guesses and a forward simulation.
  Vector warm_start;
  /// Re-simulate the optimal controls with IDA (reference settings) and report the
  /// terminal-constraint error.
  bool verify = true;
  /// Progress: called after every IPOPT iteration (may be empty).
  std::function<void(int iteration, double objective, double infeasibility)> progress;

  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of an OCP solve; the criterion is IPOPT's (tol on the scaled KKT error).
enum class OcpStatus {
  kSolved,              ///< IPOPT: optimal solution found
  kSolvedToAcceptable,  ///< IPOPT: solved to its acceptable tolerances
  kInfeasible,          ///< IPOPT: locally infeasible
  kMaxIterations,       ///< IPOPT: iteration limit
  kSimulationFailure,   ///< an interval integration failed at the initial point
  kSolverFailure,       ///< any other IPOPT failure (the message names it)
};
std::string ToString(OcpStatus status);

/// One IPOPT iteration.
struct OcpIteration {
  int iteration = 0;
  double objective = 0.0;
  double primal_infeasibility = 0.0;
  double dual_infeasibility = 0.0;
};

struct OcpStats {
  int iterations = 0;
  long simulations = 0;  ///< FESD interval integrations (each with sensitivities)
  long fesd_elements = 0;
  double cpu_seconds = 0.0;
  double verification_seconds = 0.0;
};

struct OcpResult {
  OcpStatus status = OcpStatus::kSolverFailure;
  std::string message;
  double objective = 0.0;
  Vector decision;                       ///< the NLP variables (for warm starts)
  Vector initial_state;                  ///< x0 (free components optimized)
  Matrix controls;                       ///< N x (number of decision controls)
  Vector speeds;                         ///< N speeds of time (free final time), else empty
  std::vector<double> grid;              ///< physical times of the grid points (N + 1)
  std::vector<Vector> node_states;       ///< x at the grid points (N + 1)
  double final_time = 0.0;               ///< physical T
  Vector final_state;                    ///< x(T) of the discretized optimum
  double running_cost = 0.0;             ///< int L dt at the optimum (0 without L)
  double terminal_equality_error = 0.0;  ///< max |g| at the discretized optimum
  Trajectory trajectory;                 ///< FESD at the optimum, physical time
  std::vector<Event> events;             ///< switches of that trajectory
  std::vector<RelaySignal> relays;       ///< relay memories of that trajectory
  std::vector<OcpIteration> log;
  /// Verification by re-simulation (IDA at rtol 1e-12, controls piecewise constant in
  /// physical time): x(T) of the re-simulation, max(|g|, h^+) there, and |x_sim(T) - x(T)|.
  bool verified = false;
  std::string verification_message;
  Vector resimulated_final_state;
  double resimulated_terminal_error = 0.0;
  double resimulated_state_difference = 0.0;
  OcpStats stats;
};

/// Solves the problem. Throws std::invalid_argument for an invalid problem or options.
OcpResult SolveOcp(const OcpProblem& problem, const OcpOptions& options = {});

/// The NLP of the transcription, for solvers and tests: variables, bounds and constraint
/// bounds, and an evaluation of the objective, the constraints and their exact first
/// derivatives (dense). Layout in docs/ocp.md.
class ShootingNlp {
 public:
  ShootingNlp(const OcpProblem& problem, const OcpOptions& options);
  ~ShootingNlp();
  ShootingNlp(const ShootingNlp&) = delete;
  ShootingNlp& operator=(const ShootingNlp&) = delete;

  int num_variables() const;
  int num_constraints() const;
  const Vector& variable_lower() const;
  const Vector& variable_upper() const;
  const Vector& constraint_lower() const;
  const Vector& constraint_upper() const;
  /// The initial guess: controls and speeds from the problem, node states from a forward
  /// simulation with them.
  Vector InitialGuess();
  /// Objective, constraints and (with non-null outputs) their gradients. Returns false with a
  /// message if an interval integration fails (the NLP is not defined there).
  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Matrix* jacobian, std::string* message);
  /// Structural nonzeros of the constraint Jacobian (row, column), row-major by block.
  const std::vector<std::pair<int, int>>& JacobianStructure() const;
  /// Unpacks a solution into the result fields (controls, grid, node states, trajectory).
  void Describe(const Vector& z, OcpResult* result);
  long simulations() const;
  long fesd_elements() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace moreau
