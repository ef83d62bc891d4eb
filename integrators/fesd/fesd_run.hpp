#pragma once
// The state of one FESD run (docs/fesd-formulation.md, section 5) and the steps of its
// solution procedure. Private to moreau::integrators; split by concern:
//   fesd.cpp               options, the run loop over steps and segments, the result
//   fesd_advance.cpp       one advance: trial elements, switch detection, group solves
//   fesd_smooth.cpp        smooth elements and reduced switch groups (Radau IIA steps of one field)
//   fesd_switches.cpp      status decisions at t0, at switches and at step boundaries
//   fesd_crossings.cpp     zeros of free sides between an element's nodes (bounds, Hermite)
//   fesd_record.cpp        committing solved elements: trajectories and certificates
//   fesd_sensitivities.cpp implicit-function-theorem transfers and saltation
//   fesd_directional.cpp   directional and adjoint sensitivities (sensitivity_tape.hpp)
//   fesd_adaptive.cpp      adaptive steps: the step loop, error estimate, rejection, retries
//   dense_output.cpp       values at requested output times from the collocation polynomials

#include <array>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "../common/constraint_filter.hpp"
#include "../common/crossing_search.hpp"
#include "../common/smooth_collocation.hpp"
#include "../common/step_size.hpp"
#include "group_system.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/newton/semismooth_newton.hpp"
#include "sensitivity_tape.hpp"
#include "step_control.hpp"

namespace moreau::internal {

// Where a free side first turned negative in a solved element: the fraction of the element at
// which it crossed zero (linear interpolation between the last nonnegative sample and the first
// negative one), and its pair (-1 if unknown: an element that did not converge).
struct Violation {
  bool found = false;
  int element = 0;
  double fraction = 1.0;
  int pair = -1;
};

// The local transfer of one solved element or group: [dy_end; dtau_end] as a linear map of
// [dy_start; dtau_start] (state), of dp and of du (implicit function theorem).
struct Transfer {
  Matrix state;       // (n_y + 1) x (n_y + 1)
  Matrix parameters;  // (n_y + 1) x n_p
  Matrix inputs;      // (n_y + 1) x n_u
};

// The collocation polynomial of a committed element, y(t_start + theta h) = y0 + sum_j
// w_j(theta) Z_j (RadauTableau::InterpolationWeights), with the statuses it was solved with.
// Kept only where adaptive steps (error estimate) or dense output need it.
struct ElementPolynomial {
  Vector y0;
  Matrix increments;  // n_y x s: Z_j
  Matrix algebraic;   // n_z x s: stage algebraic values z_j
  double h = 0.0;
  std::vector<bool> a_zero;
  bool frozen = false;
  // The end state y0 + Z_s, into *y (its storage reused).
  void End(Vector* y) const { *y = y0 + increments.col(increments.cols() - 1); }
};

// Everything a solved element or group contributes to the result, captured while its stage
// data and Newton factorization are available; committed if the solution is kept.
struct SolveRecord {
  std::vector<FesdElement> elements;
  std::vector<Vector> ends;       // state y at every element end (with record_trajectory)
  std::vector<Vector> algebraic;  // last-stage algebraic values of every element (idem)
  Trajectory stage_points;        // every stage (with record_stages)
  Vector y_end;
  Vector z_last;
  Vector a_last, b_last;  // pair sides at the last stage (next boundary values)
  double length = 0.0;    // total integration time covered
  bool frozen = false;    // physical time frozen (a relay jumping): not in physical outputs
  Transfer transfer;
  Matrix directions_end;  // directional sensitivities at its end (SensitivityTape::d)
  GroupStep step;         // its checkpoint for the adjoint sweep
  std::vector<ElementPolynomial> polynomials;  // per element, with keep_polynomials_

  // Empties what Record appends to, keeping the capacity (a record reused across steps).
  void ClearLists() {
    elements.clear();
    ends.clear();
    algebraic.clear();
    stage_points.t.clear();
    stage_points.x.clear();
    stage_points.algebraic.clear();
    stage_points.step.clear();
    polynomials.clear();
  }
};

class FesdRun {
 public:
  FesdRun(const Scene& scene, const FesdOptions& options, const ProgressCallback& progress)
      : FesdRun(nullptr, scene, options, progress) {}
  // Runs on an existing lowered system (FesdIntegrator: lowered once, run many times).
  FesdRun(LoweredSystem* system, const FesdOptions& options, const ProgressCallback& progress)
      : FesdRun(system, system->scene(), options, progress) {}

 private:
  FesdRun(LoweredSystem* external, const Scene& scene, const FesdOptions& options,
          const ProgressCallback& progress)
      : options_(Tracking(options)),
        full_(options.sensitivities),
        progress_(progress),
        owned_(external ? std::nullopt
                        : std::make_optional<LoweredSystem>(scene, Lowering(options))),
        system_(external ? *external : *owned_),
        group_(&system_, options.stages),
        filter_(&system_, options.constraint_filter, options.filter_safety),
        newton_(NewtonOptions(options)),
        reduced_newton_(ReducedNewtonOptions(options)),
        tableau_(RadauIIA(options.stages)),
        s_(options.stages),
        nx_(scene.num_states()),
        ny_(system_.num_states()),
        nz_(system_.num_algebraic()),
        np_(system_.num_pairs()) {
    if (nz_ == 0 && !options_.sensitivities) {
      smooth_ = std::make_unique<internal::SmoothCollocationSolver>(&system_, options.stages,
                                                                    options.newton.linear_solver);
    }
    InitializeSmoothFields();
  }

 public:
  FesdResult Run();

  // A kept adjoint (FesdOptions::keep_adjoint) keeps the integrator's lowered system alive.
  void ShareSystem(std::shared_ptr<LoweredSystem> system) { shared_system_ = std::move(system); }

  // The reverse sweep of the finished run (fesd_directional.cpp): weights of y(T) or x(T)
  // (n_y or n_x rows, q columns; empty: zero) and of the sample states (q per sample).
  FesdGradient ReverseSweep(const Matrix& final_weights, const Matrix& sample_weights);

 private:
  static SemismoothNewtonOptions NewtonOptions(const FesdOptions& options);
  // The same without the forced correction (min_iterations = 0): it checks smooth-element
  // solutions, whose stage states a converged Newton of their own produced and whose
  // algebraic values are functions of them (no extrapolated round-off to remove). The check
  // evaluates values only (defer_initial_jacobian).
  static SemismoothNewtonOptions ReducedNewtonOptions(const FesdOptions& options);

  static LoweringOptions Lowering(const FesdOptions& options);
  // The options the run works with: `sensitivities` on (the derivative is tracked) whenever
  // directional or adjoint sensitivities are asked for; full_ says whether the full matrices
  // are formed.
  static FesdOptions Tracking(const FesdOptions& options);

  bool failed() const { return result_.status != FesdStatus::kSuccess; }

  void Integrate();

  // Around every advance of the fixed-step loops: the non-finite witness cleared, and with
  // FesdOptions::estimate_error the advance's elements captured (piece_) and their local
  // error estimated afterwards (EstimateError, as error control does), accumulated into
  // FesdStats::error_estimate.
  void BeginFixedAdvance();
  void EndFixedAdvance();

  // Time-freezing (hysteresis relays): the integration variable is numerical time tau and the
  // clock runs at rate 1, or 0 while a relay jumps. A step that starts while physical time
  // runs has length (target - clock)/n, n = ceil((target - clock)/H), so that the clock lands
  // on the next control breakpoint (or tf) unless something switches; a step that starts
  // frozen has length H (the clock stands still). After a switch a new step starts from the
  // current clock. Sensitivities: row n_y of sensitivity_ tracks tau - step_end, whose
  // derivative at a step start is d(clock)/n (running) or 0 (frozen).
  void IntegrateTimeFreezing();

  // The clock counts as having reached a target within this relative distance (it lands on
  // it up to the Newton tolerance times the step length).
  static constexpr double kClockTolerance = 1e-11;

  // Completes the result and moves it out (the run is over: Run() is called once).
  FesdResult Finish(const RunClock& run_clock);

  void Fail(FesdStatus status, double t, const std::string& reason);

  // Decides the statuses at y_ (the slow solution) and records the events against `previous`
  // (null at t0). Returns false, with the status set, if no continuation exists.
  bool Decide(double t, const std::vector<bool>* previous);

  // A given initial state outside the moving sets jumps onto them (the sweeping process's
  // projection at t0); with sensitivities the transfer of the projection (implicit function
  // theorem on its complementarity system) starts the chain. Returns false on failure.
  bool ProjectInitialState();

  // Index in y of a relay's memory state (relays follow the scene states in order).
  int RelayMemoryIndex(const RelaySignal& signal) const;

  // Algebraic guess at y: consistent values of the continuous variables from y, jump
  // variables (theta, alpha, multipliers) from the velocity-level values v. The result lives
  // in a workspace (no allocation per element) until the next call: copy it to keep it.
  const Vector& ConsistentGuess(const Vector& y, const Vector& v) const;

  // Advances from tau_ towards step_end with `remaining` nominal elements: a trial pass of
  // fixed-length elements; if a free side turns negative, a group solve of equal elements that
  // ends on the switch. Returns true if a switch ended the advance. With the near-active
  // filter, the working set is chosen first, and the advance is solved again (nothing is
  // committed before) if a left-out constraint is not positive at a stage.
  bool Advance(double step_end, int* remaining);
  bool AdvanceOnce(double step_end, int* remaining, bool* retry);

  // --- near-active constraint filter (../common/constraint_filter.hpp) ---------------------
  // Chooses the working set for the next `horizon` of integration time and moves the run's
  // state into the new layout when it changed.
  void UpdateWorkingSet(double horizon);
  void AdoptLayout(const LoweredSystem::WorkingLayout& previous);
  // True if every left-out constraint is positive at the stage points of element w_e (from
  // y0); records the smallest value for the element's certificates (excluded_min_[element]).
  bool FilterCheck(const internal::CollocationStages& stages, const Vector& y0,
                   const ConstVectorRef& w_e, int element);
  // Algebraic values as trajectories record them: every declared pair with the filter on.
  Vector TrajectoryAlgebraic(const Vector& z) const;

  const Vector* last_w_ptr() const { return have_last_w_ ? &last_w_ : nullptr; }

  // --- smooth elements (FesdOptions::reduce_smooth_elements) ------------------------------
  // Which statuses leave a smooth field x' = f(x) (InitializeSmoothFields decides per scene):
  // Stewart's form of one switching effect with exactly one active mode (b = lambda_k = 0
  // kept for one pair only), moving sets with no active constraint (b = lambda = 0 kept
  // for every pair), or hysteresis relays by time-freezing (and nothing else) with every
  // relay in one region or sliding on a memory boundary (theta constant, see RelayTheta).
  enum class Reduction { kNone, kStewartMode, kFreeMovingSets, kRelayModes };
  void InitializeSmoothFields();
  // The field statuses leave (index into smooth_fields_: the mode, or 0), or -1.
  int SmoothField() const { return SmoothField(a_zero_); }
  int SmoothField(const std::vector<bool>& a_zero) const;
  // Relays (Reduction::kRelayModes): theta of every relay under the statuses a_zero, written
  // into *z at the theta unknowns (other entries untouched). Per relay, with the regions
  // mode_A, to_A, to_B, mode_B of docs/lowering.md: one active region k gives theta = e_k
  // (e^T theta = 1, theta_j = 0 for j != k); the active pairs {mode_A, to_A} (sliding on
  // w = 0) or {to_B, mode_B} (on w = 1) give theta = 1/2 on both (w' = a (theta_1 - theta_2
  // + theta_3 - theta_4) = 0 keeps w on the boundary, e^T theta = 1). The state derivative
  // of a relay-only system depends on z through theta alone (docs/lowering.md), so y' =
  // F(y, z) is then a smooth field. Returns false for any other status pattern.
  bool RelayTheta(const std::vector<bool>& a_zero, Vector* z) const;
  // Relays: the algebraic values of a stage at y of a smooth element or reduced group under
  // the statuses a_zero_: theta of the field (relay_field_z_, set by SmoothFieldSolver) and
  // lambda, mu from the stage's Voronoi indicators g with the relay's first active region a
  // (mu = g_a, lambda_k = g_k - g_a: lambda_a = 0 as a_zero_ keeps it), the rest as
  // ConsistentGuess. ConsistentGuess alone takes a from the region that contains y, which
  // past the switching surface (a trial element that crosses it) is another region: the full
  // check then fails on the status rows and takes a Newton iteration with derivatives.
  // The result lives in a workspace until the next call (as ConsistentGuess's).
  const Vector& RelayStageAlgebraic(const Vector& y) const;
  // The Radau IIA solver of the field the statuses a_zero leave, with the run's parameters
  // and inputs (and, for relays, theta) set, or null if they leave none.
  internal::SmoothCollocationSolver* SmoothFieldSolver(const std::vector<bool>& a_zero);
  // The guess *w of one element of length h from y0 (previous: the last element's unknowns
  // for the extrapolation, or null) as a Radau IIA step of that field (its own lowered system,
  // without algebraic unknowns) with algebraic values consistent with the stage states
  // (ConsistentGuess, jump variables from z_guess_). Returns false if the statuses leave no
  // smooth field or that step does not converge (*w is then not a guess).
  // *iterations, *factorizations: the reduced solve's work.
  bool SmoothElementGuess(const Vector& y0, double h, const Vector* previous, Vector* w,
                          int* iterations, long* factorizations);

  // A system without algebraic unknowns (no effects) and no sensitivities cannot switch: every
  // element is a plain Radau IIA step, solved by the same kernel as the smooth Radau IIA
  // integrator (stage increments extrapolated from the previous element's collocation
  // polynomial), and committed at once.
  void AdvanceSmooth(double step_end, int remaining);

  // Stage increments from the previous element's collocation polynomial (weights cached for
  // the step-length ratio).
  void ExtrapolatedIncrements(double h, Matrix* z);

  // After a stretch without a switch: a free side that is zero at its end (a switch exactly
  // on a step boundary, or at the final time) is decided there.
  bool DecideAtBoundary();

  // At a control breakpoint, with the new input values set: consistent velocity-level values,
  // and new statuses where a free side is zero or negative under the new inputs (an external
  // switch commutating a diode). The switch time is the breakpoint itself, which does not
  // move with the data: no saltation. Returns false on failure (status set).
  bool DecideAtBreakpoint();

  // A switch found exactly on a step boundary was not located by an event equation, so the
  // local transfers miss how its time moves with the data. The saltation matrix restores it:
  // with iota the indicator of pair k under the old statuses (its total derivative includes
  // the velocity-level values, v = v(y, p, u) from E(y, v, p, u) = 0), the switch time moves by
  // dtau_s = -(diota)/(diota/dtau), diota/dtau = iota_y F_-, and the state at the boundary by
  // (F_- - F_+) dtau_s, F_-/F_+ the fields before and after the switch.
  void ApplySaltation(const std::vector<bool>& before, const Vector& v_before, int k);

  // Reduced switch group (smooth elements, docs/fesd-formulation.md section 5): where the
  // statuses leave a smooth field (hysteresis relays, Reduction::kRelayModes), the group of m equal
  // elements that ends on the switch of `pair` is solved as m Radau IIA steps of that field whose
  // common length h is the root of the pair's scaled indicator at the end state (as in the event
  // equation: w_k iota_k(y_end, v_end) / tau^{p_k}, v_end the velocity level at y_end), found
  // from the interpolated crossing (CrossingGuess, else h_guess) by a Newton step (continuous free
  // sides) or a secant through h_trial (the trial elements' end, no solve), then secant steps
  // kept inside a bracket once there is one. *w receives
  // the group's unknowns (stage states, algebraic values consistent with them, v_end, h), the guess
  // that the full group system is then checked at. Returns false if the statuses leave no smooth
  // field or the iteration fails (the full group solve then starts from GroupGuess).
  // `element`: the trial element the switch was detected in.
  bool ReducedSwitchGuess(const std::vector<Vector>& trial_w, const Vector& y_start, double h_trial,
                          int element, int m, double h_guess, int pair, double weight, int power,
                          Vector* w, int* iterations, long* factorizations);
  // The element length of m equal elements that end where the interpolant of pair k's
  // continuous free side through the start and the stages of trial element `element` (their
  // values at the trial solution) crosses zero: a first guess accurate to the interpolant's
  // order s + 1 where the linear crossing fraction of the checks is accurate to second order.
  // h_guess if the free side is a jump side or does not cross.
  double CrossingGuess(const std::vector<Vector>& trial_w, const Vector& y_start, double h_trial,
                       int element, int pair, int m, double h_guess);

  // Guess of a group of m elements of length h_guess from the trial elements: their stage
  // increments rescaled by h_guess / h_trial, or with on_trajectory the stage states on the
  // trial elements' collocation polynomials (a guess accurate to their local error).
  Vector GroupGuess(const std::vector<Vector>& trial_w, const Vector& y_start, double h_trial,
                    int m, double h_guess, const Vector& v_end, bool on_trajectory);
  // Raises the event weights of a switch group (fesd_advance.cpp) so that every scaled
  // indicator is at least 1 where the group starts; used after a try did not converge.
  void NormalizeIndicatorWeights(const std::vector<Vector>& trial_w, const Vector& y_start,
                                 Vector* weights);

  // True if pair k's free side (the side its status does not keep at zero) is a jump variable
  // (an active constraint's multiplier, a sliding mode's theta or alpha). Stage values of those
  // are order-s approximations of the consistent (velocity-level) values; they are never
  // used for sign decisions. (Inline: the per-stage checks ask for every pair.)
  bool FreeSideIsJump(int k) const {
    const ContinuousSide side = system_.pairs()[static_cast<std::size_t>(k)].continuous;
    if (side == ContinuousSide::kBoth) return false;  // index-1 pairs: both sides continuous
    const bool continuous_a = side == ContinuousSide::kA;
    return a_zero_[static_cast<std::size_t>(k)] == continuous_a;
  }

  // The first stage at which a continuous free side is negative beyond tolerance, with the
  // crossing fraction (jump free sides are checked at element ends, see EndViolation).
  Violation StageViolation(const internal::CollocationStages& stages, const Vector& scales,
                           int element) const;

  // The velocity level at an element end as EndViolation leaves it: solved (v), or deferred
  // where the statuses give the event indicators in closed form (JumpFreeSidesInClosedForm):
  // then v is unchanged and (y, z), the end state and the last stage's algebraic values, say
  // where ResolveVelocity solves it when it is used (group guesses, the next step's start).
  struct EndVelocity {
    Vector v;
    bool deferred = false;
    Vector y, z;
  };
  // Solves a deferred velocity level (v is kept if that solve fails, as EndViolation keeps it).
  void ResolveVelocity(EndVelocity* end) const;
  // Event indicators at y (the state `velocity` belongs to) with the statuses a_zero_: jump
  // sides from velocity.v, or in closed form if it is deferred.
  void IndicatorsAt(const Vector& y, const EndVelocity& velocity, IndicatorEvaluation* out) const;

  // Event indicators at the end state y of an element (velocity-level values solved from
  // end->v, which is updated, or deferred, see EndVelocity): the first negative one beyond
  // tolerance is a switch in the element.
  Violation EndViolation(const internal::CollocationStages& stages, const Vector& y,
                         const Vector& scales, int element, EndVelocity* end) const;

  // Statuses that leave a smooth field (SmoothField() >= 0) fix the consistent value of every
  // jump free side without a velocity-level solve. Stewart's form with one active mode k
  // (reduction kStewartMode): the velocity-level rows on values, theta_j = 0 kept for j != k
  // and e^T theta = 1, alone give theta = e_k, so pair k's free side theta_k is 1 and every
  // other free side (lambda_j) is continuous. Moving sets without an active constraint
  // (kFreeMovingSets): every jump side (lambda) is kept at zero, no free side is a jump.
  // Hysteresis relays (kRelayModes): the free sides theta of the active regions are
  // RelayTheta's values (1, or 1/2 on a memory boundary). Sets
  // the jump entries of *free (n_pairs) and returns true, or returns false (no smooth field).
  bool JumpFreeSidesInClosedForm(Vector* free) const;

  // Adaptive steps (and replays): the first stage at which a jump free side, evaluated
  // consistently from the stage state (velocity level, ConsistentFreeSides), is negative
  // beyond tolerance. Long elements can hold two roots of a multiplier or theta, which the
  // check at element ends misses (fesd_adaptive.cpp).
  Violation JumpStageViolation(const internal::CollocationStages& stages, const Vector& scales,
                               int element) const;

  // Zeros of the continuous free sides between the nodes of a solved element (start y0, stage
  // unknowns w_e), where the checks at the stages and the end see none: the crossing search of
  // common/crossing_search.hpp on the element's collocation polynomial, with bounds from the
  // model functions (LoweredSystem::BoundEventIndicators) and, for free sides without bounds,
  // the extremum of the Hermite interpolant of their values and exact derivatives at the start
  // and the stages. A crossing is a violation in `element` at the fraction of its first zero.
  // A search that stays unresolved is counted (FesdStats::num_unresolved_crossings, the first
  // time in first_unresolved_time_) and gives no violation.
  Violation InsideViolation(const internal::CollocationStages& stages, const Vector& y0,
                            const ConstVectorRef& w_e, const Vector& scales, int element);
  // Error-controlled runs: zeros of the jump free sides between the stages of a solved element
  // (a multiplier that turns negative and back between two stages: a release shorter than
  // the element), from consistent velocity-level solves at points of the collocation
  // polynomial where the stage values suggest a dip (fesd_crossings.cpp). Called by
  // InsideViolation once the continuous sides show no crossing.
  Violation JumpDipViolation(const internal::CollocationStages& stages, int element);

  // Crossing fraction of pair k between the second-to-last stage and a negative end value.
  double EndCrossing(const internal::CollocationStages& stages, int k, double end_value) const;

  void CountNewton(const SemismoothNewtonResult& solved);

  // Captures the elements of the system just solved (group_ holds its stage data and Newton
  // its factorization). a0, b0: pair sides at the last stage before it (boundary values).
  // `remaining` is the element count that fixed the lengths (h = rest / remaining). Fills
  // *out, reusing its vectors (a kept record: no allocation per element).
  void Record(const Vector& w, double h, bool ends_at_switch, const SemismoothNewtonResult& solved,
              int remaining, const Vector& a0, const Vector& b0, SolveRecord* out);

  // Takes the record's stage points by move (its other vectors stay, for reuse by Record).
  void Commit(SolveRecord& record);

  // Free side of every pair at stage i: continuous sides from the stage values, jump sides
  // consistent with the stage state (closed form where JumpFreeSidesInClosedForm gives them,
  // else the velocity level at the stage state, solved from the stage's evaluation if it has
  // derivatives), see FreeSideIsJump.
  Vector ConsistentFreeSides(const internal::CollocationStages& stages, int i) const;
  void ConsistentFreeSides(const internal::CollocationStages& stages, int i,
                           Vector* free) const;  // the same into *free (no allocation)

  // Certificates of an element (see FesdElement): the enforced side of every pair at the
  // stages and at the start boundary (its continuous side) against the consistent free sides.
  void Certificates(const internal::CollocationStages& stages, const Vector& a0, const Vector& b0,
                    FesdElement* element) const;

  // --- sensitivities ------------------------------------------------------------------------
  void InitializeSensitivities();

  // Implicit function theorem on the converged system R(w; y_start, tau_start, p, u) = 0:
  // dw = -R_w^{-1} (R_y dy_start + R_tau dtau_start + R_p dp + R_u du), with R_w the generalized
  // Jacobian that Newton factorized at the solution. The element lengths depend on tau_start
  // through h = rest / count (fixed elements), h_max = rest / m and h_ref = rest / remaining.
  Transfer LocalTransfer(const Vector& w, int group_elements, int remaining);

  void ApplyTransfer(const Transfer& transfer);

  // --- directional and adjoint sensitivities (fesd_directional.cpp) -----------------------
  // Each Track* applies one step of the derivative to what the run tracks: the full
  // matrices (full_), the directions (tape_.d) and the adjoint tape.
  void InitializeTape();
  // A solved group (Record): its full transfer, its directions at the end from those at its
  // start (the committed ones, or the previous record's when a0 is that record's a_last: the
  // trial pass records elements before committing them), its checkpoint.
  void TrackGroup(const Vector& w, int group_elements, int remaining, const Vector& a0,
                  SolveRecord* record);
  // A committed record (Commit), then the sample time it may reach.
  void CommitTracks(SolveRecord& record);
  // Time-freezing: a running step of length (target - clock) / n (n > 0), or a frozen one
  // (n = 0), sets the tau row.
  void TrackClock(int clock, double n);
  // Adaptive steps and replays: a step starts (sensitivity_tape.hpp, StepStart).
  void TrackStepStart(bool lands, bool clock_targets);
  // The initial projection onto the moving sets (its derivative).
  void TrackProjection(const Matrix& d_x0, const Vector& d_t, const Matrix& d_p, const Matrix& d_u);
  // Directional: dw = -R_w^{-1} (B [d]) for every direction, from the factorization at the
  // solution; *end = the directions after the group.
  void GroupForward(const Vector& w, int group_elements, int remaining, const Matrix& start,
                    Matrix* end);
  // Adjoint: the transpose of GroupForward at a checkpoint (re-evaluated and refactorized).
  // Returns false (with *message) if the Jacobian at the checkpoint is singular.
  bool GroupTransposed(const GroupStep& step, Matrix* lambda, Matrix* gradient,
                       std::string* message);
  // The FB derivatives of the element-length pair that the transfers use.
  void EventWeights(const Vector& w, double* da, double* db) const;
  // Results of the directional and adjoint sensitivities (Finish).
  void FinishSensitivities();

  // --- adaptive steps (fesd_adaptive.cpp) ---------------------------------------------------
  // The run loop with adaptive steps (or a replayed step sequence): per control segment, steps
  // of length H chosen by the controller, each one Advance (it ends at the first switch),
  // accepted by the error estimate or rolled back and retried shorter. clock_targets: time-
  // freezing (steps in numerical time, the clock lands on the segment end).
  void IntegrateAdaptive(bool clock_targets);

  // Everything an attempted step may change, to roll it back (work counters stay).
  struct Snapshot {
    Vector y, z_guess, z_last, boundary_a, boundary_b, last_w;
    EndVelocity velocity;
    double tau = 0.0, last_h = 0.0, first_unresolved_time = 0.0;
    bool have_last_w = false;
    std::vector<bool> a_zero;
    std::vector<bool> working;  // the near-active filter's working set
    Matrix last_z_matrix, sensitivity;
    Eigen::RowVectorXd d_step_end;
    SensitivityTape::Mark tape;
    std::size_t trajectory = 0, stage_trajectory = 0, numerical_trajectory = 0, events = 0,
                elements = 0, next_output = 0;
    std::vector<std::size_t> relay_jumps;
    FesdStats stats;
  };
  void Save(Snapshot* snapshot) const;
  void Restore(const Snapshot& snapshot);

  // Hairer-Wanner's starting step for order p = 2s - 1 from F at y_ and at an Euler step,
  // times the elements per step (the heuristic sizes one collocation element).
  double StartingStep(double span);

  // Local error estimate of the elements committed by the last attempt (piece_: m elements of
  // length h with one set of statuses), Richardson extrapolation against a solution of the
  // same interval with one element of length m h (m >= 2) or two of h/2 (m = 1):
  //   m >= 2: le = (y_coarse - y_m) / (m^p - 1),  m = 1: le = (y_1 - y_halves) 2^p / (2^p - 1).
  // Returns max_i |le_i| / allowed_i over the lowered states, allowed_i = (atol + rtol
  // max(|y_start_i|, |y_end_i|)) `fraction` (error per unit step: fraction is the part of the
  // horizon the piece covers), but never below what floating point resolves (proposal) and
  // the solves resolve (acceptance; see kNewtonNoise); infinity if a comparison solve fails.
  // first_element: the piece's first element in result_.elements.
  struct ErrorEstimate {
    double acceptance = 0.0;  // the step is accepted iff <= 1
    double proposal = 0.0;    // what the controller sizes the next step by
  };
  ErrorEstimate EstimateError(double fraction, std::size_t first_element);

  // How well the piece's elements resolve the continuous free sides (the functions whose sign
  // changes are switches): the largest, over elements, pairs and two test points in the
  // widest gaps between the element start and the stages, of |value - interpolant| / range,
  // the interpolant through the start and the stages, the range over all of them. Infinity
  // if a free side is negative at a test point (a switch between the checked points).
  double IndicatorResolution() const;
  struct ResolutionGrid;
  const ResolutionGrid& Resolution() const;  // the grid of s_ stages (made once per process)
  static void MakeResolutionGrid(const RadauTableau& tableau, ResolutionGrid* grid);

  // Solves one fixed-length element from y0 with the given statuses (comparison solutions of
  // EstimateError), initial guess from the piece's collocation polynomials. Returns false if
  // Newton does not converge; *y_end is the element's end state.
  bool SolveComparisonElement(const Vector& y0, double t0, double h,
                              const std::vector<bool>& a_zero, Vector* y_end);

  // The state of the piece's collocation polynomials at offset `offset` from the piece start,
  // with the algebraic values of the nearest stage (guesses for comparison solves).
  void PieceState(double offset, Vector* y, Vector* z) const;

  // Called for every committed element (Commit, AdvanceSmooth) when keep_polynomials_: the
  // adaptive attempt's piece and the dense output.
  // Takes the element (a record's polynomials are not read after Commit).
  void OnCommittedElement(ElementPolynomial&& element);

  // --- dense output (dense_output.cpp) ------------------------------------------------------
  // Sorts and checks the output times (output_times and the output_step grid), throws
  // std::invalid_argument for times outside [t0, tf].
  void PrepareOutputTimes();
  // Appends the output times inside a committed element to the trajectory.
  void DenseOutput(const ElementPolynomial& element);

  FesdOptions options_;
  bool full_ = false;  // FesdOptions::sensitivities as given: full matrices
  ProgressCallback progress_;
  std::shared_ptr<LoweredSystem> shared_system_;  // kept alive for a kept adjoint
  std::optional<LoweredSystem> owned_;            // empty when running on an external system
  LoweredSystem& system_;
  GroupSystem group_;
  NearActiveFilter filter_;
  std::vector<double> excluded_min_;  // per element of the current solve (FilterCheck)
  SemismoothNewton newton_;
  SemismoothNewton reduced_newton_;  // smooth elements (ReducedNewtonOptions)
  // The Newton that solved the system Record captures (its factorization at the solution
  // serves LocalTransfer with sensitivities).
  const SemismoothNewton* solved_by_ = &newton_;
  const RadauTableau& tableau_;
  int s_, nx_, ny_, nz_, np_;
  FesdResult result_;
  Vector y_;
  double tau_ = 0.0;
  std::vector<bool> a_zero_;
  // The velocity level at y_ with the statuses a_zero_: solved, or deferred (EndVelocity: the
  // trial pass ended with indicators in closed form) until something reads it through v().
  // Every change of a_zero_ sets it anew (Decide), so a deferred one keeps its statuses.
  // Indicators at y_ need only its jump entries (StartIndicators: closed form when deferred).
  mutable EndVelocity velocity_;
  const Vector& v() const {
    ResolveVelocity(&velocity_);
    return velocity_.v;
  }
  void set_v(const Vector& v) {
    velocity_.v = v;
    velocity_.deferred = false;
  }
  Vector z_guess_;  // algebraic guess for the next element
  Vector z_last_;
  Vector boundary_a_, boundary_b_;  // pair sides at the last stage of the previous element
  Vector last_w_;                   // last committed element (for extrapolated guesses)
  bool have_last_w_ = false;
  double last_h_ = 0.0;
  // The stretches the run steps through: ends at the control breakpoints and the stop times
  // (StretchEnds), the control segment of each, and the start of every control segment.
  std::vector<double> segment_ends_;
  std::vector<int> segment_control_;
  std::vector<double> control_starts_;
  int segment_ = 0;  // the control segment being integrated (input sensitivities)
  // True if stretch `segment` starts a control segment after the first (new input values).
  bool StartsControlSegment(std::size_t segment) const {
    return segment > 0 && segment_control_[segment] != segment_control_[segment - 1];
  }
  long factorizations_ = 0;
  Matrix sensitivity_;                                         // d(y, tau) / d(x0, p, u)
  std::unique_ptr<internal::SmoothCollocationSolver> smooth_;  // elements without pairs
  // Smooth elements: per field a Radau IIA solver, built on first use, and for free moving sets
  // the lowered system of the dynamics alone (Stewart modes and relays evaluate their fields
  // on system_ itself); empty if the scene does not reduce.
  struct FieldSolver {
    std::unique_ptr<LoweredSystem> system;
    std::unique_ptr<internal::SmoothCollocationSolver> solver;
  };
  Reduction reduction_ = Reduction::kNone;
  std::vector<FieldSolver> smooth_fields_;
  // kRelayModes: per relay the indices in z of theta and lambda for its regions mode_A, to_A,
  // to_B, mode_B and of mu, and the fixed algebraic values of the field (RelayTheta).
  struct RelayUnknowns {
    std::array<int, 4> theta{}, lambda{};
    int mu = -1;
  };
  std::vector<RelayUnknowns> relay_theta_;
  Vector relay_field_z_;
  Matrix smooth_field_z_;  // stage increments of a smooth-element solve (n_y x s)
  Matrix smooth_z_, last_z_matrix_, extrapolation_;
  // ReducedSwitchGuess's stage increments per element and field evaluation (kept across groups).
  std::vector<Matrix> switch_z_;
  struct SwitchBuffers {  // ReducedSwitchGuess's workspace, kept across groups
    Vector level, solved_v, y_end, weights;
    Matrix rescale, product;
  };
  SwitchBuffers switch_buffers_;
  mutable Vector piece_weights_;         // PieceState's interpolation weights (kept: no allocation)
  std::vector<double> crossing_values_;  // CrossingGuess's node values (kept: no allocation)
  PointEvaluation switch_field_;
  double extrapolation_ratio_ = -1.0;
  // InsideViolation's workspace (kept across elements).
  struct InsideBuffers {
    PolynomialPath path;
    Matrix increments;
    std::vector<char> watched, end_grazes;
    // box_lower/upper: the box of the path that BoundEventIndicators reads.
    Vector thresholds, y, dy, box_lower, box_upper, end_values, probe;
    Eigen::RowVectorXd row;  // a row of at.d_y
    IndicatorEvaluation at;
    std::vector<Vector> node_values, node_slopes;
    std::vector<double> values, slopes;
    CrossingWorkspace search;
  };
  InsideBuffers inside_;
  mutable Vector end_solved_;    // EndViolation's velocity-level solution (kept across elements)
  mutable Vector filter_state_;  // FilterCheck's stage state
  // Advance's fallback: the state before the step, and the search switched off while the step
  // is taken again without it.
  Snapshot advance_before_;
  bool inside_search_off_ = false;
  double first_unresolved_time_ = std::numeric_limits<double>::infinity();
  // Adaptive steps and dense output.
  bool keep_polynomials_ = false;         // record ElementPolynomial of committed elements
  bool estimating_ = false;               // fixed steps with FesdOptions::estimate_error
  std::size_t estimate_from_ = 0;         // first element of the advance being estimated
  double estimate_tau_ = 0.0;             // and its start
  StateScale scale_;                      // per lowered state: the largest |y_i| so far
  bool check_jump_stages_ = false;        // JumpStageViolation in the trial pass and groups
  bool capture_piece_ = false;            // collect them in piece_ (adaptive attempts)
  std::vector<ElementPolynomial> piece_;  // elements committed by the current attempt
  // Polynomials no longer read (records cleared, pieces done), kept with their storage for the
  // next elements' (Record): a steady step makes and drops them without allocating.
  std::vector<ElementPolynomial> spare_polynomials_;
  void RecyclePolynomials(std::vector<ElementPolynomial>* list);
  ElementPolynomial SparePolynomial();  // a recycled one (members to overwrite), or a new one
  double comparison_residual_ = 0.0;    // largest Newton residual of comparison solves
  struct ComparisonBuffers {            // SolveComparisonElement's vectors, kept across comparisons
    Vector base, z;
    std::vector<Vector> states, algebraic;
    Matrix increments;
    GroupSetup setup;
    Vector guess;
    SemismoothNewtonResult solved;
    // EstimateError's: the piece's end, the comparison solutions and the local error.
    Vector piece_end, coarse, half, fine, local;
  };
  ComparisonBuffers comparison_;
  struct ResolutionBuffers {  // IndicatorResolution's workspace, kept across steps
    IndicatorEvaluation at;
    std::vector<int> continuous;
    Vector v, y, predicted;
    Matrix node_values, dense;
  };
  mutable ResolutionBuffers resolution_;
  Eigen::RowVectorXd d_step_end_;               // d(step end)/d(x0, p, u) of the last step
  SensitivityTape tape_;                        // directional and adjoint sensitivities
  const Vector* pending_a_last_ = nullptr;      // TrackGroup's last record (its a_last) ...
  const Matrix* pending_directions_ = nullptr;  // ... and its directions at its end
  std::map<int, std::unique_ptr<LinearSolver>> reverse_solvers_;  // the sweep's, by size
  SystemMatrix reverse_jacobian_;
  bool dense_output_ = false;         // output times replace element ends
  std::vector<double> output_times_;  // sorted, in (t0, tf]
  std::size_t next_output_ = 0;
  // DenseOutput's workspaces: interpolation weights, their derivative, the interpolated state.
  Vector output_weights_, output_slope_weights_, output_state_;
  // Workspaces of the per-element checks and certificates (const members, no allocation per
  // element): event indicators and the consistent free sides of each stage.
  mutable IndicatorEvaluation indicators_;
  mutable std::vector<Vector> free_sides_;
  mutable Vector stage_y_, stage_v_;  // a stage state and its consistent velocity level
  mutable Vector closed_free_;        // JumpFreeSidesInClosedForm's scratch
  mutable Vector closed_theta_;       // and its relays' theta (RelayTheta)
  mutable Vector consistent_z_;       // ConsistentGuess's result
  mutable Vector relay_stage_z_;      // RelayStageAlgebraic's result
  // IndicatorResolution's points in an element (fractions of it) and the Lagrange weights of
  // the nodes there; they depend on the tableau only (Resolution: made once per run).
  struct ResolutionGrid {
    std::vector<double> nodes;  // 0, c_1, ..., c_s
    std::vector<double> tests;  // the midpoints of the two widest gaps between nodes
    Matrix test_weights;        // row t: the weights at tests[t]
    Matrix dip_weights;         // row m: the weights at the dip search's sample m
    // The collocation polynomial's weights (RadauTableau::InterpolationWeights) at the nodes
    // and the tests.
    std::vector<Vector> node_state_weights, test_state_weights;
    Matrix differences;  // (l, j): nodes[j] - nodes[l] (CrossingGuess's denominators)
  };
  Vector boundary_scaled_;  // DecideAtBoundary's scaled indicators
  // The consistent velocity level and indicators that EndViolation solved at an element's end
  // state, which is its last stage (c_s = 1), from that stage's evaluation and algebraic
  // values: the element's certificates need the same solve there (ConsistentFreeSides with the
  // same y, statuses, z and evaluation), so they take it from here. Keyed by y and z (bitwise)
  // and valid only until the next element system is evaluated (Record follows EndViolation).
  struct EndLevel {
    bool valid = false;
    std::vector<bool> a_zero;
    Vector y, z, indicators;
  };
  mutable EndLevel end_level_;
  // AdvanceOnce's per-step vectors, kept across steps so that a step does not allocate them
  // again (AdvanceOnce is not reentrant: Decide and the checks it calls do not advance).
  struct AdvanceBuffers {
    Vector y_start, y, y_next, scales;
    // NormalizeIndicatorWeights's evaluations: the indicators at y_start and at the first stage.
    IndicatorEvaluation start_indicators, first_stage_indicators;
    Vector first_stage_state;
    std::vector<int> powers;
    std::vector<SolveRecord> records;  // the trial pass's elements (the first num_records)
    std::size_t num_records = 0;
    SolveRecord group_record;     // a group's elements
    std::vector<Vector> trial_w;  // their solutions
    EndVelocity v_end;
    GroupSetup trial_setup;  // only y_start, a_zero and h_fixed are ever set
    Vector guess;
    GroupSetup group_setup;  // a switch group's (every member set per attempt)
    Vector group_guess;
    // The Newton result of the current element or group, kept so that its solution and
    // history keep their storage across solves, and the trial solutions' vectors once
    // trial_w is cleared, taken again for the next step's (a steady step allocates none).
    SemismoothNewtonResult solved;
    std::vector<Vector> spare_w;
  };
  AdvanceBuffers advance_;
};

}  // namespace moreau::internal
