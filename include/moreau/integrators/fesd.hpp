#pragma once
/// @file
/// FESD Radau IIA: finite elements with switch detection, solved by semismooth Newton.
///
/// Method (docs/fesd-formulation.md). The scene is lowered to a DCS (LoweredSystem). Every
/// integration step of length H (the control interval) holds N_fe finite elements of s-stage
/// Radau IIA collocation whose lengths are unknowns. Elements are solved in *groups*: a group
/// is a run of m elements of equal length h (step equilibration) in which every
/// complementarity pair keeps one status, the one decided at the group's start (cross
/// complementarity: a side that is zero at one stage or at the start is zero at all stages).
/// Per group the system is square:
///   - Radau IIA collocation and the algebraic equations G at every stage;
///   - one status equation per pair and stage: a_k = 0 or b_k = 0;
///   - the velocity-level problem at the group's end state (consistent multipliers);
///   - one element-length complementarity  0 <= (h_max - h)/h_max  ⟂  iota(y_end) >= 0,
///     where iota is the smallest scaled event indicator (the free side of every pair,
///     evaluated from the end state: c for inactive constraints, the velocity-level
///     multiplier for active ones, lambda = g_j - g_i for inactive Stewart modes, theta for
///     sliding ones). Either the group covers the rest of the step (h = h_max) or it ends
///     exactly on a switch (iota = 0).
/// It is solved by the semismooth Newton method on the Fischer-Burmeister reformulation of
/// that complementarity. Switches therefore lie on element boundaries; indicators taken from
/// the end state (not from stage multipliers, which converge with order s only) keep the
/// Radau IIA order 2s - 1 for states and switch times across switches.
/// Statuses after a switch come from the velocity-level complementarity problem at the
/// switch point (LoweredSystem::DecideStatuses: projection on the tangent cone, the slow
/// solution; non-unique continuations are reported as EventKind::kAmbiguous).
/// Groups start with a trial pass (elements of fixed length R/N_r, i.e. plain Radau IIA
/// steps with fixed statuses); only when a free side turns negative is the group re-solved
/// with the event equation. A scene without effects therefore costs what smooth Radau IIA
/// costs.
///
/// Sensitivities: with FesdOptions::sensitivities, the implicit function theorem on every
/// converged group system (including the switch-determined element lengths) gives
/// dx(T)/dx(0), dx(T)/dp and dx(T)/du for the piecewise-constant inputs of every control
/// segment. These are the derivatives of the discrete solution map; they converge to those of
/// the exact flow, whereas the time-stepping baseline misses the dependence of switch times.
/// The same derivative applied to a block of directions (FesdOptions::sensitivity_directions)
/// and transposed onto adjoint weights by a reverse sweep over checkpoints of the run's groups
/// (adjoint_weights, sample_times, keep_adjoint; FesdAdjoint) serves systems too large for
/// the full matrices (docs/sensitivities.md).
///
/// Effects: moving sets, switching surfaces and hysteresis relays; path constraints belong
/// to the alpha-method stepper.
///
/// Speed of time (Scene::time_scale_input): the scene's time axis is numerical time, every
/// physical rate and the clock are multiplied by the input s; final_time is the clock.
///
/// Adaptive steps (FesdOptions::adaptive, or rtol/atol given to Simulate and the command line;
/// docs/fesd-formulation.md, section 10): the step H is chosen by a local error estimate,
/// Richardson extrapolation of the accepted solution against a solution of the same interval with
/// another element count (one element of m h for m >= 2 elements of length h, two of h/2 for one),
/// valid on elements that end on a switch because their statuses are fixed, with error per unit
/// step (local error <= tol H / (tf - t0), so that the global error follows the tolerance) and a
/// predictive (Gustafsson) controller. A step ends at the first switch in it. A step whose
/// solves fail (Newton, event location) is retried with half the step down to min_step_size.
/// Sensitivities in adaptive mode are those of the accepted step sequence with the step sizes
/// held fixed (internal differentiation); FesdOptions::step_sequence replays a sequence.
/// Dense output (FesdOptions::output_times, output_step): the collocation polynomial of the
/// element containing each time, never across a switch.
///
/// Hysteresis relays are lowered by time-freezing (docs/lowering.md): the integration
/// variable becomes numerical time tau, in which a relay's memory w travels continuously
/// between 0 and 1 while the clock (physical time) stands still. Steps have length H in tau;
/// a step that starts while physical time runs is shortened so that the clock lands exactly
/// on the next control breakpoint or tf unless a relay switches in it, and after a switch a
/// new step starts from the clock. The run ends when the clock reaches tf. Results are in
/// physical time (frozen elements are left out of the trajectories; the memories are
/// reported as RelaySignal); the numerical-time trajectory is kept for inspection. With a
/// speed of time the horizon stays in numerical time (fixed steps; the clock is free), which
/// is what a time-optimal control problem needs.

#include <memory>
#include <string>
#include <vector>

#include "moreau/integrators/simulation.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/model/scene.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau {

/// Options of FESD Radau IIA (docs/fesd-formulation.md); defaults are the values below.
struct FesdOptions {
  /// Radau IIA stages s in [1, kMaxRadauStages]; order 2s - 1 (1, 3, 5, 7 for s = 1..4).
  int stages = 3;
  /// Fixed integration step H > 0 (control interval; steps never cross control breakpoints;
  /// with hysteresis relays H is measured in numerical time, see the file comment). 0 (the
  /// default): no fixed step, the steps are error-controlled (ErrorControlled(): a default-
  /// constructed FesdOptions runs to the tolerances below, so that a step that knows nothing
  /// of the model's time scale is never the default). With `adaptive` a positive H is the
  /// initial step of the error-controlled run.
  double step_size = 0.0;
  /// Nominal finite elements per step N_fe >= 1.
  int finite_elements = 2;
  /// Lowering of switching surfaces.
  SwitchingForm switching_form = SwitchingForm::kStewart;
  /// Newton options for the element and group systems (tolerance on the scaled residual).
  SemismoothNewtonOptions newton = DefaultNewtonOptions();
  /// Pairs whose continuous side is within this of zero are decided by the velocity-level
  /// problem; free sides below minus this (times 1 + their scale) count as switches. > 0.
  double event_tolerance = 1e-9;
  /// After a switch, a remainder of the step shorter than this fraction of a nominal element
  /// (H / N_fe) is merged into the next step, unless the step ends at a control breakpoint or
  /// the final time. In (0, 0.5].
  double min_element_fraction = 1e-3;
  /// Re-solves allowed per switch (other element counts or guesses) before failing, >= 1.
  int max_event_retries = 6;
  /// A switch located within min_element_fraction of a nominal element after the start of an
  /// advance does not use up an element of the step: the rest of the step keeps its elements.
  /// Then the solution map is continuous in the initial state when it starts on a constraint
  /// boundary (a start just inside reaches the boundary after a vanishing element and
  /// continues as a start on it would), which multiple shooting needs: its node states lie on
  /// active boundaries. Off (the default): such a switch counts as an element, and the map
  /// jumps there by the change of the discretization error (docs/ocp.md).
  bool keep_elements_after_early_switch = false;
  /// Near-active constraint filter (docs/sparse-systems.md): moving-set constraints whose
  /// value exceeds filter_safety * H * (a bound on their rate at the step start) are left out
  /// of the element systems and checked at every stage afterwards (a step whose left-out
  /// constraint is not positive there is solved again with it). kAutomatic: on when the scene
  /// declares more than kFilterThreshold moving-set constraints.
  ConstraintFilter constraint_filter = ConstraintFilter::kAutomatic;
  /// Safety factor of the filter's margin, >= 1.
  double filter_safety = 4.0;
  /// Threads evaluating the derivatives of model functions made of blocks (MakeBlockFunction)
  /// in large scenes (systems stored sparse; LoweredSystem::SetThreads), >= 0: 0 for every
  /// hardware thread, 1 for the calling thread alone. Results are bitwise the same for any
  /// value; cpu_seconds counts every thread's CPU time.
  int threads = 0;
  /// Compute dx(T)/dx(0), dx(T)/dp, dx(T)/du (FesdResult::sensitivities).
  bool sensitivities = false;
  /// Directional (forward) sensitivities (docs/sensitivities.md): a block V of k directions
  /// over theta = (x0, p, u_1, ..., u_S) (n_x + n_p + n_u S rows, u_k the inputs of control
  /// segment k) or over the lowered theta_L = (y0, p, u_1, ..., u_S) (n_y + n_p + n_u S rows,
  /// y0 = (x0, relay memories, clock)); a single column of n k entries is read column by
  /// column (front ends pass lists). Gives FesdSensitivities::directional = dx(T)/dtheta V
  /// (and the same at sample_times) without forming dx(T)/dtheta: per group one solve per
  /// direction with the run's own factorization at the solution. Empty: none.
  Matrix sensitivity_directions;
  /// Adjoint (reverse) sensitivities: weights W of the final state (n_x x q, or n_y x q over
  /// the lowered y(T); a single column of n q entries is read column by column). Gives
  /// FesdSensitivities::adjoint = W^T dx(T)/dtheta (+ the sample terms below), q x n_theta,
  /// by a reverse sweep over the run's groups that transposes exactly the derivative of the
  /// directional sensitivities (switch-determined element lengths, saltation at switches on
  /// step boundaries, relay jumps). Memory: the run keeps every group's converged unknowns
  /// and re-evaluates and refactorizes its Jacobian in the sweep (docs/sensitivities.md).
  /// Empty (and no adjoint_sample_weights): none.
  Matrix adjoint_weights;
  /// Sample times in (t0, tf] (physical time, increasing): FesdResult::sample_states holds the
  /// state there, the directional and adjoint sensitivities their terms. Each must be an
  /// element end of the run (fixed steps: a multiple of h from a control breakpoint); the run
  /// throws std::invalid_argument naming a sample time that is not.
  std::vector<double> sample_times;
  /// Adjoint weights of the states at sample_times: n_x x (q * samples) (or n_y rows), sample
  /// j in columns j q, ..., (j + 1) q - 1; a single column is read column by column.
  Matrix adjoint_sample_weights;
  /// Keep the run's reverse-sweep data (FesdResult::adjoint) so that adjoints for weights
  /// chosen after the run (the gradient of a function of x(T) and of sample_states) cost one
  /// reverse sweep each.
  bool keep_adjoint = false;
  /// Memory bound of the adjoint's checkpoints, in megabytes (0: none). Checkpoints beyond it
  /// (every further group's converged unknowns and start state) are written to a temporary
  /// file and read back by the sweep, so that the resident memory of the tape stays below the
  /// bound at the cost of file I/O (docs/sensitivities.md). >= 0.
  double adjoint_memory_limit_mb = 0.0;
  /// Smooth elements: in an element whose statuses leave a smooth vector field (Stewart's form
  /// of one SwitchingSurfaces effect with exactly one active mode, no other effects or
  /// dynamics; moving sets only, with no active constraint; or hysteresis relays only, each in
  /// one region or sliding on a memory boundary), the element equations are exactly a Radau
  /// IIA step of that field (theta = e_k and lambda, mu functions of the state; lambda = 0;
  /// theta constant, 1 or 1/2). The trial element is first solved that way (n_y s unknowns,
  /// the field only), its algebraic stage values are reconstructed from the stage states, and
  /// the full element system must then hold to the Newton tolerance (else its Newton continues
  /// from there): results agree with the full solve to that tolerance; switch detection,
  /// certificates and sensitivities are unchanged. The comparison solves of the adaptive
  /// error estimate use the field too.
  bool reduce_smooth_elements = true;
  /// Step-size control by the local error estimate (see the file comment and
  /// docs/fesd-formulation.md, section 10) even with a fixed step H given (H is then the
  /// initial step). Error control is on whenever step_size is 0, whatever this says.
  bool adaptive = false;
  /// Initial step of an error-controlled run, > 0; 0 (the default): step_size if positive,
  /// else automatic (Hairer-Norsett-Wanner's starting step for order 2s - 1 from the field at
  /// t0 and at an Euler step, times N_fe; see StartingStep in fesd_adaptive.cpp).
  double initial_step_size = 0.0;
  /// Tolerances of the error-controlled steps: the local error of a step of length H, weighted
  /// per state by atol_i + rtol max(|y_start|, |y_end|), is kept below H / (tf - t0) (error per
  /// unit step), so that the error at tf is about rtol relative to the solution's scale
  /// (docs/accuracy.md). rtol > 0. atol > 0 is one absolute tolerance for every state; 0 (the
  /// default) makes it per state and proportional to rtol: atol_i = rtol times the largest
  /// |y_i| of the run so far (initial value included), i.e. every state is controlled
  /// relative to its own scale, whatever its unit.
  double relative_tolerance = kDefaultRelativeTolerance;
  double absolute_tolerance = 0.0;  ///< atol: > 0 for every state, 0 per state (see above)
  /// Smallest step of the adaptive controller and of the failure retries, > 0 (never below
  /// 64 ulps of the time); below it the run stops with kStepSizeTooSmall or the status of the
  /// failed solve.
  double min_step_size = 1e-12;
  /// Largest adaptive step, >= 0 (0: no bound; steps never cross control breakpoints).
  double max_step_size = 0.0;
  /// Stop times (breakpoints): steps end at these times and never cross them, fixed and
  /// adaptive (any order; times outside (t0, tf) are ignored; in the scene's time axis, as
  /// control breakpoints). The remedy for what a step cannot see (docs/fesd-formulation.md,
  /// section 11): a switch the indicator bounds cannot resolve, at a time the user knows.
  std::vector<double> stop_times;
  /// Dense output: the trajectory holds the state at these times (physical time, in
  /// [t0, tf], any order) instead of every element end, evaluated on the collocation
  /// polynomial of the element that contains the time (never across a switch; accuracy:
  /// the polynomial's uniform order s + 1, exact at element ends). Algebraic values there are
  /// the consistent ones (velocity level) at the interpolated state.
  std::vector<double> output_times;
  /// Dense output every output_step from t0 (with output_times: both), >= 0 (0: none).
  double output_step = 0.0;
  /// Replays the steps of an adaptive run (FesdResult::step_sequence) without error control:
  /// step k ends at min(t_k + step_sequence[k], end of its control segment); an entry 0 is a
  /// step to the end of the segment (with hysteresis relays: the clock to it). A step ends at
  /// the first switch in it; entries left over are unused, and steps to the segment end
  /// follow when they run out. With sensitivities: the derivatives of exactly this discrete
  /// map, which an adaptive run also reports (step sizes held fixed).
  std::vector<double> step_sequence;
  /// Start from this lowered state y0 = (x0, relay memories w0, clock) instead of the scene's
  /// (empty: the scene's x0, initial memories and t0). A shooting code passes node states this
  /// way: with time-freezing a node may lie inside a frozen interval (0 < w < 1).
  Vector initial_state;
  /// Most integration steps of a run, >= 1. A fixed grid (step_size without error control)
  /// with more steps than this is refused before any work (std::invalid_argument); an
  /// error-controlled run that reaches it stops with FesdStatus::kMaxStepsReached. A FESD
  /// step costs tens of microseconds or more, so the default bounds a run to seconds (a 10^6
  /// step fixed grid used to run for minutes without a word).
  long max_steps = 100'000;
  /// Fixed steps: estimate the local error of every step as error control does (Richardson
  /// extrapolation against a comparison solve of the same interval, EstimateError) and
  /// accumulate it into FesdStats::error_estimate, with a warning in FesdResult::warnings when
  /// it exceeds kErrorWarningFactor times relative_tolerance (docs/accuracy.md). Costs one
  /// comparison element solve per step; shooting codes that integrate the same intervals many
  /// times may switch it off.
  bool estimate_error = true;
  /// An initial state x0 outside the moving sets is projected onto them (the sweeping
  /// process's jump at t0, with its derivative in the sensitivities) instead of refused, as
  /// initial_state is: shooting codes whose node states leave the sets between iterations.
  bool project_initial_state = false;
  /// Record the stage trajectory (FesdResult::stage_trajectory).
  bool record_stages = false;
  /// Record element ends in the trajectory (false: initial and final points only).
  bool record_trajectory = true;

  /// Whether the steps are error-controlled: no replayed step_sequence, and adaptive or no
  /// fixed step (step_size == 0).
  bool ErrorControlled() const { return step_sequence.empty() && (adaptive || step_size == 0.0); }

  /// The Newton settings of the element solves when none are given (tolerances and iteration limits
  /// tuned for the element systems).
  static SemismoothNewtonOptions DefaultNewtonOptions();
  /// Throws std::invalid_argument naming the first out-of-range option.
  void Validate() const;
};

/// Outcome of a FESD run.
enum class FesdStatus {
  kSuccess,                ///< reached the final time
  kNewtonFailure,          ///< a fixed-length element (no switch) did not converge
  kEventLocationFailure,   ///< a switch was detected but no group solve ended on it within
                           ///< max_event_retries (Newton failure or inconsistent signs)
  kStatusDecisionFailure,  ///< no consistent continuation at a switch point
  kStepSizeTooSmall,       ///< error control: the error test failed with the step at its
                           ///< minimum max(min_step_size, 64 eps max(1, |t|))
  kNonFinite,              ///< a model function is not finite at a point the step needs (the
                           ///< message names the function, its output, t and the state); with
                           ///< error control after the step was shortened to its minimum
  kMaxStepsReached,        ///< error control: max_steps steps before the final time
  /// the adjoint sweep found the Jacobian of a converged group singular at its checkpoint
  /// (reciprocal condition below kSingularRcond): no adjoint sensitivities
  kSensitivityFailure,
};
/// The status as text (snake case, as in summary.json).
std::string ToString(FesdStatus status);

/// One finite element of the solution.
struct FesdElement {
  double t_start = 0.0;         ///< integration time at the element start (numerical time tau)
  double physical_start = 0.0;  ///< clock at the element start (= t_start without relays)
  double length = 0.0;          ///< h (in the integration variable)
  bool frozen = false;          ///< physical time frozen on it (a relay jumping)
  bool ends_at_switch = false;  ///< a switch lies on its end boundary
  int newton_iterations = 0;    ///< of the solve that produced it (shared by a group)
  /// ||S Phi||_inf of that solve at convergence: collocation, algebraic, status, velocity-level
  /// and element-length equations (collocation rows scaled by 1 / (1 + |y_start|)).
  double newton_residual = 0.0;
  /// max over pairs and stage pairs (i, j), start boundary included, of |min(a_i, b_j)|:
  /// zero iff one side of every pair vanishes on the whole element and the other is >= 0.
  double cross_complementarity = 0.0;
  double complementarity = 0.0;  ///< max over stages and pairs of |min(a, b)|
};

/// Derivatives of the final scene state (rows) with respect to (columns):
struct FesdSensitivities {
  Matrix initial_state;  ///< n_x x n_x: dx(T)/dx(0)
  Matrix parameters;     ///< n_x x n_p: dx(T)/dp
  /// n_x x (n_u * segments): dx(T)/du_k for the input values u_k held on control segment k
  /// (segments between the scene's control breakpoints, in order).
  Matrix inputs;
  std::vector<double> segment_starts;  ///< start time of every control segment
  /// The whole derivative of the final lowered state y(T) = (x, relay memories, clock):
  /// n_y rows; columns y0 (n_y), then p (n_p), then u per segment (n_u each). The blocks above
  /// are its scene-state parts.
  Matrix lowered;
  /// With FesdOptions::sensitivity_directions (k directions): dx(T)/dtheta V (n_x x k).
  Matrix directional;
  /// The same for the lowered y(T) (n_y x k).
  Matrix directional_lowered;
  /// dx(t_j)/dtheta V (n_x x k) at every FesdOptions::sample_times entry.
  std::vector<Matrix> sample_directional;
  /// With adjoint weights (q functionals): q x (n_x + n_p + n_u S), the gradient of every
  /// functional with respect to theta = (x0, p, u_1..u_S), and q x (n_y + n_p + n_u S) with
  /// respect to the lowered theta_L = (y0, p, u) (adjoint_lowered).
  Matrix adjoint;
  /// q x (n_y + n_p + n_u S): the gradients with respect to theta_L = (y0, p, u_1..u_S).
  Matrix adjoint_lowered;
};

class FesdAdjoint;
namespace internal {
class FesdRun;
}

/// Counters and certificates of a FESD run.
struct FesdStats {
  /// Integration steps taken (accepted steps when adaptive).
  long num_steps = 0;
  /// Finite elements of the accepted solution.
  long num_elements = 0;
  long num_groups = 0;    ///< group solves with the event equation
  long num_switches = 0;  ///< element boundaries with a switch
  /// Newton iterations of all element and group solves.
  long num_newton_iterations = 0;
  /// LU factorizations of the Newton matrices.
  long num_factorizations = 0;
  /// Group solves repeated from another guess while locating a switch.
  long num_event_retries = 0;
  long num_rejected_steps = 0;  ///< adaptive: steps rejected by the error test
  long num_failed_steps = 0;    ///< adaptive: steps whose solves failed, retried smaller
  /// Largest cross-complementarity certificate over the elements (FesdElement).
  double max_cross_complementarity = 0.0;
  /// Largest stage complementarity residual |min(a, b)| over the elements.
  double max_complementarity = 0.0;
  /// Shortest element length.
  double min_element_length = 0.0;
  double frozen_time = 0.0;  ///< numerical time spent with physical time frozen (relays)
  /// Near-active filter: steps solved again because a left-out constraint was not positive
  /// at a stage, and the largest number of pairs in an element system.
  long num_filter_rechecks = 0;
  /// Largest number of complementarity pairs in one element system.
  long max_working_pairs = 0;
  /// Elements solved as a Radau IIA step of a smooth field (FesdOptions::reduce_smooth_elements)
  /// whose full element system then held without a Newton iteration of its own.
  long num_reduced_elements = 0;
  /// Zeros of free sides between an element's nodes (docs/fesd-formulation.md, section 11):
  /// crossings found there (and then located as switches), searches whose bounds admitted a
  /// crossing that the search could not resolve (each one a warning), and the interval
  /// evaluations of the indicators the searches made.
  long num_inside_crossings = 0;
  long num_unresolved_crossings = 0;  ///< (see num_inside_crossings)
  long num_bound_evaluations = 0;     ///< (see num_inside_crossings)
  /// Estimated error of the run relative to the solution's scale: the local error estimates
  /// of the accepted steps accumulated, rtol sum_k (H_k / (tf - t0)) err_k with err_k the
  /// estimate per unit step in the tolerance weights (docs/accuracy.md). Error-controlled runs
  /// keep it near rtol by construction; fixed steps with estimate_error report theirs. -1
  /// where not estimated (fixed steps without estimate_error, replays).
  double error_estimate = -1.0;
  /// Steps whose error could not be estimated (a comparison solve failed); not in
  /// error_estimate.
  long num_unestimated_steps = 0;
  /// Adjoint sensitivities: bytes the run kept in memory for the reverse sweep (converged
  /// unknowns and group data).
  double adjoint_memory_bytes = 0.0;
  double adjoint_file_bytes = 0.0;  ///< checkpoints beyond adjoint_memory_limit_mb (file)
  /// Thread CPU time of the adjoint reverse sweep(s) in this result.
  double adjoint_cpu_seconds = 0.0;
  /// CPU time of the run.
  double cpu_seconds = 0.0;

  /// Sums counters and times; takes the max/min of the extreme values.
  FesdStats& operator+=(const FesdStats& other);
  /// One line for the command line's summary.
  std::string Summary() const;
};

/// Result of SimulateFesd: status, final values, trajectories, events, elements with their
/// certificates, sensitivities and statistics.
struct FesdResult {
  /// kSuccess, or why the run stopped.
  FesdStatus status = FesdStatus::kSuccess;
  /// The time and reason when status != kSuccess.
  std::string message;
  double final_time = 0.0;      ///< physical time reached (the clock)
  Vector final_state;           ///< scene states
  Vector final_lowered_state;   ///< y(T) = (x, relay memories, clock)
  Vector final_algebraic;       ///< algebraic unknowns at the last stage
  Trajectory trajectory;        ///< element ends in physical time (h column: element lengths)
  Trajectory stage_trajectory;  ///< every stage point (with record_stages), physical time
  /// With hysteresis relays: every element end in numerical time tau (frozen ones included),
  /// states y = (x, relay memories w, clock).
  Trajectory numerical_trajectory;
  /// With hysteresis relays: each relay's memory w(t) in physical time.
  std::vector<RelaySignal> relays;
  /// Switch events in physical time (enter, leave, switch, ...).
  std::vector<Event> events;
  /// Every finite element with its certificates (in integration time).
  std::vector<FesdElement> elements;
  /// The accepted steps of an adaptive run (or of a replay) in the form FesdOptions::
  /// step_sequence takes them: the attempted length of every step, 0 for a step to the end
  /// of its control segment.
  std::vector<double> step_sequence;
  FesdSensitivities sensitivities;  ///< with FesdOptions::sensitivities
  /// The lowered state y = (x, relay memories, clock) at every FesdOptions::sample_times.
  std::vector<Vector> sample_states;
  /// With FesdOptions::keep_adjoint: the reverse sweep of this run (shared by copies).
  std::shared_ptr<FesdAdjoint> adjoint;
  /// Counters and certificates.
  FesdStats stats;
  /// What the caller should know although the run succeeded (an estimated error far above
  /// the tolerance, a zero of a free side between an element's nodes that the crossing search
  /// left undecided: a switch may have been stepped over; docs/fesd-formulation.md, section
  /// 11), one sentence each.
  std::vector<std::string> warnings;
};

/// Gradients of q functionals of one run (FesdAdjoint::Sweep).
struct FesdGradient {
  Matrix theta;              ///< q x (n_x + n_p + n_u S): with respect to (x0, p, u_1..u_S)
  Matrix lowered;            ///< q x (n_y + n_p + n_u S): with respect to (y0, p, u_1..u_S)
  double cpu_seconds = 0.0;  ///< thread CPU time of the sweep
  /// False if the Jacobian of a group was singular at its checkpoint (message says where).
  bool success = true;
  std::string message;  ///< why the sweep failed (empty on success)
};

/// The reverse sweep of a finished run (FesdOptions::keep_adjoint): the transpose of the
/// run's directional sensitivities, for weights chosen after the run, e.g. the gradient of a
/// scalar function f(x(T), x(t_1), ..., x(t_K)) from its partial derivatives at the run's
/// final and sample states. Holds the run's group data (FesdStats::adjoint_memory_bytes)
/// and its lowered system. Not thread-safe; with FesdIntegrator, not concurrently with it.
class FesdAdjoint {
 public:
  /// Made by the run (FesdOptions::keep_adjoint), which passes itself; not for applications.
  explicit FesdAdjoint(std::shared_ptr<internal::FesdRun> run);
  /// final_weights: n_x x q or n_y x q (empty: zero); sample_weights: n_x x (q K) or n_y x
  /// (q K) for the K sample times (empty: zero). Throws std::invalid_argument for other
  /// shapes.
  FesdGradient Sweep(const Matrix& final_weights, const Matrix& sample_weights = Matrix()) const;

 private:
  std::shared_ptr<internal::FesdRun> run_;  // the finished run, kept alive
};

/// Simulates `scene` over [t0, tf]. Throws std::invalid_argument for invalid options, an
/// invalid scene or an unsupported effect (naming it).
FesdResult SimulateFesd(const Scene& scene, const FesdOptions& options,
                        const ProgressCallback& progress = {});

/// FESD on one scene, many times (shooting codes, sweeps of initial states and parameters):
/// the options are validated and the scene is lowered once; each Simulate call takes the
/// values of `values` — the same scene with another initial state, horizon, parameter values
/// or input signals (e.g. after SetSceneValue) — and runs exactly as SimulateFesd would on it.
/// Not thread-safe (one object per thread).
class FesdIntegrator {
 public:
  /// Validates the options and lowers the scene once; throws std::invalid_argument as SimulateFesd
  /// does.
  FesdIntegrator(const Scene& scene, const FesdOptions& options);
  ~FesdIntegrator();
  FesdIntegrator(const FesdIntegrator&) = delete;
  FesdIntegrator& operator=(const FesdIntegrator&) = delete;
  /// Throws std::invalid_argument if `values` has another structure than the scene.
  FesdResult Simulate(const Scene& values, const ProgressCallback& progress = {});

 private:
  FesdOptions options_;
  std::shared_ptr<LoweredSystem> system_;  // shared with kept adjoint sweeps
};

}  // namespace moreau
