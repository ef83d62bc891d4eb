#pragma once
/// @file
/// Event-driven reference integrator on SUNDIALS IDA (variable-order BDF, adaptive steps).
///
/// Method (docs/ida.md). The scene is lowered to a dynamic complementarity system
/// (LoweredSystem; relays as discrete memories, RelayForm::kDiscreteMemory). Between events
/// every pair keeps its status (which side is zero), so the system is smooth: a *phase*. In
/// a phase the complementarity conditions are imposed at velocity level, which makes the
/// DAE index 1:
///
///   y'   = F(y, v_J)                       (v_J: jump variables theta, alpha, multipliers)
///   z_c' = v_c                             (continuous algebraic variables, e.g. Stewart's
///                                           lambda and mu, carried as states)
///   0    = V(y, v) + kappa P(y, z_c, v_J)  (the velocity-level problem for the phase's
///                                           statuses, LoweredSystem::EvaluateVelocityLevel)
///
/// where P are the position-level conditions the velocity-level rows differentiate (the
/// continuous sides kept at zero, e.g. c = 0 for an active constraint or g_i = g_j on a
/// sliding surface, and the algebraic equations G). Along exact solutions P = 0; the term
/// kappa P (Baumgarte stabilization, IdaOptions::drift_rate) makes the constraint manifold of
/// the phase attracting, so integration errors do not drift off it; at the end of every phase
/// the state is projected back onto P = 0 (minimum-norm correction) before the statuses of
/// the next phase are decided. Root functions watch the free side of every pair
/// (LoweredSystem::EvaluateEventIndicators: c of inactive constraints, multipliers of active
/// ones, lambda of inactive modes, theta of sliding ones) and the relays' switching functions;
/// they are also sampled inside every step on IDA's interpolant and bounded on it by interval
/// arithmetic (docs/ida.md, "Contacts inside a step"), so that a contact or a pulse of a
/// switching function that begins and ends within one step is found (or, where the bounds
/// cannot decide, a warning says so). At a root the new statuses come from the velocity-level
/// complementarity problem at the event state (LoweredSystem::DecideStatuses: the slow
/// solution), a relay flips its memory, and IDA restarts from consistent values. Sliding modes
/// are DAE phases, never chattering. Control breakpoints restart IDA with the new input values;
/// an indicator that is zero at a breakpoint or at tf is decided there.
///
/// Step growth is SUNDIALS IDA's: at most a factor 2 per step. Accuracy is tolerance-driven
/// (rtol, atol); IdaOptions::Reference() (rtol = 1e-12) gives
/// the reference solutions that tests and benchmarks compare the other integrators with.
///
/// Effects supported: moving sets, switching surfaces, hysteresis relays. Path constraints
/// are refused (alpha-method stepper). No SUNDIALS type appears in this header.

#include <string>
#include <vector>

#include "moreau/integrators/simulation.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/model/scene.hpp"

namespace moreau {

/// Options of the SUNDIALS IDA reference integrator (docs/ida.md); defaults are the values below.
struct IdaOptions {
  /// Relative and absolute tolerances of IDA's local error test, > 0.
  double relative_tolerance = 1e-8;
  /// Absolute tolerance of IDA's local error test, > 0.
  double absolute_tolerance = 1e-10;
  /// IDA's Newton iteration stops when its error estimate is below this fraction (in (0, 1])
  /// of the local error tolerance (IDA's default 0.33). With old Jacobians the remaining
  /// Newton error adds to every step's local error; the reference settings use 0.01.
  double newton_convergence_factor = 0.33;
  /// Baumgarte rate kappa >= 0 (1/time) of the drift control: the position-level conditions
  /// of a phase decay like exp(-kappa t) instead of drifting (0 disables it).
  double drift_rate = 10.0;
  /// Lowering of switching surfaces.
  SwitchingForm switching_form = SwitchingForm::kStewart;
  /// Dense LU (SUNDIALS dense) or sparse LU (SUNDIALS KLU); automatic: KLU for more than
  /// kDenseSizeLimit unknowns or for dynamics with a hand-written sparse Jacobian. The
  /// derivatives are stored as StorageForLinearSolver says (sparse with KLU; automatic
  /// otherwise, sparse above kSparseStorageThreshold), and the phase Jacobian is assembled in
  /// the solver's format from them (docs/ida.md, "Linear algebra").
  LinearSolverKind linear_solver = LinearSolverKind::kAutomatic;
  /// Pairs whose continuous side is within this of zero are decided by the velocity-level
  /// problem at events; at breakpoints and tf, free sides below it count as events. > 0.
  double event_tolerance = 1e-9;
  /// Internal steps allowed over the whole run (> 0), and events (Zeno guard, > 0).
  long max_steps = 10000000;
  /// Events allowed over the whole run (Zeno guard), > 0.
  long max_events = 100000;
  /// Largest internal step (0: no limit).
  double max_step = 0.0;
  /// Stop times (breakpoints): IDA stops exactly at these times (IDASetStopTime) and never
  /// steps across them (any order; times outside (t0, tf) are ignored). The remedy for a root
  /// the bounds on the interpolant cannot resolve, at a time the user knows.
  std::vector<double> stop_times;
  /// Record every internal step in the trajectory (false: events and breakpoints only).
  /// Ignored with output_times.
  bool record_steps = true;
  /// Output times in [t0, tf] (need not be sorted): the trajectory is then exactly t0, these
  /// times (interpolated by IDA to the integration accuracy) and tf, nothing else (events
  /// are in IdaResult::events).
  std::vector<double> output_times;

  /// The reference-solution settings: rtol = 1e-12, atol = 1e-14, Newton convergence
  /// factor 0.01 (measured on H1: final-state error 1.5e-9 with IDA's default 0.33, 2e-10
  /// with 0.01, in fewer steps).
  static IdaOptions Reference();
  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of an IDA run.
enum class IdaStatus {
  kSuccess,                ///< reached the final time
  kSolverFailure,          ///< IDA returned an error (its flag and message are in the message)
  kStatusDecisionFailure,  ///< no consistent continuation at an event
  kTooManySteps,           ///< max_steps internal steps without reaching tf
  kTooManyEvents,          ///< max_events events without reaching tf (Zeno-like)
  kNoProgress,             ///< kMaxStalledIdaSteps consecutive internal steps did not advance t
                           ///< (steps below the resolution of t, e.g. at a point beyond which
                           ///< the model is singular or not finite)
  kStepSizeTooSmall,       ///< kMaxCollapsedIdaSteps accepted internal steps in a row shorter
                           ///< than 10 eps |t|: the step collapsed (the message names a
                           ///< non-finite model value if IDA met one)
  kNonFinite,              ///< IDA failed on non-finite residuals (repeated recoverable
                           ///< residual errors); the message names the model function, its
                           ///< output, t and the state
};
/// IDA steps shorter than this many units in the last place of t (10 eps |t|) count as
/// collapsed; kMaxCollapsedIdaSteps of them in a row end the run with
/// IdaStatus::kStepSizeTooSmall (IDA's first steps after a restart can be that short, but
/// they double every step).
inline constexpr double kMinIdaStepUlps = 10.0;
inline constexpr int kMaxCollapsedIdaSteps = 20;  ///< collapsed steps in a row that end a run
/// Consecutive internal IDA steps that leave t unchanged before IdaStatus::kNoProgress.
inline constexpr int kMaxStalledIdaSteps = 100;
/// The status as text (snake case, as in summary.json).
std::string ToString(IdaStatus status);

/// Counters and certificates of an IDA run (summed over its phases).
struct IdaStats {
  /// Internal IDA steps.
  long num_steps = 0;
  /// Residual evaluations (IDA's, without Jacobian).
  long num_residual_evaluations = 0;
  /// Jacobian evaluations.
  long num_jacobian_evaluations = 0;
  /// Newton iterations of IDA's nonlinear solver.
  long num_nonlinear_iterations = 0;
  /// Steps rejected by IDA's local error test.
  long num_error_test_failures = 0;
  long num_phases = 0;  ///< (re)starts of IDA: events and breakpoints
  /// Events located (switches, contacts, relay jumps).
  long num_events = 0;
  /// KLU symbolic analyses: Jacobian evaluations whose sparsity pattern differed from the
  /// previous one (at most one per phase; 0 with the dense LU).
  long num_symbolic_analyses = 0;
  /// Largest |P| (position-level conditions of the phase) at the end of a phase, before the
  /// projection: the drift certificate.
  double max_drift = 0.0;
  /// Steps in which the bounds of a root function on IDA's interpolant admit a zero that the
  /// crossing search could not resolve (each one a warning; docs/ida.md, "Contacts inside a
  /// step").
  long num_unresolved_crossings = 0;
  /// CPU time of the run.
  double cpu_seconds = 0.0;

  /// One line for the command line's summary.
  std::string Summary() const;
};

/// Result of SimulateIda: status, final values, trajectory, events, relay memories and statistics.
struct IdaResult {
  /// kSuccess, or why the run stopped.
  IdaStatus status = IdaStatus::kSuccess;
  /// The time and reason when status != kSuccess.
  std::string message;
  /// Time reached.
  double final_time = 0.0;
  Vector final_state;     ///< scene states
  Trajectory trajectory;  ///< scene states and algebraic values (z layout) at recorded times
  /// Located events in time order.
  std::vector<Event> events;
  std::vector<RelaySignal> relays;  ///< each relay's memory w(t)
  /// Counters and certificates.
  IdaStats stats;
  /// What the run suspects but could not resolve, one sentence each (a root inside a step
  /// that the bounds admit and the search left undecided).
  std::vector<std::string> warnings;
};

/// Simulates `scene` over [t0, tf]. Throws std::invalid_argument for invalid options, an
/// invalid scene or an unsupported effect (naming it).
IdaResult SimulateIda(const Scene& scene, const IdaOptions& options,
                      const ProgressCallback& progress = {});

/// A reference solution: IDA with IdaOptions::Reference() (or the given options), sampled at
/// `sample_times` (trajectory points exactly there, in order, plus t0). Throws
/// std::runtime_error with IDA's message if the run does not succeed, so that a test or
/// benchmark never compares against a failed reference.
struct ReferenceSolution {
  /// Scene states at the final time.
  Vector final_state;
  /// The final time reached (the scene's tf).
  double final_time = 0.0;
  /// The events located on the way.
  std::vector<Event> events;
  /// The times asked for (ascending).
  std::vector<double> sample_times;
  std::vector<Vector> samples;  ///< scene states at sample_times
  /// Each relay's memory w(t).
  std::vector<RelaySignal> relays;
};
/// The reference solution of `scene` (see ReferenceSolution); throws std::runtime_error if IDA does
/// not succeed.
ReferenceSolution ComputeReference(const Scene& scene, const std::vector<double>& sample_times = {},
                                   const IdaOptions& options = IdaOptions::Reference());

}  // namespace moreau
