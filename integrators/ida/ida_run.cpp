// One IDA run: SUNDIALS set-up, the run over control segments, phases, restarts and events
// (ida_run.hpp).

#include "ida_run.hpp"

#include <ida/ida.h>
#include <ida/ida_ls.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunlinsol/sunlinsol_klu.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunmatrix/sunmatrix_sparse.h>

#include <cstdlib>
#include <limits>
#include <sstream>

#include "moreau/core/clock.hpp"
#include "moreau/integrators/simulate.hpp"

namespace moreau::internal {
namespace {

// KLU's ordering codes (SUNLinSol_KLUSetOrdering): 0 AMD, 1 COLAMD, 2 natural.
constexpr int kKluOrderingAmd = 0;

}  // namespace

IdaRun::IdaRun(const Scene& scene, const IdaOptions& options, const ProgressCallback& progress)
    : options_(options), progress_(progress), system_(scene, Lowering(options)) {
  ny_ = system_.num_states();
  nx_ = system_.num_scene_states();
  nz_ = system_.num_algebraic();
  ng_ = system_.num_equations();
  np_ = system_.num_pairs();
  nr_ = static_cast<int>(system_.relay_names().size());
  for (int i = 0; i < nz_; ++i) {
    if (system_.continuous_algebraic()[static_cast<std::size_t>(i)]) continuous_.push_back(i);
  }
  nc_ = static_cast<int>(continuous_.size());
  n_ = ny_ + nc_ + nz_;
  // Index-1 pairs (both sides continuous): their multiplier b = z_j is an IDA algebraic
  // component determined by the kept side at position level (docs/complementarity.md).
  position_pair_.assign(static_cast<std::size_t>(nc_), -1);
  for (int k = 0; k < np_; ++k) {
    const PairInfo& info = system_.pairs()[static_cast<std::size_t>(k)];
    if (info.continuous != ContinuousSide::kBoth) continue;
    const auto it = std::find(continuous_.begin(), continuous_.end(), info.b_unknown);
    MOREAU_ASSERT(it != continuous_.end(), "an index-1 pair's b must be a continuous unknown");
    position_pair_[static_cast<std::size_t>(it - continuous_.begin())] = k;
  }
  // IDA column of each algebraic unknown: continuous ones are carried as z_c, jump ones are
  // their velocity-level slots. IDA row of each index-1 position-level condition.
  z_column_.resize(static_cast<std::size_t>(nz_));
  for (int i = 0; i < nz_; ++i) z_column_[static_cast<std::size_t>(i)] = ny_ + nc_ + i;
  position_row_.assign(static_cast<std::size_t>(nz_), -1);
  for (int c = 0; c < nc_; ++c) {
    z_column_[static_cast<std::size_t>(continuous_[static_cast<std::size_t>(c)])] = ny_ + c;
    const int k = position_pair_[static_cast<std::size_t>(c)];
    if (k >= 0) position_row_[static_cast<std::size_t>(ng_ + k)] = ny_ + c;
  }
  tested_.assign(static_cast<std::size_t>(n_), false);
  for (int i = 0; i < nx_; ++i) tested_[static_cast<std::size_t>(i)] = true;
  for (int c = 0; c < nc_; ++c) {
    tested_[static_cast<std::size_t>(ny_ + c)] = position_pair_[static_cast<std::size_t>(c)] < 0;
  }
  const bool sparse_dynamics = scene.dynamics.has_sparse_state_jacobian();
  sparse_ = options.linear_solver == LinearSolverKind::kSparseLu ||
            options.linear_solver == LinearSolverKind::kKlu ||
            (options.linear_solver == LinearSolverKind::kAutomatic &&
             (sparse_dynamics || n_ > kDenseSizeLimit));
  RequireArgument(!sparse_dynamics || sparse_,
                  "dynamics with a hand-written sparse Jacobian need the sparse linear solver");
}

IdaRun::~IdaRun() {
  if (memory_ != nullptr) IDAFree(&memory_);
  if (linear_solver_ != nullptr) SUNLinSolFree(linear_solver_);
  if (matrix_ != nullptr) SUNMatDestroy(matrix_);
}

IdaResult IdaRun::Run() {
  const RunClock run_clock;
  const Scene& scene = system_.scene();
  result_.trajectory.state_names = scene.state_names;
  result_.trajectory.algebraic_names = system_.algebraic_names();
  for (int i = 0; i < nr_; ++i) {
    RelaySignal signal;
    signal.relay = system_.relay_names()[static_cast<std::size_t>(i)];
    result_.relays.push_back(signal);
  }
  output_times_ = options_.output_times;
  std::sort(output_times_.begin(), output_times_.end());
  y_ = system_.InitialState();
  for (int i = 0; i < nr_; ++i)
    result_.relays[static_cast<std::size_t>(i)].initial_value = static_cast<int>(y_[nx_ + i]);
  const double t0 = scene.initial_time;
  std::vector<int> control;  // the control segment of every stretch
  const std::vector<double> ends =
      StretchEnds(t0, scene.final_time, scene.ControlBreakpoints(), options_.stop_times, &control);
  Y_ = std::make_unique<SerialVector>(n_, context_.context);
  Yp_ = std::make_unique<SerialVector>(n_, context_.context);
  dky_ = std::make_unique<SerialVector>(n_, context_.context);
  CreateSolver(t0);

  // Relays whose memory is inconsistent with psi(x0) switch at t0.
  SwitchRelays(t0, system_.MemorySwitchingFunctions(y_), /*initial=*/true);
  if (Decide(t0, nullptr)) {
    Record(t0, 0.0);
    for (std::size_t segment = 0; segment + 1 < ends.size() && !failed(); ++segment) {
      system_.SetInputs(scene.InputValues(ends[segment]));
      // New input values at a breakpoint: decide there (an indicator may be zero) and
      // restart from consistent values.
      const bool new_inputs = segment > 0 && control[segment] != control[segment - 1];
      if (new_inputs && !DecideAtBoundary(ends[segment])) break;
      Integrate(ends[segment + 1]);
    }
    // An event exactly at tf.
    if (!failed()) DecideAtBoundary(scene.final_time);
  }
  result_.final_time = t_;
  result_.final_state = y_.head(nx_);
  if (result_.trajectory.t.empty() || result_.trajectory.t.back() != t_) Record(t_, 0.0);
  if (result_.stats.num_unresolved_crossings > 0) {
    std::ostringstream warning;
    warning.precision(10);
    warning << result_.stats.num_unresolved_crossings
            << (result_.stats.num_unresolved_crossings == 1 ? " step" : " steps")
            << " (the first from t = " << first_unresolved_time_
            << ") where the bounds of a root function on IDA's interpolant admit a zero that the "
               "search could not resolve: an event may have been stepped over; bound the step "
               "(max_step) or give its time as a breakpoint (tstops)";
    result_.warnings.push_back(warning.str());
  }
  // The last phase's counters: a run that fails inside a phase has no IDAReInit after it
  // (hard_corner with the Newton factor 0.001 reported 48 steps after 10^7).
  AccumulateStats();
  result_.stats.cpu_seconds = run_clock.CpuSeconds();
  return result_;
}

LoweringOptions IdaRun::Lowering(const IdaOptions& options) {
  LoweringOptions lowering;
  lowering.switching_form = options.switching_form;
  lowering.relay_form = RelayForm::kDiscreteMemory;
  // Sparse with KLU, else automatic (sparse for large systems and hand-written sparse
  // dynamics): the phase Jacobian is assembled from either storage (AssembleJacobian).
  lowering.storage = StorageForLinearSolver(options.linear_solver);
  return lowering;
}

void IdaRun::Fail(IdaStatus status, double t, const std::string& reason) {
  if (failed()) return;
  result_.status = status;
  std::ostringstream s;
  s.precision(17);
  s << ToString(status) << " at t = " << t << ": " << reason;
  result_.message = s.str();
}

void IdaRun::SizeBoundedRootPaths() {
  BoundedRootBuffers& b = bounded_root_;
  for (int order = 1; order <= kMaxBdfOrder; ++order) {
    internal::PolynomialPath& path = b.paths[static_cast<std::size_t>(order)];
    if (path.coefficients().rows() != n_) path.SetShape(n_, order);
  }
}

void IdaRun::CreateSolver(double t0) {
  memory_ = IDACreate(context_.context);
  MOREAU_ASSERT(memory_ != nullptr, "IDACreate failed");
  View(Y_->vector).setZero();
  View(Yp_->vector).setZero();
  Check(IDAInit(memory_, &IdaRun::ResidualCallback, t0, Y_->vector, Yp_->vector), "IDAInit");
  Check(IDASetUserData(memory_, this), "IDASetUserData");
  Check(IDASetErrHandlerFn(memory_, &IdaRun::ErrorCallback, this), "IDASetErrHandlerFn");
  // Error weights (WeightCallback): rtol and atol as the local error test of the scene states.
  Check(IDAWFtolerances(memory_, &IdaRun::WeightCallback), "IDAWFtolerances");
  Check(IDASetMaxNumSteps(memory_, options_.max_steps), "IDASetMaxNumSteps");
  Check(IDASetMaxOrd(memory_, kMaxBdfOrder), "IDASetMaxOrd");
  SizeBoundedRootPaths();
  Check(IDASetNonlinConvCoef(memory_, options_.newton_convergence_factor), "IDASetNonlinConvCoef");
  if (options_.max_step > 0.0) Check(IDASetMaxStep(memory_, options_.max_step), "IDASetMaxStep");
  if (sparse_) {
    matrix_ = SUNSparseMatrix(n_, n_, std::max<sunindextype>(n_, 1), CSC_MAT, context_.context);
    linear_solver_ = SUNLinSol_KLU(Y_->vector, matrix_, context_.context);
    // AMD fill-reducing ordering instead of SUNDIALS' default COLAMD: the phase Jacobian is
    // structurally nearly symmetric (F_y, the Gram-like rows J F_z of the kept pairs), and
    // on the crowd KLU's refactorizations took 12% of the run with AMD against 45% with
    // COLAMD (N = 1000, tf = 0.5: 5.5 s against 8.5 s; docs/ida.md, "Linear algebra").
    if (linear_solver_ != nullptr) {
      Check(SUNLinSol_KLUSetOrdering(linear_solver_, kKluOrderingAmd), "SUNLinSol_KLUSetOrdering");
    }
  } else {
    matrix_ = SUNDenseMatrix(n_, n_, context_.context);
    linear_solver_ = SUNLinSol_Dense(Y_->vector, matrix_, context_.context);
  }
  MOREAU_ASSERT(matrix_ != nullptr && linear_solver_ != nullptr, "SUNDIALS linear solver");
  Check(IDASetLinearSolver(memory_, linear_solver_, matrix_), "IDASetLinearSolver");
  Check(IDASetJacFn(memory_, &IdaRun::JacobianCallback), "IDASetJacFn");
  const int roots = np_ + nr_;
  if (roots > 0) {
    Check(IDARootInit(memory_, roots, &IdaRun::RootCallback), "IDARootInit");
    // Free sides and relay switching functions are positive inside a phase: only a
    // decrease through zero is an event.
    std::vector<int> direction(static_cast<std::size_t>(roots), -1);
    Check(IDASetRootDirection(memory_, direction.data()), "IDASetRootDirection");
    Check(IDASetNoInactiveRootWarn(memory_), "IDASetNoInactiveRootWarn");
  }
  // Algebraic components (the velocity-level unknowns v) for consistent-value corrections.
  SerialVector id(n_, context_.context);
  View(id.vector).head(ny_ + nc_).setOnes();
  View(id.vector).tail(nz_).setZero();
  for (int c = 0; c < nc_; ++c) {
    if (position_pair_[static_cast<std::size_t>(c)] >= 0) View(id.vector)[ny_ + c] = 0.0;
  }
  Check(IDASetId(memory_, id.vector), "IDASetId");
  // The velocity-level values are functions of the differential components (index 1):
  // the local error test applies to y and z_c only.
  Check(IDASetSuppressAlg(memory_, SUNTRUE), "IDASetSuppressAlg");
}

void IdaRun::ErrorCallback(int, const char*, const char* function, char* message, void* user_data) {
  auto* run = static_cast<IdaRun*>(user_data);
  run->last_error_ = std::string(function) + ": " + message;
}

// Decides the statuses at (t_, y_) and records the events against `previous` (null at t0).
bool IdaRun::Decide(double t, const std::vector<bool>* previous) {
  const StatusDecision decision = system_.DecideStatuses(y_, options_.event_tolerance);
  if (!decision.solved) {
    Fail(IdaStatus::kStatusDecisionFailure, t, decision.message);
    return false;
  }
  if (decision.ambiguous) {
    result_.events.push_back({t, EventKind::kAmbiguous, system_.scene().name, decision.message});
  }
  if (previous != nullptr) {
    for (Event& event : system_.StatusEvents(t, *previous, decision.a_zero)) {
      result_.events.push_back(std::move(event));
    }
  }
  a_zero_ = decision.a_zero;
  position_side_.assign(static_cast<std::size_t>(np_), PositionSide::kNone);
  for (int k = 0; k < np_; ++k) {
    const ContinuousSide side = system_.pairs()[static_cast<std::size_t>(k)].continuous;
    const bool keeps_a = a_zero_[static_cast<std::size_t>(k)];
    // Only continuous kept sides have a position-level condition (kBoth: both are).
    if (side != ContinuousSide::kBoth && keeps_a != (side == ContinuousSide::kA)) continue;
    position_side_[static_cast<std::size_t>(k)] = keeps_a ? PositionSide::kA : PositionSide::kB;
  }
  roles_ = LoweredSystem::RolesFor(a_zero_);
  v_ = decision.v;
  StartPhase(t);
  return true;
}

// Consistent values at (t, y_) for the statuses a_zero_ and velocity-level values v_, and
// an IDA restart from them.
void IdaRun::StartPhase(double t) {
  t_ = t;
  const Vector guess = system_.InitialAlgebraicGuess(y_);
  Vector z = v_;
  for (int c = 0; c < nc_; ++c)
    z[continuous_[static_cast<std::size_t>(c)]] = guess[continuous_[static_cast<std::size_t>(c)]];
  PointEvaluation point;
  system_.Evaluate(y_, z, Derivatives::kNone, &point);
  auto Y = View(Y_->vector);
  auto Yp = View(Yp_->vector);
  Y.head(ny_) = y_;
  Yp.head(ny_) = point.F;
  for (int c = 0; c < nc_; ++c) {
    const int i = continuous_[static_cast<std::size_t>(c)];
    Y[ny_ + c] = z[i];
    Yp[ny_ + c] = v_[i];  // continuous variables: their rates sit in v
  }
  Y.tail(nz_) = v_;
  Yp.tail(nz_).setZero();
  ArmRoots(/*phase_start=*/true);
  ReInit(t);
  ++result_.stats.num_phases;
}

// Root functions of free sides that start at zero. A free side within the event tolerance
// of zero at the start of a phase (a constraint that has just left, a multiplier that starts
// at zero at a grazing contact) has a zero rate there; its value in the first steps is
// round-off and integration error of either sign, and IDA reported "decreases through
// zero" of that noise as events. Each such event was decided at a point where the
// velocity-level problem is degenerate, and a run of them ended in the wrong branch (S5 with
// u = (0, 1), the doorway plan at rtol 1e-10: a pusher that had left the left disc was
// glued to it with a negative multiplier, its root function starting below zero where IDA
// never reports it). Until such a free side has exceeded the event tolerance at the end of
// an accepted step (armed), its root function is offset, g = value + event tolerance +
// max(0, -start value): an event only when it falls by more than the event tolerance below
// zero and below its start. The offset is the resolution of the status decisions
// (candidates are free sides within the event tolerance of zero); a continuous free side
// found below zero is projected back onto zero at the root (EndPhase).
void IdaRun::ArmRoots(bool phase_start) {
  if (np_ == 0) return;
  if (phase_start) root_offset_.assign(static_cast<std::size_t>(np_), 0.0);
  if (!phase_start && std::none_of(root_offset_.begin(), root_offset_.end(),
                                   [](double offset) { return offset > 0.0; })) {
    return;
  }
  system_.EvaluateEventIndicators(y_, v_, a_zero_, Derivatives::kNone, &indicators_);
  const double tolerance = options_.event_tolerance;
  for (int k = 0; k < np_; ++k) {
    const double value = indicators_.values[k];
    double& offset = root_offset_[static_cast<std::size_t>(k)];
    if (phase_start) {
      offset = value > tolerance ? 0.0 : tolerance + std::max(0.0, -value);
    } else if (value > tolerance) {
      offset = 0.0;  // armed: both root functions are positive here, no false sign change
    }
  }
}

// Adds IDA's counters since the last accumulation (IDAReInit resets them; ReInit below
// accumulates first), so that calling it twice counts nothing twice. Jacobian evaluations
// are counted by the callback instead: IDA's count (IDAGetNumJacEvals) belongs to the
// linear-solver interface, which IDAReInit does not reset (the next IDASolve does), so a
// run ending with a restart at tf counted its last phase's Jacobians twice (the heat
// equation: 46 for 23 evaluations).
void IdaRun::AccumulateStats() {
  long steps = 0, residuals = 0, iterations = 0, failures = 0;
  IDAGetNumSteps(memory_, &steps);
  IDAGetNumResEvals(memory_, &residuals);
  IDAGetNumNonlinSolvIters(memory_, &iterations);
  IDAGetNumErrTestFails(memory_, &failures);
  result_.stats.num_steps += steps - counted_.steps;
  result_.stats.num_residual_evaluations += residuals - counted_.residuals;
  result_.stats.num_nonlinear_iterations += iterations - counted_.iterations;
  result_.stats.num_error_test_failures += failures - counted_.failures;
  counted_ = {steps, residuals, iterations, failures};
}

// IDAReInit at (t, Y_, Yp_), its counters accumulated first.
void IdaRun::ReInit(double t) {
  last_sample_time_ = std::numeric_limits<double>::quiet_NaN();  // a new solution from t
  AccumulateStats();
  Check(IDAReInit(memory_, t, Y_->vector, Yp_->vector), "IDAReInit");
  counted_ = {};
}

// Integrates from t_ to t_end (a breakpoint or tf), handling roots on the way.
// Where IDA's step collapsed without a non-finite evaluation, the model is probed this far
// (relative to max(1, |t|)) beyond t to name a singularity there: 1e-12 is far beyond the
// collapsed steps (below 10 eps |t|) and close enough to be the same singular point.
constexpr double kSingularityProbe = 1e-12;

void IdaRun::Integrate(double t_end) {
  Check(IDASetStopTime(memory_, t_end), "IDASetStopTime");
  int stalled_steps = 0;
  int collapsed_steps = 0;
  while (!failed()) {
    const double t_previous = t_;
    double t_return = t_;
    system_.ClearNonFinite();
    const int flag = IDASolve(memory_, t_end, &t_return, Y_->vector, Yp_->vector, IDA_ONE_STEP);
    if (flag < 0) {
      char* name = IDAGetReturnFlagName(flag);
      const std::string reason =
          std::string(name) + (last_error_.empty() ? "" : " (" + last_error_ + ")");
      std::free(name);
      // Non-finite residuals (the residual callback's recoverable error) are named.
      const std::string named = NonFiniteWitness();
      if (!named.empty()) {
        Fail(IdaStatus::kNonFinite, t_, named + "; " + reason);
      } else {
        Fail(IdaStatus::kSolverFailure, t_, reason);
      }
      return;
    }
    // A collapsed step (below 10 eps |t|) would otherwise creep on, recording every step, until
    // max_steps: the run stops after kMaxCollapsedIdaSteps of them in a row (an IDA run on a
    // model whose square root's argument turned negative took 10^7 steps of 2 ulps and wrote a
    // 1.5 GB trajectory). IDA's first steps after a restart may be that short too, but they
    // double every step (an event of the rectifier at rtol 1e-12: 7.6e-20 at t = 1.5e-4), so
    // they leave the range within a few steps.
    double last_step = 0.0;
    IDAGetLastStep(memory_, &last_step);
    const bool collapsed =
        std::fabs(last_step) <
        kMinIdaStepUlps * std::numeric_limits<double>::epsilon() * std::fabs(t_return);
    collapsed_steps = collapsed ? collapsed_steps + 1 : 0;
    if (collapsed_steps >= kMaxCollapsedIdaSteps) {
      std::string named = NonFiniteWitness();
      if (named.empty()) {
        // IDA may never have evaluated beyond t (a square root's slope grows without bound
        // towards its zero): the model just beyond t names the singularity if it is one.
        Vector probe = View(Y_->vector).head(ny_);
        const double t_probe = t_return + kSingularityProbe * std::max(1.0, std::fabs(t_return));
        probe[system_.clock_index()] = t_probe;
        const std::string beyond = system_.DescribeNonFinite(probe);
        if (!beyond.empty()) named = beyond + " (just beyond t)";
      }
      std::ostringstream reason;
      reason.precision(3);
      reason << "IDA's step collapsed to " << last_step << " (" << kMaxCollapsedIdaSteps
             << " steps in a row below 10 eps |t|)"
             << (named.empty() ? "; the model may be singular just beyond t"
                               : "; it met a non-finite value: " + named);
      Fail(IdaStatus::kStepSizeTooSmall, t_return, reason.str());
      t_ = t_return;
      y_ = View(Y_->vector).head(ny_);
      return;
    }
    long steps = 0;
    IDAGetNumSteps(memory_, &steps);
    if (result_.stats.num_steps + steps - counted_.steps > options_.max_steps) {
      Fail(IdaStatus::kTooManySteps, t_return,
           std::to_string(options_.max_steps) + " internal steps");
      return;
    }
    // Steps that no longer move t (below its resolution) would otherwise run into
    // max_steps only after millions of steps: stop them early with their reason.
    stalled_steps = t_return > t_ ? 0 : stalled_steps + 1;
    if (stalled_steps >= kMaxStalledIdaSteps) {
      Fail(IdaStatus::kNoProgress, t_,
           std::to_string(kMaxStalledIdaSteps) +
               " consecutive internal steps did not advance t (step size below the "
               "resolution of t; the model may be singular or not finite just beyond t)");
      return;
    }
    // A root inside the step that IDA's sign test at the step's ends cannot see (a contact
    // shorter than the step) ends the phase there instead, from IDA's interpolant.
    double t_hidden = 0.0;
    const bool hidden = t_return > t_previous && FindHiddenRoot(t_previous, t_return, &t_hidden);
    if (hidden) {
      Check(IDAGetDky(memory_, t_hidden, 0, Y_->vector), "IDAGetDky");
      Check(IDAGetDky(memory_, t_hidden, 1, Yp_->vector), "IDAGetDky");
      t_return = t_hidden;
    }
    const bool root = hidden || flag == IDA_ROOT_RETURN;
    RecordOutputTimes(t_return);
    t_ = t_return;
    y_ = View(Y_->vector).head(ny_);
    v_ = View(Y_->vector).tail(nz_);
    if (!root) ArmRoots(/*phase_start=*/false);
    if (options_.record_steps && output_times_.empty()) {
      double h = t_ - t_previous;
      if (!hidden) IDAGetLastStep(memory_, &h);
      Record(t_, h);
    }
    if (progress_) progress_(t_);
    if (root) {
      if (!HandleRoots(hidden ? &hidden_roots_ : nullptr)) return;
      Check(IDASetStopTime(memory_, t_end), "IDASetStopTime");
      if (t_ >= t_end) return;
      continue;
    }
    if (flag == IDA_TSTOP_RETURN || t_ >= t_end) {
      t_ = t_end;
      return;
    }
  }
}

std::string IdaRun::NonFiniteWitness() const {
  if (!system_.non_finite_seen()) return "";
  const std::string named = system_.DescribeNonFinite(system_.non_finite_state());
  return named.empty() ? "a non-finite value in the lowered system (not a scene function)" : named;
}

// Trajectory points at the output times passed by the last step (IDA's interpolant).
void IdaRun::RecordOutputTimes(double t_return) {
  while (next_output_ < output_times_.size() && output_times_[next_output_] <= t_return) {
    const double t = output_times_[next_output_++];
    // t0 is the trajectory's first point; IDA's interpolant of the step [t_, t_return]
    // covers the other times (an output time at an event is the state leaving it).
    if (t <= system_.scene().initial_time) continue;
    if (IDAGetDky(memory_, t, 0, dky_->vector) < 0) continue;
    const auto Y = View(dky_->vector);
    result_.trajectory.Append(t, Y.head(nx_), Algebraic(Y), 0.0);
  }
}

// Algebraic values in the z layout from an IDA vector (continuous ones from z_c).
Vector IdaRun::Algebraic(const Eigen::Ref<const Vector>& Y) const {
  Vector z = Y.tail(nz_);
  for (int c = 0; c < nc_; ++c) z[continuous_[static_cast<std::size_t>(c)]] = Y[ny_ + c];
  return z;
}

void IdaRun::Record(double t, double h) {
  result_.trajectory.Append(t, y_.head(nx_), Algebraic(View(Y_->vector)), h);
}

// At a root (IDA's, or `hidden`: the root functions that reached zero inside a step,
// FindHiddenRoot): flip the relays whose switching function vanished, decide the statuses
// of the pairs, restart.
bool IdaRun::HandleRoots(const std::vector<int>* hidden) {
  if (++result_.stats.num_events > options_.max_events) {
    Fail(IdaStatus::kTooManyEvents, t_, std::to_string(options_.max_events) + " events");
    return false;
  }
  std::vector<int> found(static_cast<std::size_t>(np_ + nr_), 0);
  if (hidden != nullptr) {
    found = *hidden;
  } else {
    IDAGetRootInfo(memory_, found.data());
  }
  EndPhase(&found);
  Vector switching(nr_);
  for (int i = 0; i < nr_; ++i) {
    switching[i] = found[static_cast<std::size_t>(np_ + i)] != 0 ? 0.0 : 1.0;
  }
  SwitchRelays(t_, switching, /*initial=*/false);
  const std::vector<bool> previous = a_zero_;
  if (!Decide(t_, &previous)) return false;
  if (output_times_.empty()) Record(t_, 0.0);  // with output times: those only
  return true;
}

// Flips every relay whose switching function is <= 0 (within the event tolerance) and
// records its jump.
void IdaRun::SwitchRelays(double t, const Vector& switching, bool initial) {
  for (int i = 0; i < nr_; ++i) {
    if (switching[i] > (initial ? 0.0 : options_.event_tolerance)) continue;
    const bool to_b = y_[nx_ + i] < 0.5;
    system_.SwitchMemory(i, &y_);
    RelaySignal& signal = result_.relays[static_cast<std::size_t>(i)];
    signal.jump_times.push_back(t);
    signal.values.push_back(to_b ? 1 : 0);
    std::string detail = to_b ? "A -> B" : "B -> A";
    if (initial) {
      detail = std::string("initial memory w0 = ") + (to_b ? "0" : "1") +
               " is inconsistent with the input; re-initialized " + detail;
    }
    result_.events.push_back(
        {t, EventKind::kRelaySwitch, system_.relay_names()[static_cast<std::size_t>(i)], detail});
  }
}

// At a breakpoint or tf: a free side that is zero there is an event decided at that time.
// Returns false on failure.
bool IdaRun::DecideAtBoundary(double t) {
  t_ = t;
  EndPhase();
  const Vector switching = system_.MemorySwitchingFunctions(y_);
  bool event = false;
  for (int i = 0; i < nr_; ++i) event |= switching[i] <= options_.event_tolerance;
  // The inputs may have changed (SetInputs before this call): the free sides are those of
  // the velocity-level values for the new inputs and the same statuses. With the previous
  // values, a multiplier that the new inputs make negative (a push that becomes a pull) was
  // not seen, and the next phase started with a root function below zero, which IDA never
  // reports (the doorway plan kept the pusher glued to the slider for a whole control
  // interval; docs/ida.md, "Control breakpoints").
  if (nz_ > 0 && !system_.SolveVelocityLevel(y_, a_zero_, v_, &v_)) event = true;
  if (np_ > 0 && !event) {
    IndicatorEvaluation indicators;
    system_.EvaluateEventIndicators(y_, v_, a_zero_, Derivatives::kNone, &indicators);
    for (int k = 0; k < np_; ++k) event |= indicators.values[k] <= options_.event_tolerance;
  }
  if (!event) {
    StartPhase(t);
    return true;
  }
  const std::size_t events_before = result_.events.size();
  SwitchRelays(t, switching, /*initial=*/false);
  const std::vector<bool> previous = a_zero_;
  if (!Decide(t, &previous)) return false;
  // A free side that is zero right after an event (e.g. c of a constraint that just left)
  // does not change the statuses again; only real changes count as events.
  if (result_.events.size() > events_before) {
    ++result_.stats.num_events;
    if (output_times_.empty()) Record(t, 0.0);  // with output times: those only
  }
  return true;
}

}  // namespace moreau::internal
