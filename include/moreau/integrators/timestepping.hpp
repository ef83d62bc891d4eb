#pragma once
/// @file
/// Standard (fixed-step) Radau IIA time-stepping for dynamic complementarity systems:
/// the first-order baseline that FESD is measured against.
///
/// Method: the scene is lowered to y' = F(y, z), 0 = G(y, z), 0 <= A ⟂ B >= 0
/// (LoweredSystem; moving sets in gradient form, switching surfaces in Stewart's or the
/// Heaviside step form). Each step of fixed length h solves the s-stage Radau IIA collocation
/// equations with complementarity imposed at every stage only,
///   Z_i - h sum_j a_ij F(y_n + Z_j, z_j) = 0,  G(Y_i, z_i) = 0,  0 <= A(Y_i, z_i) ⟂ B(Y_i, z_i) >=
///   0,
/// by the semismooth Newton method on the Fischer-Burmeister reformulation.
/// There is no switch detection: a switch inside a step is smeared over the step, so the
/// global error is O(h) across switches whatever s is (Radau IIA order 2s - 1 on smooth
/// phases only), and derivatives of the result with respect to initial values or
/// parameters do not account for the switch times. Events are reported at the end of the
/// step in which a pair changed status (resolution h). A free side that crosses zero and
/// back between the nodes of one step (found on the step's collocation polynomial by the
/// crossing search of FESD, with bounds from the model functions) is not resolved: the run
/// warns (TimeSteppingResult::warnings) and a smaller h resolves it.
///
/// Effects supported: moving sets and switching surfaces. Hysteresis relays and path
/// constraints are refused (use fesd/ida and alpha, respectively).

#include <memory>
#include <string>
#include <vector>

#include "moreau/integrators/simulation.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/model/scene.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau {

namespace internal {
struct TimeSteppingTape;
}  // namespace internal

/// Options of the fixed-step Radau IIA time-stepping baseline with stage complementarity; defaults
/// are the values below.
struct TimeSteppingOptions {
  /// Radau IIA stages s in [1, kMaxRadauStages].
  int stages = 1;
  /// Fixed step h > 0 (uniform grid between control breakpoints, see FixedStepGrid).
  double step_size = 0.01;
  /// Lowering of switching surfaces.
  SwitchingForm switching_form = SwitchingForm::kStewart;
  /// Newton options; the tolerance applies to the scaled residual (collocation rows scaled
  /// by 1 / (1 + |y_n|), algebraic and complementarity rows unscaled). With
  /// newton.smoothing = mu > 0 every stage pair solves the smoothed complementarity
  /// a b = mu^2 (a, b > 0; Fischer-Burmeister only): the step map is smooth and the
  /// sensitivities are its classical derivatives (homotopies of the OCP layer).
  SemismoothNewtonOptions newton = DefaultNewtonOptions();
  /// Most steps of a run, >= 1: a grid with more is refused before any work.
  long max_steps = 1'000'000;
  /// Record every step in the trajectory (false: only the initial and final points).
  bool record_trajectory = true;
  /// Compute TimeSteppingResult::sensitivities: the implicit function theorem on every
  /// converged step system (R(w; y_n, u, p) = 0 with the Fischer-Burmeister generalized
  /// Jacobian Newton uses), chained over the steps. Exact derivatives of the discrete map (the
  /// map is only piecewise smooth: a pair changing status inside a step is not a switch time,
  /// so these derivatives carry no switch-time terms; see docs/ocp.md).
  bool sensitivities = false;
  /// Directional sensitivities dx(T)/dtheta V without the full matrix, and adjoint
  /// sensitivities W^T dx(T)/dtheta by a reverse sweep over the kept step transfers, as
  /// FesdOptions::sensitivity_directions and adjoint_weights (the same shapes; theta =
  /// (x0, p, u per segment), or the lowered (y0, p, u)). They chain the same dense step
  /// transfers as `sensitivities` (for the small systems time-stepping serves): the adjoint
  /// keeps one n_y x (n_y + n_p + n_u) transfer per step (8 bytes each entry), beyond
  /// adjoint_memory_limit_mb in a temporary file.
  Matrix sensitivity_directions;
  /// Adjoint weights W (n_x x q, or n_y x q over the lowered state), as
  /// FesdOptions::adjoint_weights: the gradients W^T dx(T)/dtheta (+ the sample terms) in
  /// TimeSteppingResult::adjoint.
  Matrix adjoint_weights;
  /// Sample times in (t0, tf] (increasing): TimeSteppingResult::sample_states holds the state
  /// there, the directional and adjoint sensitivities their terms. Each is a step end: it
  /// joins stop_times, so the grid is laid out between them.
  std::vector<double> sample_times;
  /// Adjoint weights of the states at sample_times: n_x x (q * samples) (or n_y rows), sample
  /// j in columns j q, ..., (j + 1) q - 1; a single column is read column by column.
  Matrix adjoint_sample_weights;
  /// Keep the step transfers in the result (TimeSteppingResult::adjoint_sweep) so that
  /// adjoints for weights chosen after the run cost one reverse sweep each.
  bool keep_adjoint = false;
  /// Memory bound of the kept step transfers, in megabytes (0: none); transfers beyond it are
  /// written to a temporary file and read back by the sweep. >= 0.
  double adjoint_memory_limit_mb = 0.0;
  /// Near-active constraint filter (docs/sparse-systems.md), as FesdOptions::constraint_filter:
  /// moving-set constraints far from contact are left out of the step systems and checked at
  /// every stage afterwards (the step is solved again with those that are not positive there).
  ConstraintFilter constraint_filter = ConstraintFilter::kAutomatic;
  /// Safety factor of the filter's margin, >= 1.
  double filter_safety = 4.0;
  /// Stop times (breakpoints): the fixed grid is laid out between them as between control
  /// breakpoints, so that a step ends at each (any order; times outside (t0, tf) are ignored).
  std::vector<double> stop_times;
  /// Threads evaluating the derivatives of model functions made of blocks (MakeBlockFunction)
  /// in large scenes (systems stored sparse; LoweredSystem::SetThreads), >= 0: 0 for every
  /// hardware thread, 1 for the calling thread alone. Results are bitwise the same for any
  /// value; cpu_seconds counts every thread's CPU time.
  int threads = 0;
  /// Start from this lowered state y0 = (x, clock) instead of the scene's x0 (shooting codes;
  /// empty: the scene's). Need not lie in the moving sets: the first step catches up.
  Vector initial_state;

  /// The Newton settings when none are given.
  static SemismoothNewtonOptions DefaultNewtonOptions();
  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of a time-stepping run.
enum class TimeSteppingStatus {
  kSuccess,        ///< reached the final time
  kNewtonFailure,  ///< the semismooth Newton method did not converge in some step
                   ///< (its status and the time are in the message)
};
/// The status as text (snake case, as in summary.json).
std::string ToString(TimeSteppingStatus status);

/// Counters and certificates of a time-stepping run.
struct TimeSteppingStats {
  /// Steps taken.
  long num_steps = 0;
  /// Newton iterations of all steps.
  long num_newton_iterations = 0;
  /// LU factorizations of the Newton matrices.
  long num_factorizations = 0;
  /// Line-search backtracks of the Newton iterations.
  long num_backtracks = 0;
  double max_complementarity_residual = 0.0;  ///< max over steps of max |min(a, b)|
  double max_newton_residual = 0.0;           ///< max over steps of ||S Phi||_inf
  /// Near-active filter: steps solved again (a left-out constraint not positive at a
  /// stage), and the most pairs in a step system.
  long num_filter_rechecks = 0;
  /// Largest number of complementarity pairs in one step system.
  long max_working_pairs = 0;
  /// Steps in which a free side falls below zero between the nodes and rises again, or whose
  /// indicator bounds admit that without the search resolving it (each one a warning).
  long num_inside_crossings = 0;
  /// Adjoint: bytes of the step transfers kept in memory.
  double adjoint_memory_bytes = 0.0;
  double adjoint_file_bytes = 0.0;  ///< transfers beyond adjoint_memory_limit_mb (file)
  /// Thread CPU time of the adjoint reverse sweep in this result.
  double adjoint_cpu_seconds = 0.0;
  /// CPU time of the run.
  double cpu_seconds = 0.0;

  /// Sums counters and times; takes the max of the extreme values.
  TimeSteppingStats& operator+=(const TimeSteppingStats& other);
  /// One line for the command line's summary.
  std::string Summary() const;
};

/// Gradients of q functionals of one time-stepping run (TimeSteppingAdjoint::Sweep).
struct TimeSteppingGradient {
  Matrix theta;              ///< q x (n_x + n_p + n_u S): with respect to (x0, p, u_1..u_S)
  Matrix lowered;            ///< q x (n_y + n_p + n_u S): with respect to (y0, p, u_1..u_S)
  double cpu_seconds = 0.0;  ///< thread CPU time of the sweep
};

/// The reverse sweep of a finished time-stepping run (TimeSteppingOptions::keep_adjoint): the
/// transposes of its step transfers T_k = d y_(k+1) / d(y_k, p, u) applied in reverse order,
/// lambda <- T_y^T lambda, gradient += T_(p,u)^T lambda, with the sample weights added where
/// their step ends. Exactly the transpose of the directional sensitivities. Not thread-safe
/// (transfers beyond the memory bound are read back from one file).
class TimeSteppingAdjoint {
 public:
  /// Made by the run, which passes its kept transfers; not for applications.
  explicit TimeSteppingAdjoint(std::shared_ptr<const internal::TimeSteppingTape> tape);
  /// final_weights: n_x x q or n_y x q (empty: zero); sample_weights: n_x x (q K) or n_y x
  /// (q K) for the K sample times (empty: zero). Throws std::invalid_argument for other
  /// shapes or no weights at all.
  TimeSteppingGradient Sweep(const Matrix& final_weights,
                             const Matrix& sample_weights = Matrix()) const;

 private:
  std::shared_ptr<const internal::TimeSteppingTape> tape_;
};

/// Result of SimulateTimeStepping: status, final values, trajectory, events, per-step certificates,
/// sensitivities and statistics.
struct TimeSteppingResult {
  /// kSuccess, or why the run stopped.
  TimeSteppingStatus status = TimeSteppingStatus::kSuccess;
  /// The time and reason when status != kSuccess.
  std::string message;
  /// Time reached.
  double final_time = 0.0;
  Vector final_state;      ///< scene states
  Vector final_algebraic;  ///< algebraic unknowns at the last stage of the last step
  Trajectory trajectory;   ///< states and algebraic values at step ends
  /// Switch and contact events (to the resolution of the step).
  std::vector<Event> events;
  /// Certificate per step: max_{stages, pairs} |min(a, b)| at the accepted solution.
  std::vector<double> step_complementarity_residual;
  /// Counters and certificates.
  TimeSteppingStats stats;
  Vector final_lowered_state;  ///< y(T) = (x, clock)
  /// With options.sensitivities: d y(T) / d(y0, p, u per control segment), n_y rows; columns
  /// y0 (n_y), p (n_p), then u per segment (n_u each), as FesdSensitivities::lowered.
  Matrix sensitivities;
  std::vector<double> segment_starts;  ///< start time of every control segment
  /// What the run suspects but does not resolve, one sentence each: a free side that falls
  /// below zero between the nodes of a step and rises again (a pulse of a switching function,
  /// a contact shorter than the step), which the stage complementarity never sees
  /// (docs/fesd-formulation.md, section 11).
  std::vector<std::string> warnings;
  /// With sensitivity_directions (k): dx(T)/dtheta V (n_x x k).
  Matrix directional;
  /// With sensitivity_directions (k): the lowered dy(T)/dtheta V (n_y x k).
  Matrix directional_lowered;
  /// With adjoint_weights (q): the gradients, q x (n_x + n_p + n_u S).
  Matrix adjoint;
  /// With adjoint_weights (q): the gradients over the lowered (y0, p, u), q x (n_y + n_p + n_u S).
  Matrix adjoint_lowered;
  /// The lowered state y = (x, clock) at every TimeSteppingOptions::sample_times entry.
  std::vector<Vector> sample_states;
  /// With sensitivity_directions: dx(t_j)/dtheta V (n_x x k) at every sample time.
  std::vector<Matrix> sample_directional;
  /// With keep_adjoint: the run's step transfers for further reverse sweeps (shared by copies).
  std::shared_ptr<const TimeSteppingAdjoint> adjoint_sweep;
};

/// Simulates `scene` over [t0, tf]. Throws std::invalid_argument for invalid options, an
/// invalid scene, or an unsupported effect (naming it).
TimeSteppingResult SimulateTimeStepping(const Scene& scene, const TimeSteppingOptions& options,
                                        const ProgressCallback& progress = {});

}  // namespace moreau
