// The phase DAE IDA integrates: its residual, its Jacobian assembled into SUNDIALS' dense or
// KLU's CSC matrix, and the error weights of IDA's local error test (ida_run.hpp).

#include <ida/ida.h>
#include <sunlinsol/sunlinsol_klu.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunmatrix/sunmatrix_sparse.h>

#include <cmath>

#include "ida_run.hpp"

namespace moreau::internal {

// Position-level conditions P (nz rows, aligned with the velocity-level rows) at the
// evaluation `point`: the differentiated equations G and the continuous kept sides.
void IdaRun::PositionLevel(const PointEvaluation& point, Vector* p) const {
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

// Splits an IDA vector into y, z (continuous values from z_c) and v.
void IdaRun::Unpack(N_Vector Y, Vector* y, Vector* z, Vector* v) const {
  const auto all = View(Y);
  *y = all.head(ny_);
  *v = all.tail(nz_);
  *z = *v;
  for (int c = 0; c < nc_; ++c) (*z)[continuous_[static_cast<std::size_t>(c)]] = all[ny_ + c];
}

// R = [y' - F(y, z); z_c' - v_c; V(y, v) + kappa P(y, z)]; for the multiplier of an
// index-1 pair the z_c row is its kept side at position level instead (P_k = 0).
int IdaRun::Residual(N_Vector Y, N_Vector Yp, N_Vector R) {
  Vector &y = unpacked_y_, &z = unpacked_z_, &v = unpacked_v_;
  Unpack(Y, &y, &z, &v);
  const auto yp = View(Yp);
  auto r = View(R);
  system_.Evaluate(y, z, Derivatives::kNone, &point_);
  r.head(ny_) = yp.head(ny_) - point_.F;
  Vector& p = position_;
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
int IdaRun::Jacobian(double c_j, N_Vector Y, SUNMatrix J) {
  ++result_.stats.num_jacobian_evaluations;
  Vector &y = unpacked_y_, &z = unpacked_z_, &v = unpacked_v_;
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
void IdaRun::AssembleJacobian(double c_j, Add&& add) const {
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
  ForEachEntry(velocity_.equations_y, [&](int r, int j, double value) { add(row0 + r, j, value); });
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
int IdaRun::WriteSparse(SUNMatrix J) {
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
  std::copy(triplets_.compressed().begin(), triplets_.compressed().end(), SUNSparseMatrix_Data(J));
  return 0;
}

// C callbacks: exceptions (a throwing model function) stop IDA with an unrecoverable error.
int IdaRun::ResidualCallback(double, N_Vector Y, N_Vector Yp, N_Vector R, void* user_data) {
  auto* run = static_cast<IdaRun*>(user_data);
  try {
    return run->Residual(Y, Yp, R);
  } catch (const std::exception& error) {
    run->last_error_ = error.what();
    return -1;
  }
}

int IdaRun::JacobianCallback(double, double c_j, N_Vector Y, N_Vector, N_Vector, SUNMatrix J,
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
int IdaRun::WeightCallback(N_Vector Y, N_Vector ewt, void* user_data) {
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

}  // namespace moreau::internal
