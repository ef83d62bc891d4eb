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
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
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
    << num_residual_evaluations << " residuals, " << num_jacobian_evaluations << " Jacobians";
  if (num_symbolic_analyses > 0) s << " (" << num_symbolic_analyses << " KLU analyses)";
  s << ", max drift " << max_drift << ", " << cpu_seconds << " s";
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

// f(row, column, value) for every entry of a finished derivative matrix: the stored entries
// of sparse storage (structural zeros included), every entry of dense storage.
template <class F>
void ForEachEntry(const DerivativeMatrix& m, F&& f) {
  if (m.is_sparse()) {
    const SparseMatrix& s = m.sparse();
    for (int j = 0; j < s.outerSize(); ++j) {
      for (SparseMatrix::InnerIterator it(s, j); it; ++it)
        f(static_cast<int>(it.row()), j, it.value());
    }
    return;
  }
  const Matrix& d = m.dense();
  for (Eigen::Index j = 0; j < d.cols(); ++j) {
    for (Eigen::Index i = 0; i < d.rows(); ++i) {
      f(static_cast<int>(i), static_cast<int>(j), d(i, j));
    }
  }
}

// Triplets (row, column, value) compressed into CSC arrays (duplicates summed, rows sorted
// within each column). The map from triplet to CSC slot is kept: while the sequence of
// (row, column) is the one it was made for (the same blocks with the same patterns), a
// compression is one pass over the values, O(triplets), without sorting or allocation.
class TripletAssembly {
 public:
  void Clear() {
    rows_.clear();
    cols_.clear();
    values_.clear();
  }
  void Add(int row, int col, double value) {
    rows_.push_back(row);
    cols_.push_back(col);
    values_.push_back(value);
  }
  const std::vector<double>& values() const { return values_; }

  // Compresses the triplets of an n x n matrix; true if the CSC pattern differs from the
  // previous compression's.
  bool Compress(int n) {
    bool new_pattern = false;
    if (rows_ != slot_rows_ || cols_ != slot_cols_) {
      new_pattern = BuildSlots(n);
      slot_rows_ = rows_;
      slot_cols_ = cols_;
    }
    compressed_.assign(inner_.size(), 0.0);
    for (std::size_t t = 0; t < values_.size(); ++t) compressed_[slot_[t]] += values_[t];
    return new_pattern;
  }
  const std::vector<sunindextype>& outer() const { return outer_; }
  const std::vector<sunindextype>& inner() const { return inner_; }
  const std::vector<double>& compressed() const { return compressed_; }

 private:
  // Counting sort by column, then by row within each column; equal (row, column) share a
  // slot. Returns true if the pattern changed.
  bool BuildSlots(int n) {
    const std::size_t m = rows_.size();
    std::vector<std::size_t> start(static_cast<std::size_t>(n) + 1, 0);
    for (int c : cols_) ++start[static_cast<std::size_t>(c) + 1];
    for (std::size_t j = 0; j < static_cast<std::size_t>(n); ++j) start[j + 1] += start[j];
    std::vector<std::size_t> order(m), next(start.begin(), start.end() - 1);
    for (std::size_t t = 0; t < m; ++t) order[next[static_cast<std::size_t>(cols_[t])]++] = t;
    std::vector<sunindextype> outer(static_cast<std::size_t>(n) + 1, 0), inner;
    inner.reserve(m);
    slot_.resize(m);
    for (std::size_t j = 0; j < static_cast<std::size_t>(n); ++j) {
      const auto first = order.begin() + static_cast<std::ptrdiff_t>(start[j]);
      const auto last = order.begin() + static_cast<std::ptrdiff_t>(start[j + 1]);
      std::sort(first, last, [this](std::size_t a, std::size_t b) { return rows_[a] < rows_[b]; });
      outer[j] = static_cast<sunindextype>(inner.size());
      for (auto it = first; it != last; ++it) {
        if (inner.size() == static_cast<std::size_t>(outer[j]) || inner.back() != rows_[*it]) {
          inner.push_back(rows_[*it]);
        }
        slot_[*it] = inner.size() - 1;
      }
    }
    outer[static_cast<std::size_t>(n)] = static_cast<sunindextype>(inner.size());
    const bool changed = outer != outer_ || inner != inner_;
    outer_ = std::move(outer);
    inner_ = std::move(inner);
    return changed;
  }

  std::vector<int> rows_, cols_;
  std::vector<double> values_;
  // The triplet sequence the slots were made for, and per triplet its CSC slot.
  std::vector<int> slot_rows_, slot_cols_;
  std::vector<std::size_t> slot_;
  std::vector<sunindextype> outer_, inner_;
  std::vector<double> compressed_;
};

class IdaRun {
 public:
  IdaRun(const Scene& scene, const IdaOptions& options, const ProgressCallback& progress)
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
  static LoweringOptions Lowering(const IdaOptions& options) {
    LoweringOptions lowering;
    lowering.switching_form = options.switching_form;
    lowering.relay_form = RelayForm::kDiscreteMemory;
    // Sparse with KLU, else automatic (sparse for large systems and hand-written sparse
    // dynamics): the phase Jacobian is assembled from either storage (AssembleJacobian).
    lowering.storage = StorageForLinearSolver(options.linear_solver);
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
      // AMD fill-reducing ordering instead of SUNDIALS' default COLAMD: the phase Jacobian is
      // structurally nearly symmetric (F_y, the Gram-like rows J F_z of the kept pairs), and
      // on the crowd KLU's refactorizations took 12% of the run with AMD against 45% with
      // COLAMD (N = 1000, tf = 0.5: 5.5 s against 8.5 s; docs/ida.md, "Linear algebra").
      if (linear_solver_ != nullptr) {
        Check(SUNLinSol_KLUSetOrdering(linear_solver_, kKluOrderingAmd),
              "SUNLinSol_KLUSetOrdering");
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

  // KLU's ordering codes (SUNLinSol_KLUSetOrdering): 0 AMD, 1 COLAMD, 2 natural.
  static constexpr int kKluOrderingAmd = 0;

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
  // accumulates first), so that calling it twice counts nothing twice. Jacobian evaluations
  // are counted by the callback instead: IDA's count (IDAGetNumJacEvals) belongs to the
  // linear-solver interface, which IDAReInit does not reset (the next IDASolve does), so a
  // run ending with a restart at tf counted its last phase's Jacobians twice (the heat
  // equation: 46 for 23 evaluations).
  void AccumulateStats() {
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
  void ReInit(double t) {
    last_sample_time_ = std::numeric_limits<double>::quiet_NaN();  // a new solution from t
    AccumulateStats();
    Check(IDAReInit(memory_, t, Y_->vector, Yp_->vector), "IDAReInit");
    counted_ = {};
  }

  // Integrates from t_ to t_end (a breakpoint or tf), handling roots on the way.
  void Integrate(double t_end) {
    Check(IDASetStopTime(memory_, t_end), "IDASetStopTime");
    int stalled_steps = 0;
    while (!failed()) {
      const double t_previous = t_;
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
      if (options_.record_steps) {
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

  // Roots inside a step. IDA compares the signs of the root functions at the ends of each
  // step, so a root function that falls below zero and recovers within one step is not seen.
  // In free flight at constant velocity the solution is linear, BDF's local error is zero and
  // the steps double without bound: a body passed straight through a fixed disc (x' = (1, 0)
  // from (-5, 0.9), no event at any rtol), and the doorway's optimal controls lost a contact
  // of 0.018 time units inside a step of 0.21 (pusher and slider at t = 0.96), which left
  // IDA's re-simulation 1.2e-4 from FESD and time-stepping (docs/ida.md, "Contacts inside a
  // step"). The root functions are sampled on IDA's interpolant at kHiddenRootIntervals + 1
  // equally spaced times of the step; around the smallest sample of each function a
  // parabola through three samples predicts the minimum (exact for the quadratic distance
  // functions of bodies in free flight), refined by successive parabolic interpolation
  // while the predicted minimum is below -event_tolerance. A function found below
  // -event_tolerance (the resolution of the status decisions: a shallower dip is a graze the
  // decision would not resolve) has its first zero located by bisection on the interpolant,
  // to IDA's own root resolution. Only functions positive at the step's start are watched
  // (IDA reports decreases through zero only). On success *t_root is the time and
  // hidden_roots_ flags the functions at or below zero there.
  bool FindHiddenRoot(double t_a, double t_b, double* t_root) {
    const int m = np_ + nr_;
    if (m == 0) return false;
    constexpr int K = kHiddenRootIntervals;
    std::array<double, K + 1> times{};
    hidden_samples_.resize(K + 1, m);
    for (int j = 0; j <= K; ++j) {
      times[static_cast<std::size_t>(j)] = j == K ? t_b : t_a + (t_b - t_a) * j / K;
      if (j == 0 && t_a == last_sample_time_) {
        // The previous step's end, sampled there: the same accepted solution (the interpolant
        // passes through it), with the root offsets of now.
        hidden_work_ = last_sample_;
        for (int k = 0; k < np_; ++k) hidden_work_[k] += root_offset_[static_cast<std::size_t>(k)];
      } else if (!RootsAt(times[static_cast<std::size_t>(j)], &hidden_work_)) {
        return false;
      }
      hidden_samples_.row(j) = hidden_work_.transpose();
    }
    // Kept without the offsets, which ArmRoots may change before the next step.
    last_sample_time_ = t_b;
    last_sample_ = hidden_samples_.row(K).transpose();
    for (int k = 0; k < np_; ++k) last_sample_[k] -= root_offset_[static_cast<std::size_t>(k)];
    const double threshold = -options_.event_tolerance;
    double t_negative = std::numeric_limits<double>::infinity();
    for (int i = 0; i < m; ++i) {
      const auto g = hidden_samples_.col(i);
      if (!(g[0] > 0.0)) continue;
      // An interior sample below the threshold (the step's end is IDA's own test).
      bool below = false;
      for (int j = 1; j < K && !below; ++j) {
        if (g[j] < threshold) {
          t_negative = std::min(t_negative, times[static_cast<std::size_t>(j)]);
          below = true;
        }
      }
      if (below) continue;
      Eigen::Index j_min = 0;
      g.minCoeff(&j_min);
      const int j0 = std::clamp(static_cast<int>(j_min) - 1, 0, K - 2);
      std::array<double, 3> a{times[static_cast<std::size_t>(j0)],
                              times[static_cast<std::size_t>(j0 + 1)],
                              times[static_cast<std::size_t>(j0 + 2)]};
      std::array<double, 3> b{g[j0], g[j0 + 1], g[j0 + 2]};
      for (int iteration = 0; iteration < kHiddenRootRefinements; ++iteration) {
        // The parabola through (a, b) in Newton form, and its vertex.
        const double d1 = (b[1] - b[0]) / (a[1] - a[0]);
        const double d2 = (b[2] - b[1]) / (a[2] - a[1]);
        const double c2 = (d2 - d1) / (a[2] - a[0]);
        if (!(c2 > 0.0)) break;  // not convex: no interior minimum
        const double t_v = 0.5 * (a[0] + a[1]) - d1 / (2.0 * c2);
        if (!(t_v > a[0] && t_v < a[2]) || t_v == a[1]) break;
        const double predicted = b[0] + d1 * (t_v - a[0]) + c2 * (t_v - a[0]) * (t_v - a[1]);
        if (!(predicted < threshold)) break;
        if (!RootsAt(t_v, &hidden_work_)) break;
        const double value = hidden_work_[i];
        if (value < threshold) {
          t_negative = std::min(t_negative, t_v);
          break;
        }
        // Keep the three points that bracket the smallest value.
        if (t_v < a[1]) {
          a = value < b[1] ? std::array<double, 3>{a[0], t_v, a[1]}
                           : std::array<double, 3>{t_v, a[1], a[2]};
          b = value < b[1] ? std::array<double, 3>{b[0], value, b[1]}
                           : std::array<double, 3>{value, b[1], b[2]};
        } else {
          a = value < b[1] ? std::array<double, 3>{a[1], t_v, a[2]}
                           : std::array<double, 3>{a[0], a[1], t_v};
          b = value < b[1] ? std::array<double, 3>{b[1], value, b[2]}
                           : std::array<double, 3>{b[0], b[1], value};
        }
      }
    }
    if (!std::isfinite(t_negative)) return false;
    // The first zero of the watched functions in [t_a, t_negative]: positive at lo, a
    // watched function at or below zero at hi.
    auto watched_minimum = [&](const Vector& values) {
      double minimum = std::numeric_limits<double>::infinity();
      for (int i = 0; i < m; ++i) {
        if (hidden_samples_(0, i) > 0.0) minimum = std::min(minimum, values[i]);
      }
      return minimum;
    };
    double lo = t_a, hi = t_negative;
    const double resolution = kHiddenRootResolution * std::numeric_limits<double>::epsilon() *
                              (std::fabs(t_b) + (t_b - t_a));
    while (hi - lo > resolution) {
      const double mid = 0.5 * (lo + hi);
      if (!RootsAt(mid, &hidden_work_)) return false;
      (watched_minimum(hidden_work_) <= 0.0 ? hi : lo) = mid;
    }
    if (!RootsAt(hi, &hidden_work_)) return false;
    hidden_roots_.assign(static_cast<std::size_t>(m), 0);
    for (int i = 0; i < m; ++i) {
      if (hidden_samples_(0, i) > 0.0 && hidden_work_[i] <= 0.0) {
        hidden_roots_[static_cast<std::size_t>(i)] = -1;
      }
    }
    *t_root = hi;
    return true;
  }

  // The root functions at t on IDA's interpolant of the last step; false outside it.
  bool RootsAt(double t, Vector* g) {
    if (IDAGetDky(memory_, t, 0, dky_->vector) < 0) return false;
    g->resize(np_ + nr_);
    try {
      Roots(dky_->vector, g->data());
    } catch (const std::exception&) {
      return false;  // not evaluable there: IDA's own test at the step's end stands
    }
    return g->allFinite();
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

  // At a root (IDA's, or `hidden`: the root functions that reached zero inside a step,
  // FindHiddenRoot): flip the relays whose switching function vanished, decide the statuses
  // of the pairs, restart.
  bool HandleRoots(const std::vector<int>* hidden = nullptr) {
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
  // Position-level conditions P (nz rows, aligned with the velocity-level rows) at the
  // evaluation `point`: the differentiated equations G and the continuous kept sides.
  void PositionLevel(const PointEvaluation& point, Vector* p) const {
    p->setZero(nz_);
    for (int r = 0; r < ng_; ++r) {
      if (system_.differentiated_equations()[static_cast<std::size_t>(r)]) (*p)[r] = point.G[r];
    }
    for (int k = 0; k < np_; ++k) {
      const PositionSide side = position_side_[static_cast<std::size_t>(k)];
      if (side != PositionSide::kNone)
        (*p)[ng_ + k] = side == PositionSide::kA ? point.A[k] : point.B[k];
    }
  }

  // f(row, column, wrt_z, value) for every stored entry of dP/dy (wrt_z false, column in y)
  // and dP/dz (wrt_z true, column in z) at `point`, streamed from the rows of G_y, G_z, A_y,
  // A_z, B_y, B_z that P selects: no P matrix is formed, and with sparse storage the cost is
  // the nonzeros of those blocks.
  template <class F>
  void ForEachPositionEntry(const PointEvaluation& point, F&& f) const {
    const auto& differentiated = system_.differentiated_equations();
    auto equation = [&](bool wrt_z) {
      return [&, wrt_z](int r, int j, double value) {
        if (differentiated[static_cast<std::size_t>(r)]) f(r, j, wrt_z, value);
      };
    };
    auto pair = [&](PositionSide kept, bool wrt_z) {
      return [&, kept, wrt_z](int k, int j, double value) {
        if (position_side_[static_cast<std::size_t>(k)] == kept) f(ng_ + k, j, wrt_z, value);
      };
    };
    if (ng_ > 0) {
      ForEachEntry(point.G_y, equation(false));
      ForEachEntry(point.G_z, equation(true));
    }
    if (np_ > 0) {
      ForEachEntry(point.A_y, pair(PositionSide::kA, false));
      ForEachEntry(point.A_z, pair(PositionSide::kA, true));
      ForEachEntry(point.B_y, pair(PositionSide::kB, false));
      ForEachEntry(point.B_z, pair(PositionSide::kB, true));
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
    if (nz_ > 0) PositionLevel(point_, &p);
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

  // J = dR/dY + c_j dR/dY', assembled straight into the solver's matrix: SUNDIALS' dense
  // matrix, or KLU's CSC matrix from triplets (no dense n x n intermediate).
  int Jacobian(double c_j, N_Vector Y, SUNMatrix J) {
    ++result_.stats.num_jacobian_evaluations;
    Vector y, z, v;
    Unpack(Y, &y, &z, &v);
    system_.Evaluate(y, z, Derivatives::kStates, &point_);
    if (nz_ > 0) system_.EvaluateVelocityLevel(y, v, roles_, Derivatives::kStates, &velocity_);
    if (sparse_) {
      triplets_.Clear();
      AssembleJacobian(c_j,
                       [this](int row, int col, double value) { triplets_.Add(row, col, value); });
      return WriteSparse(J);
    }
    double* data = SUNDenseMatrix_Data(J);
    const auto size = static_cast<std::size_t>(n_) * static_cast<std::size_t>(n_);
    std::fill(data, data + size, 0.0);
    // SUNDIALS' dense matrices are column-major with leading dimension n.
    AssembleJacobian(c_j, [data, n = static_cast<std::size_t>(n_)](int row, int col, double value) {
      data[static_cast<std::size_t>(col) * n + static_cast<std::size_t>(row)] += value;
    });
    return std::all_of(data, data + size, [](double x) { return std::isfinite(x); }) ? 0 : 1;
  }

  // add(row, column, value) for every entry of J at (point_, velocity_) (values summed). The
  // entries depend on the structure of the blocks and the phase's statuses only, never on
  // values: sparse blocks give their stored entries (structural zeros included), and the
  // diagonal is always present, so that the pattern holds within a phase and KLU's symbolic
  // analysis is reused (WriteSparse). With dense storage every entry of every block is added.
  template <class Add>
  void AssembleJacobian(double c_j, Add&& add) const {
    for (int i = 0; i < n_; ++i) add(i, i, 0.0);
    // (1) y' - F(y, z): F depends on y, z_c (continuous columns) and v_J (jump columns).
    for (int i = 0; i < ny_; ++i) add(i, i, c_j);
    ForEachEntry(point_.F_y, [&](int r, int j, double value) { add(r, j, -value); });
    ForEachEntry(point_.F_z, [&](int r, int i, double value) {
      add(r, z_column_[static_cast<std::size_t>(i)], -value);
    });
    // (2) z_c' - v_c, or P_k(y, z) for the multiplier of an index-1 pair (no z_c' term).
    for (int c = 0; c < nc_; ++c) {
      if (position_pair_[static_cast<std::size_t>(c)] >= 0) continue;
      add(ny_ + c, ny_ + c, c_j);
      add(ny_ + c, ny_ + nc_ + continuous_[static_cast<std::size_t>(c)], -1.0);
    }
    if (nz_ == 0) return;
    // (3) V(y, v) + kappa P(y, z_c, v_J).
    const int row0 = ny_ + nc_;
    ForEachEntry(velocity_.equations_y,
                 [&](int r, int j, double value) { add(row0 + r, j, value); });
    ForEachEntry(velocity_.equations_v,
                 [&](int r, int i, double value) { add(row0 + r, row0 + i, value); });
    const double kappa = options_.drift_rate;
    ForEachPositionEntry(point_, [&](int r, int j, bool wrt_z, double value) {
      const int col = wrt_z ? z_column_[static_cast<std::size_t>(j)] : j;
      if (kappa != 0.0) add(row0 + r, col, kappa * value);
      const int position_row = position_row_[static_cast<std::size_t>(r)];
      if (position_row >= 0) add(position_row, col, value);
    });
  }

  // Compresses the triplets into KLU's CSC matrix. A new pattern (a phase with other
  // statuses) redoes KLU's symbolic analysis (SUNLinSol_KLUReInit); otherwise KLU refactors
  // numerically on the analysis it has.
  int WriteSparse(SUNMatrix J) {
    if (!std::all_of(triplets_.values().begin(), triplets_.values().end(),
                     [](double x) { return std::isfinite(x); })) {
      return 1;
    }
    const bool new_pattern = triplets_.Compress(n_);
    const auto nnz = static_cast<sunindextype>(triplets_.inner().size());
    if (SUNSparseMatrix_NNZ(J) < nnz && SUNSparseMatrix_Reallocate(J, nnz) != 0) return -1;
    if (new_pattern) {
      if (SUNLinSol_KLUReInit(linear_solver_, J, SUNSparseMatrix_NNZ(J), SUNKLU_REINIT_PARTIAL) !=
          0) {
        return -1;
      }
      ++result_.stats.num_symbolic_analyses;
    }
    // IDA zeroes the matrix, indices included, before every Jacobian evaluation.
    std::copy(triplets_.outer().begin(), triplets_.outer().end(), SUNSparseMatrix_IndexPointers(J));
    std::copy(triplets_.inner().begin(), triplets_.inner().end(), SUNSparseMatrix_IndexValues(J));
    std::copy(triplets_.compressed().begin(), triplets_.compressed().end(),
              SUNSparseMatrix_Data(J));
    return 0;
  }

  int Roots(N_Vector Y, double* out) {
    Unpack(Y, &root_y_, &root_z_, &root_v_);
    const Vector& y = root_y_;
    if (np_ > 0) {
      system_.EvaluateEventIndicators(y, root_v_, a_zero_, Derivatives::kNone, &indicators_);
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
    // Rows: P (nz), then per pair whose continuous free side is a root, that free side.
    std::vector<int> reached_row(static_cast<std::size_t>(np_), -1);
    int rows = nz_;
    for (int k = 0; roots != nullptr && k < np_; ++k) {
      if ((*roots)[static_cast<std::size_t>(k)] != 0 && FreeSideIsContinuous(k)) {
        reached_row[static_cast<std::size_t>(k)] = rows++;
      }
    }
    auto Y = View(Y_->vector);
    for (int iteration = 0; iteration < kProjectionIterations; ++iteration) {
      Vector y, z, v;
      Unpack(Y_->vector, &y, &z, &v);
      system_.Evaluate(y, z, Derivatives::kStates, &point_);
      Vector p;
      PositionLevel(point_, &p);
      const double size = p.lpNorm<Eigen::Infinity>();
      if (iteration == 0) result_.stats.max_drift = std::max(result_.stats.max_drift, size);
      p.conservativeResize(rows);
      for (int k = 0; k < np_; ++k) {
        const int row = reached_row[static_cast<std::size_t>(k)];
        if (row >= 0) p[row] = a_zero_[static_cast<std::size_t>(k)] ? point_.B[k] : point_.A[k];
      }
      if (p.lpNorm<Eigen::Infinity>() <= kProjectionTolerance) break;
      Vector step;
      if (!ProjectionStep(reached_row, p, &step)) break;
      Y.head(nx_) += step.head(nx_);
      Y.segment(ny_, nc_) += step.tail(nc_);
    }
    y_ = Y.head(ny_);
  }

  // add(row, column, value) for the derivatives of the projection's rows (EndPhase) with
  // respect to its unknowns: the scene states x (columns 0..nx) and z_c (nx + c).
  template <class Add>
  void ForEachProjectionEntry(const std::vector<int>& reached_row, Add&& add) const {
    auto column = [this](int j, bool wrt_z) {
      if (!wrt_z) return j < nx_ ? j : -1;  // relay memories and the clock stay
      const int col = z_column_[static_cast<std::size_t>(j)];
      return col < ny_ + nc_ ? nx_ + col - ny_ : -1;  // jump unknowns are not moved
    };
    ForEachPositionEntry(point_, [&](int r, int j, bool wrt_z, double value) {
      const int col = column(j, wrt_z);
      if (col >= 0) add(r, col, value);
    });
    auto free_side = [&](bool b_side, bool wrt_z) {
      return [&, b_side, wrt_z](int k, int j, double value) {
        const int row = reached_row[static_cast<std::size_t>(k)];
        if (row < 0 || a_zero_[static_cast<std::size_t>(k)] != b_side) return;
        const int col = column(j, wrt_z);
        if (col >= 0) add(row, col, value);
      };
    };
    if (std::none_of(reached_row.begin(), reached_row.end(), [](int row) { return row >= 0; })) {
      return;
    }
    ForEachEntry(point_.A_y, free_side(false, false));
    ForEachEntry(point_.A_z, free_side(false, true));
    ForEachEntry(point_.B_y, free_side(true, false));
    ForEachEntry(point_.B_z, free_side(true, true));
  }

  // The minimum-norm Gauss-Newton step of (x, z_c) for the projection rows with values p at
  // point_. Dense storage: complete orthogonal decomposition of the rows x (nx + nc)
  // Jacobian. Sparse storage: step = -D^T (D D^T + delta I)^{-1} p with a sparse Cholesky
  // (LDL^T) factorization of the Gram matrix; delta (kProjectionRegularization relative to
  // its largest diagonal entry) keeps it definite when rows are redundant (a jammed crowd has
  // more contacts than degrees of freedom) or empty (pairs without a condition), and moves the
  // step from the minimum-norm one by a relative delta / sigma (sigma the smallest nonzero
  // eigenvalue of D D^T), which the next iteration corrects. False if the factorization fails.
  bool ProjectionStep(const std::vector<int>& reached_row, const Vector& p, Vector* step) const {
    const auto rows = p.size();
    const int cols = nx_ + nc_;
    if (!system_.sparse()) {
      Matrix jacobian = Matrix::Zero(rows, cols);
      ForEachProjectionEntry(reached_row,
                             [&](int r, int c, double value) { jacobian(r, c) += value; });
      *step = jacobian.completeOrthogonalDecomposition().solve(-p);
      return true;
    }
    std::vector<Eigen::Triplet<double, int>> entries;
    ForEachProjectionEntry(reached_row,
                           [&](int r, int c, double value) { entries.emplace_back(r, c, value); });
    SparseMatrix jacobian(rows, cols);
    jacobian.setFromTriplets(entries.begin(), entries.end());
    SparseMatrix gram = jacobian * SparseMatrix(jacobian.transpose());
    const double largest = gram.diagonal().size() > 0 ? gram.diagonal().maxCoeff() : 0.0;
    const double delta = kProjectionRegularization * std::max(largest, 1.0);
    for (Eigen::Index i = 0; i < rows; ++i) gram.coeffRef(i, i) += delta;
    Eigen::SimplicialLDLT<SparseMatrix> cholesky(gram);
    if (cholesky.info() != Eigen::Success) return false;
    const Vector w = cholesky.solve(-p);
    if (cholesky.info() != Eigen::Success || !w.allFinite()) return false;
    *step = jacobian.transpose() * w;
    return true;
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

  // Hidden roots (FindHiddenRoot): sub-intervals sampled per step (five evaluations of the
  // root functions per step); parabolic refinements of a predicted dip; the bisection's
  // resolution in units of eps (|t| + h), IDA's own root resolution (IDARcheck3: 100 uround).
  static constexpr int kHiddenRootIntervals = 4;
  static constexpr int kHiddenRootRefinements = 8;
  static constexpr double kHiddenRootResolution = 100.0;
  // Projection onto the phase's position-level conditions: Gauss-Newton iterations until |P|
  // is at round-off level.
  static constexpr int kProjectionIterations = 3;
  static constexpr double kProjectionTolerance = 1e-15;
  // Regularization of the sparse projection's Gram matrix relative to its largest diagonal
  // entry (ProjectionStep): a contraction of 1e-8 per iteration down to sigma = 1e-4 of it.
  static constexpr double kProjectionRegularization = 1e-12;

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
  std::vector<int> continuous_;  // indices in z of the continuous variables
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
    long steps = 0, residuals = 0, iterations = 0, failures = 0;
  } counted_;  // IDA's counters already added to the stats since the last IDAReInit
  PointEvaluation point_;
  VelocityLevelEvaluation velocity_;
  IndicatorEvaluation indicators_;
  // FindHiddenRoot's samples (rows: times, columns: root functions), a row, and its result.
  Matrix hidden_samples_;
  Vector hidden_work_;
  std::vector<int> hidden_roots_;
  // The root functions without offsets at the end of the last scanned step, and its time
  // (NaN after a restart): the next step's first sample.
  double last_sample_time_ = std::numeric_limits<double>::quiet_NaN();
  Vector last_sample_;
  Vector root_y_, root_z_, root_v_;  // Roots' unpacked arguments (no allocation per call)
  // Per algebraic unknown i: its IDA column (ny + c for the c-th continuous one, carried as
  // z_c; ny + nc + i for a jump one). Per position-level row: the IDA row of the index-1
  // multiplier it determines, or -1.
  std::vector<int> z_column_, position_row_;
  // Per pair: which side is a position-level condition in this phase (PositionLevel).
  enum class PositionSide : unsigned char { kNone, kA, kB };
  std::vector<PositionSide> position_side_;
  TripletAssembly triplets_;  // the KLU Jacobian's triplets and CSC pattern
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
