#pragma once
// One IDA run over a lowered scene (include/moreau/integrators/ida.hpp, docs/ida.md). Private
// to moreau::integrators; SUNDIALS types stay in these files. Split by concern:
//   ida.cpp           options, statuses, the entry points SimulateIda and ComputeReference
//   ida_run.cpp       SUNDIALS set-up, the run over control segments, phases and restarts
//   ida_events.cpp    root functions, roots inside a step, projection at the end of a phase
//   ida_residual.cpp  the phase DAE: residual, Jacobian (dense or KLU), error weights

#include <ida/ida.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sundials/sundials_linearsolver.h>
#include <sundials/sundials_matrix.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "../common/crossing_search.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/model/lowered_system.hpp"

namespace moreau::internal {

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
inline Eigen::Map<Vector> View(N_Vector v) {
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
  IdaRun(const Scene& scene, const IdaOptions& options, const ProgressCallback& progress);
  ~IdaRun();
  IdaRun(const IdaRun&) = delete;
  IdaRun& operator=(const IdaRun&) = delete;

  IdaResult Run();

 private:
  // --- set-up and the run (ida_run.cpp) -------------------------------------------------------
  static LoweringOptions Lowering(const IdaOptions& options);

  bool failed() const { return result_.status != IdaStatus::kSuccess; }

  void Fail(IdaStatus status, double t, const std::string& reason);

  void CreateSolver(double t0);

  static void Check(int flag, const char* what) {
    MOREAU_ASSERT(flag >= 0, std::string(what) + " failed with flag " + std::to_string(flag));
  }

  // SUNDIALS' error handler: keeps the last message for the failure status.
  static void ErrorCallback(int, const char*, const char* function, char* message, void* user_data);

  // --- phases (ida_run.cpp) -------------------------------------------------------------------
  // Decides the statuses at (t_, y_) and records the events against `previous` (null at t0).
  bool Decide(double t, const std::vector<bool>* previous);

  // Consistent values at (t, y_) for the statuses a_zero_ and velocity-level values v_, and
  // an IDA restart from them.
  void StartPhase(double t);

  // Offsets the root functions of free sides that start within the event tolerance of zero
  // until they have left it (the noise of a zero rate is not an event; definition).
  void ArmRoots(bool phase_start);

  // Adds IDA's counters since the last accumulation (IDAReInit resets them; ReInit below
  // accumulates first), so that calling it twice counts nothing twice.
  void AccumulateStats();

  // IDAReInit at (t, Y_, Yp_), its counters accumulated first.
  void ReInit(double t);

  // Integrates from t_ to t_end (a breakpoint or tf), handling roots on the way.
  void Integrate(double t_end);

  // Trajectory points at the output times passed by the last step (IDA's interpolant).
  void RecordOutputTimes(double t_return);
  // The non-finite model value the lowered system met since the last IDASolve (named), or
  // empty.
  std::string NonFiniteWitness() const;

  // Algebraic values in the z layout from an IDA vector (continuous ones from z_c).
  Vector Algebraic(const Eigen::Ref<const Vector>& Y) const;

  // A trajectory point at (t, y_) with the last step h.
  void Record(double t, double h);

  // At a root (IDA's, or `hidden`: the root functions that reached zero inside a step,
  // FindHiddenRoot): flip the relays whose switching function vanished, decide the statuses
  // of the pairs, restart.
  bool HandleRoots(const std::vector<int>* hidden = nullptr);

  // Flips every relay whose switching function is <= 0 (within the event tolerance) and
  // records its jump.
  void SwitchRelays(double t, const Vector& switching, bool initial);

  // At a breakpoint or tf: a free side that is zero there is an event decided at that time.
  // Returns false on failure.
  bool DecideAtBoundary(double t);

  // --- roots and phase ends (ida_events.cpp) --------------------------------------------------
  // IDA's root functions at Y: free sides (offset until armed) and relay switching functions.
  int Roots(N_Vector Y, double* out);

  // A root function that falls below zero and recovers inside the step [t_a, t_b], which
  // IDA's sign test at the step's ends cannot see: *t_root its first zero (definition).
  bool FindHiddenRoot(double t_a, double t_b, double* t_root);

  // The root functions at t on IDA's interpolant of the last step; false outside it.
  bool RootsAt(double t, Vector* g);

  // The crossing search of common/crossing_search.hpp on IDA's interpolant over [t_a, t_b]
  // (its Taylor expansion at t_b from IDAGetDky, of the order IDA used): bounds of the root
  // functions over the interpolant's boxes, values on it. Watches the functions positive at
  // t_a (the columns of hidden_samples_ row 0). Returns true with *t_negative a time where a
  // watched function is below -event_tolerance; counts an unresolved search.
  bool BoundedHiddenRoot(double t_a, double t_b, double* t_negative);

  // At the end of a phase: the drift certificate, then the projection onto the phase's
  // position-level conditions and the continuous free sides that reached zero (definition).
  void EndPhase(const std::vector<int>* roots = nullptr);

  // add(row, column, value) for the derivatives of the projection's rows (EndPhase) with
  // respect to its unknowns: the scene states x (columns 0..nx) and z_c (nx + c).
  template <class Add>
  void ForEachProjectionEntry(const std::vector<int>& reached_row, Add&& add) const;

  // The minimum-norm Gauss-Newton step of (x, z_c) for the projection rows with values p at
  // point_ (dense: complete orthogonal decomposition; sparse: regularized Gram LDL^T).
  bool ProjectionStep(const std::vector<int>& reached_row, const Vector& p, Vector* step) const;

  // True if pair k's free side for the current statuses is a continuous variable (a
  // constraint value or a Stewart lambda: a position-level condition when it is zero) rather
  // than a jump variable (a multiplier, zero only at velocity level).
  bool FreeSideIsContinuous(int k) const;

  // --- the phase DAE (ida_residual.cpp) -------------------------------------------------------
  // Position-level conditions P (nz rows, aligned with the velocity-level rows) at the
  // evaluation `point`: the differentiated equations G and the continuous kept sides.
  void PositionLevel(const PointEvaluation& point, Vector* p) const;

  // f(row, column, wrt_z, value) for every stored entry of dP/dy (wrt_z false, column in y) and
  // dP/dz (wrt_z true, column in z) at `point`, streamed from the rows of G_y, G_z, A_y, A_z, B_y,
  // B_z that P selects (no P matrix is formed).
  template <class F>
  void ForEachPositionEntry(const PointEvaluation& point, F&& f) const;

  // Splits an IDA vector into y, z (continuous values from z_c) and v.
  void Unpack(N_Vector Y, Vector* y, Vector* z, Vector* v) const;

  // R = [y' - F(y, z); z_c' - v_c; V(y, v) + kappa P(y, z)]; for the multiplier of an
  // index-1 pair the z_c row is its kept side at position level instead (P_k = 0).
  int Residual(N_Vector Y, N_Vector Yp, N_Vector R);

  // J = dR/dY + c_j dR/dY', assembled straight into the solver's matrix: SUNDIALS' dense
  // matrix, or KLU's CSC matrix from triplets (no dense n x n intermediate).
  int Jacobian(double c_j, N_Vector Y, SUNMatrix J);

  // add(row, column, value) for every entry of J at (point_, velocity_) (values summed).
  template <class Add>
  void AssembleJacobian(double c_j, Add&& add) const;

  // Compresses the triplets into KLU's CSC matrix. A new pattern (a phase with other
  // statuses) redoes KLU's symbolic analysis (SUNLinSol_KLUReInit); otherwise KLU refactors
  // numerically on the analysis it has.
  int WriteSparse(SUNMatrix J);

  // --- C callbacks (ida_residual.cpp, ida_events.cpp) ----------------------------------------
  // Exceptions from a throwing model function stop IDA with an unrecoverable error.
  static int ResidualCallback(double, N_Vector Y, N_Vector Yp, N_Vector R, void* user_data);
  static int JacobianCallback(double, double c_j, N_Vector Y, N_Vector, N_Vector, SUNMatrix J,
                              void* user_data, N_Vector, N_Vector, N_Vector);

  // Error weights 1/(rtol |Y_i| + atol), those of the scene states x and of the carried continuous
  // algebraic variables z_c scaled by sqrt(N / n_x), so that IDA's local error test (the weighted
  // RMS over all N components) is the RMS over the n_x scene states, as for an ODE in x alone, plus
  // the errors of z_c.
  static int WeightCallback(N_Vector Y, N_Vector ewt, void* user_data);
  static int RootCallback(double, N_Vector Y, N_Vector, double* out, void* user_data);

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
  // BoundedHiddenRoot's work storage, kept across steps (a step allocates nothing in it).
  // IDA's largest BDF order (its default, set explicitly in CreateSolver).
  static constexpr int kMaxBdfOrder = 5;
  struct BoundedRootBuffers {
    // The interpolant of the last step, one per BDF order (its coefficients and Taylor
    // scratch keep their size while the order changes: no allocation per step).
    std::array<internal::PolynomialPath, kMaxBdfOrder + 1> paths;
    std::vector<char> watched;
    Vector e, thresholds, box_lower, box_upper, pair_lower, pair_upper, relay_lower, relay_upper;
    internal::CrossingWorkspace search;
  };
  BoundedRootBuffers bounded_root_;
  // Sizes every order's path once (BoundedHiddenRoot then only writes into them).
  void SizeBoundedRootPaths();
  double first_unresolved_time_ = 0.0;
  // The root functions without offsets at the end of the last scanned step, and its time
  // (NaN after a restart): the next step's first sample.
  double last_sample_time_ = std::numeric_limits<double>::quiet_NaN();
  Vector last_sample_;
  Vector root_y_, root_z_, root_v_;  // Roots' unpacked arguments (no allocation per call)
  // Residual's and Jacobian's (never nested in each other), and the residual's position level.
  Vector unpacked_y_, unpacked_z_, unpacked_v_, position_;
  // Per algebraic unknown i: its IDA column (ny + c for the c-th continuous one, carried as
  // z_c; ny + nc + i for a jump one). Per position-level row: the IDA row of the index-1
  // multiplier it determines, or -1.
  std::vector<int> z_column_, position_row_;
  // Per pair: which side is a position-level condition in this phase (PositionLevel).
  enum class PositionSide : unsigned char { kNone, kA, kB };
  std::vector<PositionSide> position_side_;
  TripletAssembly triplets_;  // the KLU Jacobian's triplets and CSC pattern
};

// f(row, column, wrt_z, value) for every stored entry of dP/dy (wrt_z false, column in y)
// and dP/dz (wrt_z true, column in z) at `point`, streamed from the rows of G_y, G_z, A_y,
// A_z, B_y, B_z that P selects: no P matrix is formed, and with sparse storage the cost is
// the nonzeros of those blocks.
template <class F>
void IdaRun::ForEachPositionEntry(const PointEvaluation& point, F&& f) const {
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

}  // namespace moreau::internal
