// Event-driven integration of lowered scenes with SUNDIALS IDA (include/moreau/integrators/ida.hpp,
// docs/ida.md). SUNDIALS types stay in this file.

#include "moreau/integrators/ida.hpp"

#include <ida/ida.h>
#include <ida/ida_ls.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunlinsol/sunlinsol_klu.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunmatrix/sunmatrix_sparse.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"

namespace moreau {

IdaOptions IdaOptions::Reference() {
  IdaOptions options;
  options.relative_tolerance = 1e-12;
  options.absolute_tolerance = 1e-14;
  options.newton_convergence_factor = 0.01;
  return options;
}

void IdaOptions::Validate() const {
  RequireArgument(std::isfinite(relative_tolerance) && relative_tolerance > 0.0,
                  "relative tolerance must be positive and finite, got ", relative_tolerance);
  RequireArgument(std::isfinite(absolute_tolerance) && absolute_tolerance > 0.0,
                  "absolute tolerance must be positive and finite, got ", absolute_tolerance);
  RequireArgument(newton_convergence_factor > 0.0 && newton_convergence_factor <= 1.0,
                  "Newton convergence factor must be in (0, 1], got ", newton_convergence_factor);
  RequireArgument(std::isfinite(drift_rate) && drift_rate >= 0.0,
                  "drift rate must be nonnegative and finite, got ", drift_rate);
  RequireArgument(std::isfinite(event_tolerance) && event_tolerance > 0.0,
                  "event tolerance must be positive, got ", event_tolerance);
  RequireArgument(max_steps > 0, "max steps must be positive, got ", max_steps);
  RequireArgument(max_events > 0, "max events must be positive, got ", max_events);
  RequireArgument(std::isfinite(max_step) && max_step >= 0.0,
                  "max step must be nonnegative (0: no limit), got ", max_step);
  for (double t : output_times) {
    RequireArgument(std::isfinite(t), "output times must be finite, got ", t);
  }
}

std::string ToString(IdaStatus status) {
  switch (status) {
    case IdaStatus::kSuccess:
      return "success";
    case IdaStatus::kSolverFailure:
      return "solver_failure";
    case IdaStatus::kStatusDecisionFailure:
      return "status_decision_failure";
    case IdaStatus::kTooManySteps:
      return "too_many_steps";
    case IdaStatus::kTooManyEvents:
      return "too_many_events";
    case IdaStatus::kNoProgress:
      return "no_progress";
  }
  return "?";
}

std::string IdaStats::Summary() const {
  std::ostringstream s;
  s << num_steps << " steps, " << num_phases << " phases, " << num_events << " events, "
    << num_residual_evaluations << " residuals, " << num_jacobian_evaluations
    << " Jacobians, max drift " << max_drift << ", " << cpu_seconds << " s";
  return s.str();
}

namespace {

// RAII owners of the SUNDIALS objects.
struct SundialsContext {
  SUNContext context = nullptr;
  SundialsContext() {
    if (SUNContext_Create(nullptr, &context) != 0) throw std::runtime_error("SUNContext_Create");
  }
  ~SundialsContext() { SUNContext_Free(&context); }
  SundialsContext(const SundialsContext&) = delete;
  SundialsContext& operator=(const SundialsContext&) = delete;
};

struct SerialVector {
  N_Vector vector = nullptr;
  SerialVector(sunindextype n, SUNContext context) : vector(N_VNew_Serial(n, context)) {
    if (vector == nullptr) throw std::runtime_error("N_VNew_Serial");
  }
  ~SerialVector() { N_VDestroy(vector); }
  SerialVector(const SerialVector&) = delete;
  SerialVector& operator=(const SerialVector&) = delete;
  double* data() const { return N_VGetArrayPointer(vector); }
};

// Eigen views of SUNDIALS serial vectors.
Eigen::Map<Vector> View(N_Vector v) {
  return Eigen::Map<Vector>(N_VGetArrayPointer(v), N_VGetLength(v));
}

class IdaRun {
 public:
  IdaRun(const Scene& scene, const IdaOptions& options, const ProgressCallback& progress)
      : options_(options), progress_(progress), system_(scene, Lowering(scene, options)) {
    ny_ = system_.num_states();
    nx_ = system_.num_scene_states();
    nz_ = system_.num_algebraic();
    ng_ = system_.num_equations();
    np_ = system_.num_pairs();
    nr_ = static_cast<int>(system_.relay_names().size());
    for (int i = 0; i < nz_; ++i) {
      (system_.continuous_algebraic()[static_cast<std::size_t>(i)] ? continuous_ : jump_)
          .push_back(i);
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

  ~IdaRun() {
    if (memory_ != nullptr) IDAFree(&memory_);
    if (linear_solver_ != nullptr) SUNLinSolFree(linear_solver_);
    if (matrix_ != nullptr) SUNMatDestroy(matrix_);
  }
  IdaRun(const IdaRun&) = delete;
  IdaRun& operator=(const IdaRun&) = delete;

  IdaResult Run() {
    const auto start = std::chrono::steady_clock::now();
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
    const std::vector<double> ends = SegmentEnds(t0, scene.final_time, scene.ControlBreakpoints());
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
        if (segment > 0 && !DecideAtBoundary(ends[segment])) break;
        Integrate(ends[segment + 1]);
      }
      // An event exactly at tf.
      if (!failed()) DecideAtBoundary(scene.final_time);
    }
    result_.final_time = t_;
    result_.final_state = y_.head(nx_);
    if (result_.trajectory.t.empty() || result_.trajectory.t.back() != t_) Record(t_, 0.0);
    // The last phase's counters: a run that fails inside a phase has no IDAReInit after it
    // (hard_corner with the Newton factor 0.001 reported 48 steps after 10^7).
    AccumulateStats();
    result_.stats.cpu_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result_;
  }

 private:
  static LoweringOptions Lowering(const Scene& scene, const IdaOptions& options) {
    LoweringOptions lowering;
    lowering.switching_form = options.switching_form;
    lowering.relay_form = RelayForm::kDiscreteMemory;
    // The phase Jacobian below is assembled dense (then copied into KLU's CSC matrix when the
    // sparse solver is used); hand-written sparse dynamics (no effects) are read sparse.
    lowering.storage = scene.dynamics.has_sparse_state_jacobian() ? DerivativeStorage::kSparse
                                                                  : DerivativeStorage::kDense;
    return lowering;
  }

  bool failed() const { return result_.status != IdaStatus::kSuccess; }

  void Fail(IdaStatus status, double t, const std::string& reason) {
    if (failed()) return;
    result_.status = status;
    std::ostringstream s;
    s.precision(17);
    s << ToString(status) << " at t = " << t << ": " << reason;
    result_.message = s.str();
  }

  // --- SUNDIALS set-up ----------------------------------------------------------------------
  void CreateSolver(double t0) {
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
    Check(IDASetNonlinConvCoef(memory_, options_.newton_convergence_factor),
          "IDASetNonlinConvCoef");
    if (options_.max_step > 0.0) Check(IDASetMaxStep(memory_, options_.max_step), "IDASetMaxStep");
    if (sparse_) {
      matrix_ = SUNSparseMatrix(n_, n_, std::max<sunindextype>(n_, 1), CSC_MAT, context_.context);
      linear_solver_ = SUNLinSol_KLU(Y_->vector, matrix_, context_.context);
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

  static void Check(int flag, const char* what) {
    MOREAU_ASSERT(flag >= 0, std::string(what) + " failed with flag " + std::to_string(flag));
  }

  static void ErrorCallback(int, const char*, const char* function, char* message,
                            void* user_data) {
    auto* run = static_cast<IdaRun*>(user_data);
    run->last_error_ = std::string(function) + ": " + message;
  }

  // --- phases -------------------------------------------------------------------------------
  // Decides the statuses at (t_, y_) and records the events against `previous` (null at t0).
  bool Decide(double t, const std::vector<bool>* previous) {
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
    roles_ = LoweredSystem::RolesFor(a_zero_);
    v_ = decision.v;
    StartPhase(t);
    return true;
  }

  // Consistent values at (t, y_) for the statuses a_zero_ and velocity-level values v_, and
  // an IDA restart from them.
  void StartPhase(double t) {
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
  void ArmRoots(bool phase_start) {
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
  // accumulates first), so that calling it twice counts nothing twice.
  void AccumulateStats() {
    long steps = 0, residuals = 0, jacobians = 0, iterations = 0, failures = 0;
    IDAGetNumSteps(memory_, &steps);
    IDAGetNumResEvals(memory_, &residuals);
    IDAGetNumJacEvals(memory_, &jacobians);
    IDAGetNumNonlinSolvIters(memory_, &iterations);
    IDAGetNumErrTestFails(memory_, &failures);
    result_.stats.num_steps += steps - counted_.steps;
    result_.stats.num_residual_evaluations += residuals - counted_.residuals;
    result_.stats.num_jacobian_evaluations += jacobians - counted_.jacobians;
    result_.stats.num_nonlinear_iterations += iterations - counted_.iterations;
    result_.stats.num_error_test_failures += failures - counted_.failures;
    counted_ = {steps, residuals, jacobians, iterations, failures};
  }

  // IDAReInit at (t, Y_, Yp_), its counters accumulated first.
  void ReInit(double t) {
    AccumulateStats();
    Check(IDAReInit(memory_, t, Y_->vector, Yp_->vector), "IDAReInit");
    counted_ = {};
  }

  // Integrates from t_ to t_end (a breakpoint or tf), handling roots on the way.
  void Integrate(double t_end) {
    Check(IDASetStopTime(memory_, t_end), "IDASetStopTime");
    int stalled_steps = 0;
    while (!failed()) {
      double t_return = t_;
      const int flag = IDASolve(memory_, t_end, &t_return, Y_->vector, Yp_->vector, IDA_ONE_STEP);
      if (flag < 0) {
        char* name = IDAGetReturnFlagName(flag);
        Fail(IdaStatus::kSolverFailure, t_,
             std::string(name) + (last_error_.empty() ? "" : " (" + last_error_ + ")"));
        std::free(name);
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
      RecordOutputTimes(t_return);
      t_ = t_return;
      y_ = View(Y_->vector).head(ny_);
      v_ = View(Y_->vector).tail(nz_);
      if (flag != IDA_ROOT_RETURN) ArmRoots(/*phase_start=*/false);
      if (options_.record_steps) {
        double h = 0.0;
        IDAGetLastStep(memory_, &h);
        Record(t_, h);
      }
      if (progress_) progress_(t_);
      if (flag == IDA_ROOT_RETURN) {
        if (!HandleRoots()) return;
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

  // Trajectory points at the output times passed by the last step (IDA's interpolant).
  void RecordOutputTimes(double t_return) {
    while (next_output_ < output_times_.size() && output_times_[next_output_] <= t_return) {
      const double t = output_times_[next_output_++];
      if (t <= t_) continue;  // at or before the phase start (recorded there)
      if (IDAGetDky(memory_, t, 0, dky_->vector) < 0) continue;
      const auto Y = View(dky_->vector);
      result_.trajectory.Append(t, Y.head(nx_), Algebraic(Y), 0.0);
    }
  }

  // Algebraic values in the z layout from an IDA vector (continuous ones from z_c).
  Vector Algebraic(const Eigen::Ref<const Vector>& Y) const {
    Vector z = Y.tail(nz_);
    for (int c = 0; c < nc_; ++c) z[continuous_[static_cast<std::size_t>(c)]] = Y[ny_ + c];
    return z;
  }

  void Record(double t, double h) {
    result_.trajectory.Append(t, y_.head(nx_), Algebraic(View(Y_->vector)), h);
  }

  // At a root: flip the relays whose switching function vanished, decide the statuses of the
  // pairs, restart.
  bool HandleRoots() {
    if (++result_.stats.num_events > options_.max_events) {
      Fail(IdaStatus::kTooManyEvents, t_, std::to_string(options_.max_events) + " events");
      return false;
    }
    std::vector<int> found(static_cast<std::size_t>(np_ + nr_), 0);
    IDAGetRootInfo(memory_, found.data());
    EndPhase(&found);
    Vector switching(nr_);
    for (int i = 0; i < nr_; ++i) {
      switching[i] = found[static_cast<std::size_t>(np_ + i)] != 0 ? 0.0 : 1.0;
    }
    SwitchRelays(t_, switching, /*initial=*/false);
    const std::vector<bool> previous = a_zero_;
    if (!Decide(t_, &previous)) return false;
    Record(t_, 0.0);
    return true;
  }

  // Flips every relay whose switching function is <= 0 (within the event tolerance) and
  // records its jump.
  void SwitchRelays(double t, const Vector& switching, bool initial) {
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
  bool DecideAtBoundary(double t) {
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
      Record(t, 0.0);
    }
    return true;
  }

  // --- the phase DAE ----------------------------------------------------------------------
  // Position-level conditions P (nz rows, aligned with the velocity-level rows) and, with
  // `with_jacobian`, dP/dy and dP/dz at the evaluation `point`.
  void PositionLevel(const PointEvaluation& point, bool with_jacobian, Vector* p, Matrix* p_y,
                     Matrix* p_z) const {
    p->setZero(nz_);
    if (with_jacobian) {
      p_y->setZero(nz_, ny_);
      p_z->setZero(nz_, nz_);
    }
    for (int r = 0; r < ng_; ++r) {
      if (!system_.differentiated_equations()[static_cast<std::size_t>(r)]) continue;
      (*p)[r] = point.G[r];
      if (with_jacobian) {
        p_y->row(r) = point.G_y.dense().row(r);
        p_z->row(r) = point.G_z.dense().row(r);
      }
    }
    for (int k = 0; k < np_; ++k) {
      const ContinuousSide side = system_.pairs()[static_cast<std::size_t>(k)].continuous;
      const bool keeps_a = a_zero_[static_cast<std::size_t>(k)];
      // Only continuous kept sides have a position-level condition (kBoth: both are).
      if (side != ContinuousSide::kBoth && keeps_a != (side == ContinuousSide::kA)) continue;
      (*p)[ng_ + k] = keeps_a ? point.A[k] : point.B[k];
      if (with_jacobian) {
        p_y->row(ng_ + k) = keeps_a ? point.A_y.dense().row(k) : point.B_y.dense().row(k);
        p_z->row(ng_ + k) = keeps_a ? point.A_z.dense().row(k) : point.B_z.dense().row(k);
      }
    }
  }

  // Splits an IDA vector into y, z (continuous values from z_c) and v.
  void Unpack(N_Vector Y, Vector* y, Vector* z, Vector* v) const {
    const auto all = View(Y);
    *y = all.head(ny_);
    *v = all.tail(nz_);
    *z = *v;
    for (int c = 0; c < nc_; ++c) (*z)[continuous_[static_cast<std::size_t>(c)]] = all[ny_ + c];
  }

  // R = [y' - F(y, z); z_c' - v_c; V(y, v) + kappa P(y, z)]; for the multiplier of an
  // index-1 pair the z_c row is its kept side at position level instead (P_k = 0).
  int Residual(N_Vector Y, N_Vector Yp, N_Vector R) {
    Vector y, z, v;
    Unpack(Y, &y, &z, &v);
    const auto yp = View(Yp);
    auto r = View(R);
    system_.Evaluate(y, z, Derivatives::kNone, &point_);
    r.head(ny_) = yp.head(ny_) - point_.F;
    Vector p;
    if (nz_ > 0) PositionLevel(point_, false, &p, nullptr, nullptr);
    for (int c = 0; c < nc_; ++c) {
      const int k = position_pair_[static_cast<std::size_t>(c)];
      r[ny_ + c] = k >= 0 ? p[ng_ + k] : yp[ny_ + c] - v[continuous_[static_cast<std::size_t>(c)]];
    }
    if (nz_ > 0) {
      system_.EvaluateVelocityLevel(y, v, roles_, Derivatives::kNone, &velocity_);
      r.tail(nz_) = velocity_.equations + options_.drift_rate * p;
    }
    return r.allFinite() ? 0 : 1;  // non-finite: recoverable, IDA retries a smaller step
  }

  // J = dR/dY + c_j dR/dY'.
  int Jacobian(double c_j, N_Vector Y, SUNMatrix J) {
    Vector y, z, v;
    Unpack(Y, &y, &z, &v);
    system_.Evaluate(y, z, Derivatives::kStates, &point_);
    if (point_.F_y.is_sparse()) return SparseDynamicsJacobian(c_j, J);
    Matrix& jac = jacobian_;
    jac.setZero(n_, n_);
    // y' - F(y, z): F depends on y, z_c (continuous columns) and v_J (jump columns).
    jac.topLeftCorner(ny_, ny_) = c_j * Matrix::Identity(ny_, ny_) - point_.F_y.dense();
    for (int c = 0; c < nc_; ++c) {
      const int i = continuous_[static_cast<std::size_t>(c)];
      jac.block(0, ny_ + c, ny_, 1) = -point_.F_z.dense().col(i);
      jac(ny_ + c, ny_ + c) = c_j;  // z_c' - v_c
      jac(ny_ + c, ny_ + nc_ + i) = -1.0;
    }
    for (int i : jump_) jac.block(0, ny_ + nc_ + i, ny_, 1) = -point_.F_z.dense().col(i);
    if (nz_ > 0) {
      system_.EvaluateVelocityLevel(y, v, roles_, Derivatives::kStates, &velocity_);
      Vector p;
      Matrix p_y, p_z;
      PositionLevel(point_, true, &p, &p_y, &p_z);
      for (int c = 0; c < nc_; ++c) {
        const int k = position_pair_[static_cast<std::size_t>(c)];
        if (k < 0) continue;
        // Index-1 multiplier: the row is P_k(y, z) (no z_c' term).
        jac.row(ny_ + c).setZero();
        jac.block(ny_ + c, 0, 1, ny_) = p_y.row(ng_ + k);
        for (int c2 = 0; c2 < nc_; ++c2) {
          jac(ny_ + c, ny_ + c2) = p_z(ng_ + k, continuous_[static_cast<std::size_t>(c2)]);
        }
        for (int i : jump_) jac(ny_ + c, ny_ + nc_ + i) = p_z(ng_ + k, i);
      }
      const double kappa = options_.drift_rate;
      const int row = ny_ + nc_;
      jac.block(row, 0, nz_, ny_) = velocity_.equations_y.dense() + kappa * p_y;
      jac.block(row, row, nz_, nz_) = velocity_.equations_v.dense();
      for (int c = 0; c < nc_; ++c) {
        jac.block(row, ny_ + c, nz_, 1) = kappa * p_z.col(continuous_[static_cast<std::size_t>(c)]);
      }
      for (int i : jump_) jac.block(row, row + i, nz_, 1) += kappa * p_z.col(i);
    }
    if (!jac.allFinite()) return 1;
    if (sparse_) return CopySparse(jac.sparseView(), J);
    std::memcpy(SUNDenseMatrix_Data(J), jac.data(), sizeof(double) * jac.size());
    return 0;
  }

  // Scenes without effects and a hand-written sparse Jacobian: J = c_j I - F_y.
  int SparseDynamicsJacobian(double c_j, SUNMatrix J) {
    SparseMatrix identity(n_, n_);
    identity.setIdentity();
    SparseMatrix jac = c_j * identity - point_.F_y.sparse();
    return CopySparse(jac, J);
  }

  // Copies a sparse Jacobian into the CSC SUNMatrix with the diagonal always stored, so that
  // its pattern changes rarely; KLU's symbolic analysis is redone when it does.
  int CopySparse(const SparseMatrix& source, SUNMatrix J) {
    SparseMatrix jac = source;
    for (int i = 0; i < n_; ++i) jac.coeffRef(i, i) += 0.0;
    jac.makeCompressed();
    const auto nnz = static_cast<sunindextype>(jac.nonZeros());
    bool same_pattern = nnz == pattern_nnz_ && pattern_outer_.size() == std::size_t(n_ + 1);
    for (int j = 0; same_pattern && j <= n_; ++j) {
      same_pattern = pattern_outer_[static_cast<std::size_t>(j)] == jac.outerIndexPtr()[j];
    }
    for (sunindextype k = 0; same_pattern && k < nnz; ++k) {
      same_pattern = pattern_inner_[static_cast<std::size_t>(k)] == jac.innerIndexPtr()[k];
    }
    if (!same_pattern) {
      if (SUNSparseMatrix_NNZ(J) < nnz && SUNSparseMatrix_Reallocate(J, nnz) != 0) return -1;
      pattern_outer_.assign(jac.outerIndexPtr(), jac.outerIndexPtr() + n_ + 1);
      pattern_inner_.assign(jac.innerIndexPtr(), jac.innerIndexPtr() + nnz);
      pattern_nnz_ = nnz;
      if (SUNLinSol_KLUReInit(linear_solver_, J, SUNSparseMatrix_NNZ(J), SUNKLU_REINIT_PARTIAL) !=
          0) {
        return -1;
      }
    }
    sunindextype* outer = SUNSparseMatrix_IndexPointers(J);
    sunindextype* inner = SUNSparseMatrix_IndexValues(J);
    double* data = SUNSparseMatrix_Data(J);
    for (int j = 0; j <= n_; ++j) outer[j] = jac.outerIndexPtr()[j];
    for (sunindextype k = 0; k < nnz; ++k) {
      inner[k] = jac.innerIndexPtr()[k];
      data[k] = jac.valuePtr()[k];
    }
    return 0;
  }

  int Roots(N_Vector Y, double* out) {
    Vector y, z, v;
    Unpack(Y, &y, &z, &v);
    if (np_ > 0) {
      system_.EvaluateEventIndicators(y, v, a_zero_, Derivatives::kNone, &indicators_);
      for (int k = 0; k < np_; ++k) {
        out[k] = indicators_.values[k] + root_offset_[static_cast<std::size_t>(k)];
      }
    }
    if (nr_ > 0) {
      const Vector switching = system_.MemorySwitchingFunctions(y);
      for (int i = 0; i < nr_; ++i) out[np_ + i] = switching[i];
    }
    return 0;
  }

  // At the end of a phase: the drift certificate |P| (position-level conditions of the phase),
  // then the state is projected back onto P = 0 (minimum-norm Gauss-Newton correction of x and
  // z_c; relay memories and the clock stay), so that the status decision at the event sees
  // the kept sides at zero rather than at the integration error. At a root (`roots`: IDA's
  // root flags), the continuous free sides that reached zero are kept at zero by the same
  // projection: the correction of the drift (of the size of the integration error) would
  // otherwise move them off zero, and a constraint just reached could be found violated by
  // more than the event tolerance (the doorway plan at rtol 1e-8: -5.4e-8 for the slider on
  // the left disc, a status-decision failure).
  void EndPhase(const std::vector<int>* roots = nullptr) {
    if (nz_ == 0) return;
    std::vector<int> reached;  // pairs whose continuous free side is a root
    for (int k = 0; roots != nullptr && k < np_; ++k) {
      if ((*roots)[static_cast<std::size_t>(k)] != 0 && FreeSideIsContinuous(k))
        reached.push_back(k);
    }
    const int rows = nz_ + static_cast<int>(reached.size());
    auto Y = View(Y_->vector);
    for (int iteration = 0; iteration < kProjectionIterations; ++iteration) {
      Vector y, z, v;
      Unpack(Y_->vector, &y, &z, &v);
      PointEvaluation point;
      system_.Evaluate(y, z, Derivatives::kStates, &point);
      Vector p;
      Matrix p_y, p_z;
      PositionLevel(point, true, &p, &p_y, &p_z);
      const double size = p.lpNorm<Eigen::Infinity>();
      if (iteration == 0) result_.stats.max_drift = std::max(result_.stats.max_drift, size);
      p.conservativeResize(rows);
      p_y.conservativeResize(rows, Eigen::NoChange);
      p_z.conservativeResize(rows, Eigen::NoChange);
      for (std::size_t r = 0; r < reached.size(); ++r) {
        const int k = reached[r];
        const bool free_b = a_zero_[static_cast<std::size_t>(k)];
        const int row = nz_ + static_cast<int>(r);
        p[row] = free_b ? point.B[k] : point.A[k];
        p_y.row(row) = free_b ? point.B_y.dense().row(k) : point.A_y.dense().row(k);
        p_z.row(row) = free_b ? point.B_z.dense().row(k) : point.A_z.dense().row(k);
      }
      if (p.lpNorm<Eigen::Infinity>() <= kProjectionTolerance) break;
      Matrix jacobian(rows, nx_ + nc_);
      jacobian.leftCols(nx_) = p_y.leftCols(nx_);
      for (int c = 0; c < nc_; ++c) {
        jacobian.col(nx_ + c) = p_z.col(continuous_[static_cast<std::size_t>(c)]);
      }
      const Vector step = jacobian.completeOrthogonalDecomposition().solve(-p);
      Y.head(nx_) += step.head(nx_);
      Y.segment(ny_, nc_) += step.tail(nc_);
    }
    y_ = Y.head(ny_);
  }

  // True if pair k's free side for the current statuses is a continuous variable (a
  // constraint value or a Stewart lambda: a position-level condition when it is zero) rather
  // than a jump variable (a multiplier, zero only at velocity level).
  bool FreeSideIsContinuous(int k) const {
    const ContinuousSide side = system_.pairs()[static_cast<std::size_t>(k)].continuous;
    if (side == ContinuousSide::kBoth) return true;
    const bool free_b = a_zero_[static_cast<std::size_t>(k)];
    return free_b == (side == ContinuousSide::kB);
  }

  // Projection onto the phase's position-level conditions: Gauss-Newton iterations until |P|
  // is at round-off level.
  static constexpr int kProjectionIterations = 3;
  static constexpr double kProjectionTolerance = 1e-15;

  // C callbacks: exceptions (a throwing model function) stop IDA with an unrecoverable error.
  static int ResidualCallback(double, N_Vector Y, N_Vector Yp, N_Vector R, void* user_data) {
    auto* run = static_cast<IdaRun*>(user_data);
    try {
      return run->Residual(Y, Yp, R);
    } catch (const std::exception& error) {
      run->last_error_ = error.what();
      return -1;
    }
  }
  static int JacobianCallback(double, double c_j, N_Vector Y, N_Vector, N_Vector, SUNMatrix J,
                              void* user_data, N_Vector, N_Vector, N_Vector) {
    auto* run = static_cast<IdaRun*>(user_data);
    try {
      return run->Jacobian(c_j, Y, J);
    } catch (const std::exception& error) {
      run->last_error_ = error.what();
      return -1;
    }
  }

  // Error weights 1/(rtol |Y_i| + atol), those of the scene states x and of the carried
  // continuous algebraic variables z_c scaled by sqrt(N / n_x), so that IDA's local error test
  // (the weighted RMS over all N components) is the RMS over the n_x scene states, as for an
  // ODE in x alone, plus the errors of z_c. The other components carry no error of their own:
  // the clock and relay memories are integrated exactly, the velocity-level values and the
  // index-1 multipliers are algebraic (suppressed from the test). Counting z_c in the average
  // (sqrt(N / (n_x + n_c)), as before) diluted the test on x: on the exact solution z_c is a
  // function of x (lambda = g - min g) whose local errors are far smaller than x's, and F1
  // took fewer steps than the ODE x' = A2 x alone and ended 2.2 times less accurate
  // (docs/ida.md, "Accuracy and settings").
  static int WeightCallback(N_Vector Y, N_Vector ewt, void* user_data) {
    const auto* run = static_cast<const IdaRun*>(user_data);
    const auto y = View(Y);
    auto weights = View(ewt);
    const double scale = std::sqrt(static_cast<double>(run->n_) / std::max(run->nx_, 1));
    for (int i = 0; i < run->n_; ++i) {
      const double tolerance =
          run->options_.relative_tolerance * std::fabs(y[i]) + run->options_.absolute_tolerance;
      weights[i] = (run->tested_[static_cast<std::size_t>(i)] ? scale : 1.0) / tolerance;
    }
    return 0;
  }
  static int RootCallback(double, N_Vector Y, N_Vector, double* out, void* user_data) {
    auto* run = static_cast<IdaRun*>(user_data);
    try {
      return run->Roots(Y, out);
    } catch (const std::exception& error) {
      run->last_error_ = error.what();
      return -1;
    }
  }

  IdaOptions options_;
  ProgressCallback progress_;
  LoweredSystem system_;
  int ny_ = 0, nx_ = 0, nz_ = 0, ng_ = 0, np_ = 0, nr_ = 0, nc_ = 0, n_ = 0;
  std::vector<int> continuous_, jump_;  // indices in z of continuous and jump variables
  // Per continuous variable: the index-1 pair whose multiplier it is (position-level row), or -1.
  std::vector<int> position_pair_;
  // Per IDA component: in the local error test with the scaled weight (WeightCallback): the
  // scene states x and the differential z_c.
  std::vector<bool> tested_;
  bool sparse_ = false;
  SundialsContext context_;
  void* memory_ = nullptr;
  SUNMatrix matrix_ = nullptr;
  SUNLinearSolver linear_solver_ = nullptr;
  std::unique_ptr<SerialVector> Y_, Yp_, dky_;
  IdaResult result_;
  double t_ = 0.0;
  Vector y_, v_;
  std::vector<bool> a_zero_;
  std::vector<PairRole> roles_;
  // Per pair: the offset of its root function until the free side is armed (ArmRoots), or 0.
  std::vector<double> root_offset_;
  std::vector<double> output_times_;
  std::size_t next_output_ = 0;
  std::string last_error_;
  struct Counters {
    long steps = 0, residuals = 0, jacobians = 0, iterations = 0, failures = 0;
  } counted_;  // IDA's counters already added to the stats since the last IDAReInit
  PointEvaluation point_;
  VelocityLevelEvaluation velocity_;
  IndicatorEvaluation indicators_;
  Matrix jacobian_;
  std::vector<sunindextype> pattern_outer_, pattern_inner_;
  sunindextype pattern_nnz_ = -1;
};

}  // namespace

IdaResult SimulateIda(const Scene& scene, const IdaOptions& options,
                      const ProgressCallback& progress) {
  options.Validate();
  RequireSupportedEffects(scene, "ida");
  IdaRun run(scene, options, progress);
  return run.Run();
}

ReferenceSolution ComputeReference(const Scene& scene, const std::vector<double>& sample_times,
                                   const IdaOptions& options) {
  IdaOptions reference = options;
  reference.output_times = sample_times;
  reference.record_steps = false;
  const IdaResult result = SimulateIda(scene, reference);
  if (result.status != IdaStatus::kSuccess) {
    throw std::runtime_error("reference solution of scene '" + scene.name +
                             "' failed: " + result.message);
  }
  ReferenceSolution solution;
  solution.final_state = result.final_state;
  solution.final_time = result.final_time;
  solution.events = result.events;
  solution.relays = result.relays;
  for (double t : sample_times) {
    // The trajectory holds t0, event points, the output times and tf, in time order.
    const auto& times = result.trajectory.t;
    std::size_t best = 0;
    for (std::size_t k = 1; k < times.size(); ++k) {
      if (std::fabs(times[k] - t) < std::fabs(times[best] - t)) best = k;
    }
    solution.sample_times.push_back(t);
    solution.samples.push_back(result.trajectory.x[best]);
  }
  return solution;
}

}  // namespace moreau
