#include "moreau/linalg/linear_solver.hpp"

#include <klu.h>
#include <umfpack.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "compress_entries.hpp"
#include "dense_columns.hpp"
#include "moreau/core/error.hpp"

namespace moreau {

std::string ToString(LinearSolverKind kind) {
  switch (kind) {
    case LinearSolverKind::kAutomatic:
      return "auto";
    case LinearSolverKind::kDenseLu:
      return "dense";
    case LinearSolverKind::kSparseLu:
      return "sparse";
    case LinearSolverKind::kKlu:
      return "klu";
  }
  return "?";
}

LinearSolverKind ParseLinearSolverKind(const std::string& name) {
  if (name == "auto") return LinearSolverKind::kAutomatic;
  if (name == "dense") return LinearSolverKind::kDenseLu;
  if (name == "sparse") return LinearSolverKind::kSparseLu;
  if (name == "klu") return LinearSolverKind::kKlu;
  ThrowInvalidArgument("unknown linear solver '", name, "'; expected auto, dense, sparse or klu");
}

std::string ToString(FactorizationStatus status) {
  switch (status) {
    case FactorizationStatus::kSuccess:
      return "success";
    case FactorizationStatus::kSingular:
      return "singular";
    case FactorizationStatus::kNonFinite:
      return "non-finite";
  }
  return "?";
}

// ---- SystemMatrix --------------------------------------------------------------------------

void SystemMatrix::Reset(int n, bool sparse) {
  n_ = n;
  sparse_ = sparse;
  if (sparse_) {
    triplets_.clear();
    dense_.resize(0, 0);
  } else {
    dense_.setZero(n, n);
  }
}

void SystemMatrix::AddDenseColumns(int row0, int col0, const double* data, Eigen::Index rows,
                                   Eigen::Index cols, Eigen::Index stride, double scale) {
  MOREAU_ASSERT(row0 >= 0 && col0 >= 0 && row0 + rows <= n_ && col0 + cols <= n_,
                "block outside the system matrix");
  internal::AddScaledColumns(dense_.data() + static_cast<Eigen::Index>(col0) * n_ + row0, n_, data,
                             stride, rows, cols, scale);
}

void SystemMatrix::AddBlock(int row0, int col0, const ConstMatrixRef& block, double scale) {
  MOREAU_ASSERT(row0 >= 0 && col0 >= 0 && row0 + block.rows() <= n_ && col0 + block.cols() <= n_,
                "block outside the system matrix");
  if (!sparse_) {
    AddDenseColumns(row0, col0, block.data(), block.rows(), block.cols(), block.outerStride(),
                    scale);
    return;
  }
  for (Eigen::Index j = 0; j < block.cols(); ++j) {
    for (Eigen::Index i = 0; i < block.rows(); ++i) {
      triplets_.emplace_back(row0 + static_cast<int>(i), col0 + static_cast<int>(j),
                             scale * block(i, j));
    }
  }
}

void SystemMatrix::AddSparseBlock(int row0, int col0, const SparseMatrix& block, double scale) {
  MOREAU_ASSERT(row0 + block.rows() <= n_ && col0 + block.cols() <= n_,
                "sparse block outside the system matrix");
  for (int j = 0; j < block.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(block, j); it; ++it) {
      if (sparse_) {
        triplets_.emplace_back(row0 + it.row(), col0 + it.col(), scale * it.value());
      } else {
        dense_(row0 + it.row(), col0 + it.col()) += scale * it.value();
      }
    }
  }
}

void SystemMatrix::AddDerivative(int row0, int col0, const DerivativeMatrix& m, double scale) {
  if (m.is_sparse()) {
    AddSparseBlock(row0, col0, m.sparse(), scale);
  } else if (!sparse_) {
    // Straight from the matrix: small blocks (the stage Jacobians of the smooth Radau kernel)
    // are added in every Newton matrix, where building a Ref costs about as much as the adds.
    const Matrix& block = m.dense();
    AddDenseColumns(row0, col0, block.data(), block.rows(), block.cols(), block.rows(), scale);
  } else {
    AddBlock(row0, col0, m.dense(), scale);
  }
}

void SystemMatrix::AddWeightedRows(int row0, int col0, const ConstVectorRef& row_weights,
                                   const DerivativeMatrix& m) {
  MOREAU_ASSERT(row_weights.size() == m.rows(), "AddWeightedRows: one weight per row");
  if (!m.is_sparse()) {
    MOREAU_ASSERT(row0 + m.rows() <= n_ && col0 + m.cols() <= n_, "block outside the matrix");
    if (!sparse_) {
      const Matrix& block = m.dense();
      const Eigen::Index rows = block.rows();
      for (Eigen::Index j = 0; j < block.cols(); ++j) {
        double* target = dense_.data() + (col0 + j) * n_ + row0;
        const double* source = block.data() + j * rows;
        for (Eigen::Index i = 0; i < rows; ++i) target[i] += row_weights[i] * source[i];
      }
    } else {
      AddBlock(row0, col0, row_weights.asDiagonal() * m.dense());
    }
    return;
  }
  const SparseMatrix& block = m.sparse();
  MOREAU_ASSERT(row0 + block.rows() <= n_ && col0 + block.cols() <= n_,
                "sparse block outside the system matrix");
  for (int j = 0; j < block.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(block, j); it; ++it) {
      // Rows with weight zero leave no entries: a pair kept at b = 0 then has a row with b's
      // entry alone (a status equation), whose elimination creates no fill, where the a-side
      // entries would couple everything a depends on. The pattern changes only when a weight
      // becomes zero or nonzero (statuses: at switches), and the sparse LU analyzes anew then.
      if (row_weights[it.row()] == 0.0) continue;
      const double value = row_weights[it.row()] * it.value();
      if (sparse_) {
        triplets_.emplace_back(row0 + it.row(), col0 + it.col(), value);
      } else {
        dense_(row0 + it.row(), col0 + it.col()) += value;
      }
    }
  }
}

void SystemMatrix::AddScaledRow(int row, int col0, int k, double weight,
                                const DerivativeMatrix& m) {
  MOREAU_ASSERT(k >= 0 && k < m.rows() && row < n_ && col0 + m.cols() <= n_,
                "AddScaledRow: wrong sizes");
  if (!m.is_sparse()) {
    if (!sparse_) {
      dense_.row(row).segment(col0, m.cols()) += weight * m.dense().row(k);
    } else {
      AddBlock(row, col0, weight * m.dense().row(k));
    }
    return;
  }
  // Compressed columns with ascending row indices: row k's entry of column j, if stored, is
  // found by binary search.
  const SparseMatrix& block = m.sparse();
  const int* outer = block.outerIndexPtr();
  const int* inner = block.innerIndexPtr();
  const double* values = block.valuePtr();
  for (int j = 0; j < block.outerSize(); ++j) {
    const int* begin = inner + outer[j];
    const int* end = inner + outer[j + 1];
    const int* at = std::lower_bound(begin, end, k);
    if (at != end && *at == k) AddEntry(row, col0 + j, weight * values[at - inner]);
  }
}

void SystemMatrix::AddDiagonal(int row0, int col0, int count, double value) {
  MOREAU_ASSERT(row0 + count <= n_ && col0 + count <= n_, "diagonal outside the system matrix");
  if (!sparse_) {
    for (int i = 0; i < count; ++i) dense_(row0 + i, col0 + i) += value;
    return;
  }
  for (int i = 0; i < count; ++i) triplets_.emplace_back(row0 + i, col0 + i, value);
}

void SystemMatrix::AddEntry(int row, int col, double value) {
  if (sparse_) {
    triplets_.emplace_back(row, col, value);
  } else {
    dense_(row, col) += value;
  }
}

void SystemMatrix::Finalize() {
  if (!sparse_) return;
  internal::CompressEntries(triplets_, n_, n_, &sparse_matrix_, &plan_);
}

Vector SystemMatrix::Multiply(const Vector& x) const {
  return sparse_ ? Vector(sparse_matrix_ * x) : Vector(dense_ * x);
}

Vector SystemMatrix::MultiplyTransposed(const Vector& x) const {
  return sparse_ ? Vector(sparse_matrix_.transpose() * x) : Vector(dense_.transpose() * x);
}

void SystemMatrix::MultiplyTransposed(const Vector& x, Vector* y) const {
  if (sparse_) {
    y->noalias() = sparse_matrix_.transpose() * x;  // (y is never x: no temporary)
  } else {
    y->noalias() = dense_.transpose() * x;
  }
}

double SystemMatrix::InfinityNorm() const {
  if (!sparse_) return n_ == 0 ? 0.0 : dense_.cwiseAbs().rowwise().sum().maxCoeff();
  Vector row_sums = Vector::Zero(n_);
  for (int j = 0; j < sparse_matrix_.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(sparse_matrix_, j); it; ++it) {
      row_sums[it.row()] += std::fabs(it.value());
    }
  }
  return n_ == 0 ? 0.0 : row_sums.maxCoeff();
}

void LinearSolver::SolveMatrix(MatrixRef rhs) const {
  for (Eigen::Index j = 0; j < rhs.cols(); ++j) {
    Vector column = rhs.col(j);
    Solve(column);
    rhs.col(j) = column;
  }
}

namespace {

// ---- dense LU ------------------------------------------------------------------------------
// Up to this size the LU with partial pivoting is computed by the plain loops below; Eigen's
// PartialPivLU dispatches every column through dynamic-size block expressions, whose set-up
// costs several times the arithmetic of the small systems that integrators solve most often
// (FESD elements of 10 to 60 unknowns, velocity-level problems of a few). Larger systems use
// Eigen's blocked factorization.
constexpr int kSmallDenseLu = 64;

// True if no entry is infinite or NaN (those have every exponent bit set: adding one to the
// lowest exponent bit then carries into the sign bit, for them only). An integer reduction
// of and, add and or without early exit: it vectorizes, where Eigen's allFinite tests entry
// by entry (a fifth of the cost of a small factorization).
bool AllFinite(const Matrix& a) {
  constexpr std::uint64_t kExponent = 0x7ff0000000000000ULL;
  constexpr std::uint64_t kLowestExponentBit = std::uint64_t{1} << 52;
  const double* x = a.data();
  std::uint64_t bad = 0;
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    std::uint64_t bits = 0;
    std::memcpy(&bits, x + i, sizeof bits);
    bad |= (bits & kExponent) + kLowestExponentBit;
  }
  return (bad >> 63) == 0;
}

class DenseLuSolver final : public LinearSolver {
 public:
  LinearSolverKind kind() const override { return LinearSolverKind::kDenseLu; }

  FactorizationStatus Factorize(const SystemMatrix& a) override {
    MOREAU_ASSERT(!a.sparse(), "dense LU needs dense storage");
    ++num_factorizations_;
    if (!AllFinite(a.dense())) return FactorizationStatus::kNonFinite;
    n_ = a.size();
    if (n_ == 0) {
      rcond_ = 1.0;
      return FactorizationStatus::kSuccess;
    }
    small_ = n_ <= kSmallDenseLu;
    if (small_) {
      FactorizeSmall(a.dense());
    } else {
      lu_.compute(a.dense());
    }
    // Singularity from the pivots of U (O(n)): min |u_ii| / max |u_ii|. This is a lower bound
    // on nothing in general, but with partial pivoting a tiny ratio is how rank deficiency shows,
    // and it costs nothing next to the L1 condition estimator (which dominated the cost of the
    // small factorizations of collocation steps).
    const auto pivots = (small_ ? small_lu_ : lu_.matrixLU()).diagonal().cwiseAbs();
    const double largest = pivots.maxCoeff();
    rcond_ = largest > 0.0 ? pivots.minCoeff() / largest : 0.0;
    if (rcond_ >= kSingularRcond) return FactorizationStatus::kSuccess;
    // The plain ratio changes with the units of the unknowns: a FESD group on a time scale of
    // 1e-5 s has an element length of 1e-6 beside multipliers of 1e5, columns 1e11 apart, and
    // its pivots spread accordingly although the system is well posed. Partial pivoting
    // permutes rows only, so pivot j belongs to column j, and |u_jj| relative to the largest
    // entry of column j of A does not change with column scaling: the matrix is singular only
    // if the ratio of these is small as well. (Sparse LU's rcond is left as it is: its row
    // scaling and threshold pivoting make no such ratio invariant.)
    column_max_ = a.dense().cwiseAbs().colwise().maxCoeff().transpose();
    double lowest = std::numeric_limits<double>::infinity(), highest = 0.0;
    for (int j = 0; j < n_; ++j) {
      const double relative = column_max_[j] > 0.0 ? pivots[j] / column_max_[j] : 0.0;
      lowest = std::min(lowest, relative);
      highest = std::max(highest, relative);
    }
    rcond_ = std::max(rcond_, highest > 0.0 ? lowest / highest : 0.0);
    if (!(rcond_ >= kSingularRcond)) return FactorizationStatus::kSingular;
    return FactorizationStatus::kSuccess;
  }
  void Solve(VectorRef rhs) const override {
    if (small_) {
      SolveSmall(rhs);
    } else {
      // Eigen's PartialPivLU::_solve_impl (c = P rhs, unit-lower then upper solves in place)
      // in kept scratch: `rhs = lu_.solve(rhs)` formed P rhs in a temporary per solve.
      Vector& c = solve_scratch_;
      c.noalias() = lu_.permutationP() * rhs;
      lu_.matrixLU().triangularView<Eigen::UnitLower>().solveInPlace(c);
      lu_.matrixLU().triangularView<Eigen::Upper>().solveInPlace(c);
      rhs = c;
    }
  }
  void SolveMatrix(MatrixRef rhs) const override {
    if (small_) {
      for (Eigen::Index j = 0; j < rhs.cols(); ++j) SolveSmall(rhs.col(j));
    } else {
      rhs = lu_.solve(rhs);
    }
  }
  void SolveTransposed(VectorRef rhs) const override {
    if (small_) {
      SolveTransposedSmall(rhs);
    } else {
      rhs = lu_.transpose().solve(rhs);
    }
  }
  double reciprocal_condition() const override { return rcond_; }

 private:
  // P A = L U in place (L unit lower, U upper), right-looking, column by column; pivot_[k] is
  // the row swapped with row k at step k. A zero pivot leaves its column unscaled (the matrix
  // is reported singular by the pivot ratio).
  // The multipliers of a column are often mostly zero (the Jacobians of collocation and
  // complementarity systems are block sparse): the update then runs over the nonzero ones
  // only. Skipping zero multipliers and zero entries of U changes no result (x - 0 u = x).
  void FactorizeSmall(const Matrix& a) {
    small_lu_ = a;
    pivot_.resize(static_cast<std::size_t>(n_));
    rows_.resize(static_cast<std::size_t>(n_));
    double* lu = small_lu_.data();
    int* rows = rows_.data();
    const int n = n_;
    for (int k = 0; k < n; ++k) {
      double* column_k = lu + static_cast<std::ptrdiff_t>(k) * n;
      int p = k;
      double biggest = std::fabs(column_k[k]);
      for (int i = k + 1; i < n; ++i) {
        if (std::fabs(column_k[i]) > biggest) {
          biggest = std::fabs(column_k[i]);
          p = i;
        }
      }
      pivot_[static_cast<std::size_t>(k)] = p;
      if (p != k) {
        for (int j = 0; j < n; ++j) std::swap(lu[k + j * n], lu[p + j * n]);
      }
      const double pivot = column_k[k];
      if (pivot == 0.0) continue;
      int count = 0;
      for (int i = k + 1; i < n; ++i) {
        if (column_k[i] == 0.0) continue;
        column_k[i] /= pivot;
        rows[count++] = i;
      }
      if (count == 0) continue;
      const bool all_rows = count == n - k - 1;  // contiguous: the loop vectorizes
      for (int j = k + 1; j < n; ++j) {
        double* column_j = lu + static_cast<std::ptrdiff_t>(j) * n;
        const double u = column_j[k];
        if (u == 0.0) continue;
        if (all_rows) {
          for (int i = k + 1; i < n; ++i) column_j[i] -= column_k[i] * u;
        } else {
          for (int r = 0; r < count; ++r) column_j[rows[r]] -= column_k[rows[r]] * u;
        }
      }
    }
  }
  // A x = b: b permuted, L y = P b forward, U x = y backward.
  void SolveSmall(VectorRef x) const {
    const int n = n_;
    const double* lu = small_lu_.data();
    for (int k = 0; k < n; ++k) {
      const int p = pivot_[static_cast<std::size_t>(k)];
      if (p != k) std::swap(x[k], x[p]);
    }
    for (int k = 0; k < n; ++k) {
      const double xk = x[k];
      if (xk == 0.0) continue;
      const double* column = lu + static_cast<std::ptrdiff_t>(k) * n;
      for (int i = k + 1; i < n; ++i) x[i] -= column[i] * xk;
    }
    for (int k = n - 1; k >= 0; --k) {
      const double* column = lu + static_cast<std::ptrdiff_t>(k) * n;
      x[k] /= column[k];
      const double xk = x[k];
      if (xk == 0.0) continue;
      for (int i = 0; i < k; ++i) x[i] -= column[i] * xk;
    }
  }
  // A^T x = b with A = P^T L U: U^T y = b forward, L^T z = y backward, x = P^T z.
  void SolveTransposedSmall(VectorRef x) const {
    const int n = n_;
    const double* lu = small_lu_.data();
    for (int k = 0; k < n; ++k) {
      const double* column = lu + static_cast<std::ptrdiff_t>(k) * n;
      double sum = x[k];
      for (int i = 0; i < k; ++i) sum -= column[i] * x[i];
      x[k] = sum / column[k];
    }
    for (int k = n - 1; k >= 0; --k) {
      const double* column = lu + static_cast<std::ptrdiff_t>(k) * n;
      double sum = x[k];
      for (int i = k + 1; i < n; ++i) sum -= column[i] * x[i];
      x[k] = sum;
    }
    for (int k = n - 1; k >= 0; --k) {
      const int p = pivot_[static_cast<std::size_t>(k)];
      if (p != k) std::swap(x[k], x[p]);
    }
  }

  int n_ = 0;
  bool small_ = true;
  Matrix small_lu_;
  Vector column_max_;  // scratch of the singularity test
  std::vector<int> pivot_, rows_;
  Eigen::PartialPivLU<Matrix> lu_;
  mutable Vector solve_scratch_;  // Solve's P rhs (kept: no allocation per solve)
  double rcond_ = 0.0;
};

// ---- sparse LU (UMFPACK) -------------------------------------------------------------------
// Multifrontal LU with threshold partial pivoting inside the frontal matrices (COLAMD
// column ordering, unsymmetric strategy). On request (kSparseLu), and behind the automatic
// KLU's fill guard: its frontal pivoting weighs the fill, so saddle-point structures that
// make KLU pivot off the diagonal (multipliers of active constraints have zero diagonals)
// stay sparse (an earlier crowd of 10^3 agents: L + U of 3.6e6 entries and 3 s per
// factorization with KLU against 9.7e4 and 0.06 s with UMFPACK; docs/decisions.md).
class UmfpackSolver final : public LinearSolver {
 public:
  UmfpackSolver() {
    // Defaults (iterative refinement of every solve, up to 2 steps: the threshold pivoting
    // leaves residuals 10-100 times those of partial pivoting, which sensitivities would see).
    umfpack_di_defaults(control_);
  }
  ~UmfpackSolver() override { Release(); }
  UmfpackSolver(const UmfpackSolver&) = delete;
  UmfpackSolver& operator=(const UmfpackSolver&) = delete;

  LinearSolverKind kind() const override { return LinearSolverKind::kSparseLu; }

  FactorizationStatus Factorize(const SystemMatrix& a) override {
    MOREAU_ASSERT(a.sparse(), "UMFPACK needs sparse storage");
    ++num_factorizations_;
    matrix_ = a.sparse_matrix();
    const int n = static_cast<int>(matrix_.rows());
    for (int k = 0; k < matrix_.nonZeros(); ++k) {
      if (!std::isfinite(matrix_.valuePtr()[k])) return FactorizationStatus::kNonFinite;
    }
    n_ = n;
    if (n == 0) {
      rcond_ = 1.0;
      return FactorizationStatus::kSuccess;
    }
    const int* col = matrix_.outerIndexPtr();
    const int* row = matrix_.innerIndexPtr();
    const double* values = matrix_.valuePtr();
    const bool same_pattern = symbolic_ != nullptr &&
                              static_cast<std::size_t>(n) + 1 == col_pattern_.size() &&
                              std::equal(col, col + n + 1, col_pattern_.begin()) &&
                              static_cast<std::size_t>(col[n]) == row_pattern_.size() &&
                              std::equal(row, row + col[n], row_pattern_.begin());
    if (numeric_ != nullptr) umfpack_di_free_numeric(&numeric_);
    if (!same_pattern) {
      if (symbolic_ != nullptr) umfpack_di_free_symbolic(&symbolic_);
      col_pattern_.assign(col, col + n + 1);
      row_pattern_.assign(row, row + col[n]);
      if (umfpack_di_symbolic(n, n, col, row, values, &symbolic_, control_, info_) != UMFPACK_OK) {
        symbolic_ = nullptr;
        rcond_ = 0.0;
        return FactorizationStatus::kSingular;
      }
    }
    const int status = umfpack_di_numeric(col, row, values, symbolic_, &numeric_, control_, info_);
    rcond_ = info_[UMFPACK_RCOND];
    if (status != UMFPACK_OK || numeric_ == nullptr || !(rcond_ >= kSingularRcond)) {
      if (status != UMFPACK_OK) rcond_ = 0.0;
      return FactorizationStatus::kSingular;
    }
    return FactorizationStatus::kSuccess;
  }

  void Solve(VectorRef rhs) const override { SolveWith(UMFPACK_A, rhs); }
  void SolveTransposed(VectorRef rhs) const override { SolveWith(UMFPACK_At, rhs); }
  double reciprocal_condition() const override { return rcond_; }

 private:
  void SolveWith(int system, VectorRef rhs) const {
    if (n_ == 0) return;
    MOREAU_ASSERT(numeric_ != nullptr, "solve before factorization");
    solution_.resize(n_);
    umfpack_di_solve(system, matrix_.outerIndexPtr(), matrix_.innerIndexPtr(), matrix_.valuePtr(),
                     solution_.data(), rhs.data(), numeric_, control_, solve_info_);
    rhs = solution_;
  }
  void Release() {
    if (numeric_ != nullptr) umfpack_di_free_numeric(&numeric_);
    if (symbolic_ != nullptr) umfpack_di_free_symbolic(&symbolic_);
  }

  double control_[UMFPACK_CONTROL];
  double info_[UMFPACK_INFO];
  mutable double solve_info_[UMFPACK_INFO];
  void* symbolic_ = nullptr;
  void* numeric_ = nullptr;
  SparseMatrix matrix_;
  std::vector<int> col_pattern_, row_pattern_;
  mutable Vector solution_;
  int n_ = 0;
  double rcond_ = 0.0;
};

// ---- sparse LU (KLU) -----------------------------------------------------------------------
// Left-looking LU (Gilbert-Peierls) after a block triangular form and an AMD ordering of each
// diagonal block, partial pivoting that prefers the diagonal (threshold 0.001). No BLAS and
// no frontal matrices: on the very sparse systems of large scenes (one or two entries per
// column beside the diagonal) its factorizations cost less than UMFPACK's.
//
// The symbolic analysis is kept while the pattern holds. On request (kKlu) a factorization
// with the same pattern first reuses the previous pivot order (klu_refactor).
//
// Made by kAutomatic (`automatic`), it pivots afresh every time and watches the ordering. AMD
// orders for diagonal pivots, and a matrix that makes KLU pivot off the diagonal (the
// multipliers of active constraints have zero diagonal entries) can fill far beyond the
// ordering's estimate (the crowd of 10^3 agents' systems of an earlier formulation held
// 3.6e6 entries in L + U against UMFPACK's 9.7e4; docs/decisions.md).
// When a fresh factorization holds more than kMaxFillGrowth times the estimated entries, the
// solver hands this and every later factorization to UMFPACK, whose frontal pivoting weighs
// the fill. So it does, before factorizing, when the estimate itself exceeds kMaxEstimatedFill
// times the matrix's entries: KLU's kernel has no dense blocks to spend such fill in.
class KluSolver final : public LinearSolver {
 public:
  explicit KluSolver(bool automatic) : automatic_(automatic) { klu_defaults(&common_); }
  ~KluSolver() override { Release(); }
  KluSolver(const KluSolver&) = delete;
  KluSolver& operator=(const KluSolver&) = delete;

  LinearSolverKind kind() const override { return LinearSolverKind::kKlu; }

  FactorizationStatus Factorize(const SystemMatrix& a) override {
    MOREAU_ASSERT(a.sparse(), "KLU needs sparse storage");
    ++num_factorizations_;
    if (umfpack_ != nullptr) return umfpack_->Factorize(a);
    // KLU reads the matrix during klu_analyze, klu_factor and klu_refactor only (its factors
    // hold their own copies), so it reads the SystemMatrix's arrays in place; its API takes
    // non-const pointers but does not write through them.
    const SparseMatrix& matrix = a.sparse_matrix();
    MOREAU_ASSERT(matrix.isCompressed(), "KLU needs a compressed matrix");
    const int n = static_cast<int>(matrix.rows());
    for (int k = 0; k < matrix.nonZeros(); ++k) {
      if (!std::isfinite(matrix.valuePtr()[k])) return FactorizationStatus::kNonFinite;
    }
    int* col = const_cast<int*>(matrix.outerIndexPtr());
    int* row = const_cast<int*>(matrix.innerIndexPtr());
    double* values = const_cast<double*>(matrix.valuePtr());
    const bool same_pattern = symbolic_ != nullptr && n == n_ &&
                              std::equal(col, col + n + 1, col_pattern_.begin()) &&
                              static_cast<std::size_t>(col[n]) == row_pattern_.size() &&
                              std::equal(row, row + col[n], row_pattern_.begin());
    if (!same_pattern) {
      Release();
      n_ = n;
      col_pattern_.assign(col, col + n + 1);
      row_pattern_.assign(row, row + col[n]);
      symbolic_ = klu_analyze(n, col, row, &common_);
      if (symbolic_ == nullptr) return FactorizationStatus::kSingular;
      if (automatic_ && EstimatedEntries() > kMaxEstimatedFill * col[n]) {
        Release();
        umfpack_ = std::make_unique<UmfpackSolver>();
        return umfpack_->Factorize(a);
      }
    }
    // Numeric factorization. On request (LinearSolverKind::kKlu) the previous pivot order is
    // tried first (klu_refactor), kept while the condition estimate holds. kAutomatic pivots
    // afresh every time, as UMFPACK does: on the crowd of 10^3 agents reused pivots grew up to
    // 2e7 times more than fresh ones (klu_rgrowth), for 2% of the run's time.
    bool ok = false;
    if (numeric_ != nullptr && !automatic_) {
      ok = klu_refactor(col, row, values, symbolic_, numeric_, &common_) == 1;
      if (ok) {
        // A refactorization keeps the old pivot order, which may be poor for new values.
        ok = klu_rcond(symbolic_, numeric_, &common_) == 1 && common_.rcond >= kSingularRcond;
      }
    }
    if (!ok) {
      if (numeric_ != nullptr) klu_free_numeric(&numeric_, &common_);
      numeric_ = klu_factor(col, row, values, symbolic_, &common_);
      if (numeric_ == nullptr || common_.status == KLU_SINGULAR) {
        rcond_ = 0.0;
        return FactorizationStatus::kSingular;
      }
      // The fill guard: entries held in L, U and the off-diagonal blocks against the
      // ordering's estimate for diagonal pivots.
      const double held = static_cast<double>(numeric_->lnz) + numeric_->unz + numeric_->nzoff;
      if (automatic_ && held > kMaxFillGrowth * EstimatedEntries()) {
        Release();
        umfpack_ = std::make_unique<UmfpackSolver>();
        return umfpack_->Factorize(a);
      }
    }
    klu_rcond(symbolic_, numeric_, &common_);
    rcond_ = common_.rcond;
    if (!(rcond_ >= kSingularRcond)) return FactorizationStatus::kSingular;
    return FactorizationStatus::kSuccess;
  }

  void Solve(VectorRef rhs) const override {
    if (umfpack_ != nullptr) return umfpack_->Solve(rhs);
    MOREAU_ASSERT(numeric_ != nullptr, "solve before factorization");
    klu_solve(symbolic_, numeric_, n_, 1, rhs.data(), &common_);
  }
  void SolveMatrix(MatrixRef rhs) const override {
    if (umfpack_ != nullptr) return umfpack_->SolveMatrix(rhs);
    MOREAU_ASSERT(numeric_ != nullptr, "solve before factorization");
    if (rhs.outerStride() == rhs.rows()) {
      klu_solve(symbolic_, numeric_, n_, static_cast<int>(rhs.cols()), rhs.data(), &common_);
    } else {
      LinearSolver::SolveMatrix(rhs);
    }
  }
  void SolveTransposed(VectorRef rhs) const override {
    if (umfpack_ != nullptr) return umfpack_->SolveTransposed(rhs);
    MOREAU_ASSERT(numeric_ != nullptr, "solve before factorization");
    klu_tsolve(symbolic_, numeric_, n_, 1, rhs.data(), &common_);
  }
  double reciprocal_condition() const override {
    return umfpack_ != nullptr ? umfpack_->reciprocal_condition() : rcond_;
  }

 private:
  // kAutomatic's fill guard: entries of L + U over the ordering's estimate that mean the
  // pivoting left the ordering. The crowd of 10^3 agents stays at or below the estimate in
  // all 1043 factorizations of its run (0.78 to 1.0 of it); a 40 x 40 grid whose diagonal
  // entries are too small to pivot on holds 6.4 times it (the test), a 100 x 100 one 13 times.
  static constexpr double kMaxFillGrowth = 4.0;
  // kAutomatic's estimate rule: the ordering's estimate of L + U over the matrix's entries
  // beyond which UMFPACK factorizes instead. The crowds' element systems stay at about 1.1
  // (docs/benchmarks.md); a switch group of the crowd of 6000 agents with FESD s = 3 (n = 81384,
  // 1.16e6 entries) was estimated at 16 times its entries, and KLU spent about 98 s on each of
  // its factorizations: with UMFPACK the segment of that run around it (t in [4.15, 4.2]) took
  // 16 s of CPU instead of 167 s.
  static constexpr double kMaxEstimatedFill = 10.0;

  // Entries of L, U and the off-diagonal blocks that the ordering estimates (diagonal pivots).
  double EstimatedEntries() const {
    return symbolic_->lnz + symbolic_->unz + static_cast<double>(symbolic_->nzoff);
  }

  void Release() {
    if (numeric_ != nullptr) klu_free_numeric(&numeric_, &common_);
    if (symbolic_ != nullptr) klu_free_symbolic(&symbolic_, &common_);
    numeric_ = nullptr;
    symbolic_ = nullptr;
  }

  bool automatic_;
  mutable klu_common common_;
  klu_symbolic* symbolic_ = nullptr;
  klu_numeric* numeric_ = nullptr;
  std::unique_ptr<UmfpackSolver> umfpack_;  // kAutomatic after the fill guard fired
  std::vector<int> col_pattern_, row_pattern_;
  int n_ = 0;
  double rcond_ = 0.0;
};

}  // namespace

LinearSolverKind ResolveLinearSolverKind(LinearSolverKind kind, int n, double nonzeros) {
  if (kind != LinearSolverKind::kAutomatic) return kind;
  const double density = n == 0 ? 1.0 : nonzeros / (static_cast<double>(n) * n);
  return (n <= kDenseSizeLimit || density > kSparseDensityLimit) ? LinearSolverKind::kDenseLu
                                                                 : LinearSolverKind::kKlu;
}

std::unique_ptr<LinearSolver> MakeLinearSolver(LinearSolverKind kind, int n, double nonzeros) {
  RequireArgument(n >= 0, "linear system size must be non-negative, got ", n);
  const bool automatic = kind == LinearSolverKind::kAutomatic;
  kind = ResolveLinearSolverKind(kind, n, nonzeros);
  if (kind == LinearSolverKind::kSparseLu) return std::make_unique<UmfpackSolver>();
  if (kind == LinearSolverKind::kKlu) return std::make_unique<KluSolver>(automatic);
  return std::make_unique<DenseLuSolver>();
}

}  // namespace moreau
