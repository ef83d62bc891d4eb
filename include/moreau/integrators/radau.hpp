#pragma once
/// @file
/// Smooth Radau IIA integrator for scenes without nonsmooth effects.
///
/// Method: s-stage Radau IIA collocation (order 2s - 1, L-stable; tableaus from
/// RadauIIA()), applied to the lowered system y' = F(y), y = (x, clock), in the stage
/// increments Z_i = Y_i - y_n:  Z_i = h sum_j a_ij F(y_n + Z_j).
/// Newton: full Newton with the exact stage Jacobians dF/dy(Y_j) (automatic
/// differentiation), matrix I - h (A ⊗ I) blockdiag(F_y(Y_j)), dense or sparse LU.
/// Stage initial guesses come from the previous step's collocation polynomial.
/// Step size: controlled by the embedded estimate err = (I - h gamma0 J)^{-1}(gamma0 h F(y_n) +
/// sum_j e_j Z_j) of local order s + 1 (Hairer & Wanner II, Sec. IV.8) in the weighted RMS norm
/// with weights atol_i + rtol max(|y_n,i|, |y_{n+1},i|), h_new = h min(5, max(0.2, 0.9
/// err^{-1/(s+1)})), a step growing by at most 5 (the default: no step given), or fixed (a uniform
/// grid between control breakpoints), whose steps get the same estimate, accumulated into
/// RadauStats:: error_estimate (docs/accuracy.md). A step below max(min_step_size, 10 eps |t|) ends
/// the run (kStepSizeTooSmall); a non-finite model value is named (kNonFinite). Steps never cross
/// control breakpoints or the stop times (RadauOptions::stop_times). Scenes with effects are
/// refused (use the time-stepping, FESD, IDA or alpha-method integrators).

#include <string>
#include <vector>

#include "moreau/integrators/simulation.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// Options of the smooth Radau IIA integrator (scenes without effects); defaults are the values
/// below.
struct RadauOptions {
  /// Number of stages s in [1, kMaxRadauStages]; the method has order 2s - 1.
  int stages = 3;
  /// Fixed step h > 0; 0 (the default): no fixed step, the steps are error-controlled
  /// (ErrorControlled()). With `adaptive` a positive h is the initial step.
  double step_size = 0.0;
  /// Error-controlled steps even with a step_size given (it is then the initial step); on
  /// whenever step_size is 0.
  bool adaptive = false;
  /// Initial step of error-controlled runs, > 0; 0: step_size if positive, else automatic
  /// (Hairer, Norsett & Wanner's starting step, Solving ODEs I, Sec. II.4).
  double initial_step_size = 0.0;
  /// Tolerances of the local error: rtol > 0; atol > 0 one absolute tolerance for every
  /// state, or 0 (the default): atol_i = rtol times the largest |y_i| of the run so far, each
  /// state controlled relative to its own scale (docs/accuracy.md).
  double relative_tolerance = kDefaultRelativeTolerance;
  double absolute_tolerance = 0.0;  ///< atol: > 0 for every state, 0 per state (see above)
  /// Smallest step the controller may take, > 0 (never below 10 eps |t|); below it the run
  /// stops with RadauStatus::kStepSizeTooSmall.
  double min_step_size = 1e-14;
  /// Largest step the controller may take (adaptive), > 0.
  double max_step_size = 1e300;
  /// Newton stops when max_i |dZ_i| / (1 + |y_n,i|) <= newton_tolerance (fixed step), or when
  /// the weighted RMS of dZ is <= 0.01 (adaptive: a small fraction of the error tolerance).
  double newton_tolerance = 1e-12;
  /// Newton iterations per step before the step counts as failed, >= 1.
  int max_newton_iterations = 25;
  /// Accepted steps before the run stops with RadauStatus::kMaxStepsReached, >= 1; a fixed
  /// grid with more steps is refused before any work (std::invalid_argument).
  long max_steps = 10'000'000;
  /// Fixed steps: compute the embedded error estimate of every step too (one more LU of
  /// I - h gamma0 J per step), accumulated into RadauStats::error_estimate, with a warning
  /// above kErrorWarningFactor times relative_tolerance.
  bool estimate_error = true;
  /// Dense or sparse LU for the Newton matrices (automatic: by size).
  LinearSolverKind linear_solver = LinearSolverKind::kAutomatic;
  /// Stop times (breakpoints): steps end at these times and never cross them (any order;
  /// times outside (t0, tf) are ignored), e.g. where a forcing term changes abruptly.
  std::vector<double> stop_times;
  /// Record every accepted step in the trajectory (false: only the initial and final point).
  bool record_trajectory = true;

  /// Whether the steps are error-controlled: adaptive, or no fixed step (step_size == 0).
  bool ErrorControlled() const { return adaptive || step_size == 0.0; }

  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of a Radau run; each value is documented by the criterion that produces it.
enum class RadauStatus {
  kSuccess,           ///< reached the final time
  kNewtonFailure,     ///< fixed step: Newton did not reach its tolerance (max iterations,
                      ///< contraction rate >= 1, or a singular Newton matrix)
  kStepSizeTooSmall,  ///< error control: the step fell below max(min_step_size, 10 eps |t|)
  kMaxStepsReached,   ///< max_steps accepted steps before the final time
  kNonFinite,         ///< NaN or infinity in the state or the dynamics (the message names
                      ///< the model function, its output, t and the state)
};
/// The status as text (snake case, as in summary.json).
std::string ToString(RadauStatus status);

/// Counters of a Radau run.
struct RadauStats {
  long num_steps = 0;           ///< accepted steps
  long num_rejected_steps = 0;  ///< error-test and Newton rejections (adaptive)
  /// Newton iterations of all steps.
  long num_newton_iterations = 0;
  long num_factorizations = 0;        ///< LU factorizations (Newton and error filter)
  long num_function_evaluations = 0;  ///< evaluations of F (with or without Jacobian)
  long num_jacobian_evaluations = 0;  ///< evaluations of F with its Jacobian
  /// Fixed steps: the estimated error relative to the solution's scale, rtol times the sum
  /// over the steps of the embedded estimate in the tolerance weights (local errors of order
  /// s + 1 accumulated without propagation: an upper estimate, docs/accuracy.md). -1 for
  /// error-controlled runs (the tolerance is their statement) and without estimate_error.
  double error_estimate = -1.0;
  /// CPU time of the run.
  double cpu_seconds = 0.0;

  /// Sums the counters and times.
  RadauStats& operator+=(const RadauStats& other);
  /// One line for the command line's summary.
  std::string Summary() const;
};

/// Result of SimulateRadau: status, final values, trajectory and statistics.
struct RadauResult {
  /// kSuccess, or why the run stopped.
  RadauStatus status = RadauStatus::kSuccess;
  std::string message;      ///< time and reason when status != kSuccess
  double final_time = 0.0;  ///< time reached
  Vector final_state;       ///< scene states at final_time
  /// Accepted steps (or the initial and final points without record_trajectory).
  Trajectory trajectory;
  /// Counters of the run.
  RadauStats stats;
  /// What the caller should know although the run succeeded, one sentence each.
  std::vector<std::string> warnings;
};

/// Simulates `scene` over [t0, tf]. Throws std::invalid_argument for invalid options, an
/// invalid scene, or a scene with effects (naming the effect).
RadauResult SimulateRadau(const Scene& scene, const RadauOptions& options,
                          const ProgressCallback& progress = {});

}  // namespace moreau
