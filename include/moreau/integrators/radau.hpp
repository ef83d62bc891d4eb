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
/// Step size: fixed (uniform grid between control breakpoints), or controlled by the
/// embedded estimate err = (I - h gamma0 J)^{-1}(gamma0 h F(y_n) + sum_j e_j Z_j) of local
/// order s + 1 (Hairer & Wanner II, Sec. IV.8) in the weighted RMS norm with weights
/// atol + rtol max(|y_n|, |y_{n+1}|), h_new = h min(5, max(0.2, 0.9 err^{-1/(s+1)})).
/// Steps never cross control breakpoints. Scenes with effects are refused (use the
/// time-stepping, FESD, IDA or alpha-method integrators).

#include <string>

#include "moreau/integrators/simulation.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// Options of the smooth Radau IIA integrator (scenes without effects); defaults are the values
/// below.
struct RadauOptions {
  /// Number of stages s in [1, kMaxRadauStages]; the method has order 2s - 1.
  int stages = 3;
  /// Step size h > 0: the fixed step, or the initial step when adaptive (0 = automatic
  /// starting step, Hairer-Wanner I, Sec. II.4).
  double step_size = 0.01;
  /// Step-size control by the embedded error estimate instead of fixed steps.
  bool adaptive = false;
  /// Relative and absolute tolerances of the local error (adaptive only), > 0.
  double relative_tolerance = 1e-6;
  /// Absolute tolerance of the local error (adaptive only), > 0.
  double absolute_tolerance = 1e-8;
  /// Smallest step the controller may take (adaptive), > 0; below it the run stops with
  /// RadauStatus::kStepSizeTooSmall.
  double min_step_size = 1e-14;
  /// Largest step the controller may take (adaptive), > 0.
  double max_step_size = 1e300;
  /// Newton stops when max_i |dZ_i| / (1 + |y_n,i|) <= newton_tolerance (fixed step), or when
  /// the weighted RMS of dZ is <= 0.01 (adaptive: a small fraction of the error tolerance).
  double newton_tolerance = 1e-12;
  /// Newton iterations per step before the step counts as failed, >= 1.
  int max_newton_iterations = 25;
  /// Accepted steps before the run stops with RadauStatus::kMaxStepsReached, >= 1.
  long max_steps = 10'000'000;
  /// Dense or sparse LU for the Newton matrices (automatic: by size).
  LinearSolverKind linear_solver = LinearSolverKind::kAutomatic;
  /// Record every accepted step in the trajectory (false: only the initial and final point).
  bool record_trajectory = true;

  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of a Radau run; each value is documented by the criterion that produces it.
enum class RadauStatus {
  kSuccess,           ///< reached the final time
  kNewtonFailure,     ///< fixed step: Newton did not reach its tolerance (max iterations,
                      ///< contraction rate >= 1, or a singular Newton matrix)
  kStepSizeTooSmall,  ///< adaptive: the step fell below min_step_size after rejections
  kMaxStepsReached,   ///< max_steps accepted steps before the final time
  kNonFinite,         ///< NaN or infinity in the state or the dynamics
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
};

/// Simulates `scene` over [t0, tf]. Throws std::invalid_argument for invalid options, an
/// invalid scene, or a scene with effects (naming the effect).
RadauResult SimulateRadau(const Scene& scene, const RadauOptions& options,
                          const ProgressCallback& progress = {});

}  // namespace moreau
