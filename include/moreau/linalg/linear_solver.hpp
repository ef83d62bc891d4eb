#pragma once
/// @file
/// Linear solvers for the Newton systems of every integrator.
///
/// Integrators assemble their (generalized) Jacobians block by block into a
/// SystemMatrix, which stores them dense or sparse (CSC) depending on the solver chosen by
/// MakeLinearSolver: a dense LU with partial pivoting (Eigen) for small or dense systems, a
/// sparse LU (SuiteSparse KLU, handing over to UMFPACK where its pivoting fills in) for large
/// sparse ones. All report singular matrices through their return value (never by
/// exception), so that integrators can turn them into statuses.

#include <memory>
#include <string>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/linalg/derivative_matrix.hpp"

namespace moreau {

/// Which factorization backs a LinearSolver.
enum class LinearSolverKind {
  /// Dense LU if n <= kDenseSizeLimit or the matrix is dense (more than kSparseDensityLimit
  /// of its entries), else KLU with a fill guard: KLU pivots afresh at every factorization,
  /// and once a factorization holds more than 4 times the entries its ordering estimated
  /// (off-diagonal pivots, as zero diagonals of multipliers may force) this and every later
  /// factorization of the solver go to UMFPACK.
  kAutomatic,
  kDenseLu,  ///< Eigen PartialPivLU on a dense matrix
  /// SuiteSparse UMFPACK on a CSC matrix (multifrontal, threshold pivoting; symbolic analysis
  /// reused while the pattern holds): robust on saddle-point structures
  kSparseLu,
  /// SuiteSparse KLU (left-looking, BTF + AMD; symbolic analysis reused, and the previous
  /// pivot order while the condition estimate holds): the fastest on very sparse systems
  /// whose diagonal pivots are sound; no fill guard on request (kAutomatic has one)
  kKlu,
};
/// "auto", "dense", "sparse" or "klu".
std::string ToString(LinearSolverKind kind);
/// Parses "auto", "dense", "sparse" or "klu"; throws std::invalid_argument otherwise.
LinearSolverKind ParseLinearSolverKind(const std::string& name);

/// Systems up to this size always use the dense LU under kAutomatic.
inline constexpr int kDenseSizeLimit = 256;
/// Above kDenseSizeLimit, kAutomatic picks the sparse LU if at most this fraction of the
/// entries is structurally nonzero.
inline constexpr double kSparseDensityLimit = 0.1;

/// A square matrix assembled from blocks, stored dense or sparse.
class SystemMatrix {
 public:
  /// Starts a new n-by-n matrix of zeros in the given storage (true: sparse).
  void Reset(int n, bool sparse);
  /// The dimension n.
  int size() const { return n_; }
  /// True for sparse storage.
  bool sparse() const { return sparse_; }
  /// A(row0 + i, col0 + j) += scale * block(i, j), for all entries of the block (exact zeros
  /// included in sparse storage, so that the sparsity pattern does not depend on values).
  void AddBlock(int row0, int col0, const ConstMatrixRef& block, double scale = 1.0);
  /// A(row0 + i, col0 + j) += scale * block(i, j) for the stored entries of a sparse block.
  void AddSparseBlock(int row0, int col0, const SparseMatrix& block, double scale = 1.0);
  /// A(row0 + i, col0 + j) += scale * M(i, j) for the stored entries of a derivative matrix
  /// (every entry of a dense one).
  void AddDerivative(int row0, int col0, const DerivativeMatrix& m, double scale = 1.0);
  /// A(row0 + i, col0 + j) += row_weights(i) * M(i, j) (rows weighted, e.g. by NCP derivatives;
  /// with sparse storage rows of weight zero add no entries).
  void AddWeightedRows(int row0, int col0, const ConstVectorRef& row_weights,
                       const DerivativeMatrix& m);
  /// A(row, col0 + j) += weight * M(k, j): one row of M into one row of A. With sparse
  /// storage every stored entry of row k enters (weight zero included), so that the pattern
  /// depends on k only; rows of M other than k add nothing (a combination of all rows would
  /// make a dense row, which sparse LU's threshold pivoting can turn into dense fronts).
  void AddScaledRow(int row, int col0, int k, double weight, const DerivativeMatrix& m);
  /// A(row0 + i, col0 + i) += value, i = 0..count-1.
  void AddDiagonal(int row0, int col0, int count, double value);
  /// A(row, col) += value.
  void AddEntry(int row, int col, double value);
  /// Completes the assembly (sparse: builds the CSC matrix, summing duplicates).
  void Finalize();

  /// The dense matrix (dense storage, after Finalize).
  const Matrix& dense() const { return dense_; }
  /// The compressed sparse matrix (sparse storage, after Finalize).
  const SparseMatrix& sparse_matrix() const { return sparse_matrix_; }
  /// y = A x (after Finalize).
  Vector Multiply(const Vector& x) const;
  /// y = A^T x (after Finalize).
  Vector MultiplyTransposed(const Vector& x) const;
  /// *y = A^T x without allocating (y sized by the caller or resized).
  void MultiplyTransposed(const Vector& x, Vector* y) const;
  /// max_i sum_j |A_ij| (after Finalize).
  double InfinityNorm() const;

 private:
  // Dense storage: A(row0 + i, col0 + j) += scale * data[i + j stride], i < rows, j < cols.
  void AddDenseColumns(int row0, int col0, const double* data, Eigen::Index rows, Eigen::Index cols,
                       Eigen::Index stride, double scale);

  int n_ = 0;
  bool sparse_ = false;
  Matrix dense_;
  std::vector<Eigen::Triplet<double, int>> triplets_;
  SparseMatrix sparse_matrix_;
  internal::CompressionPlan plan_;  // how Finalize last filled sparse_matrix_
};

/// Result of a factorization.
enum class FactorizationStatus {
  kSuccess,    ///< factors computed and reciprocal_condition() >= kSingularRcond
  kSingular,   ///< a zero pivot or reciprocal_condition() < kSingularRcond
  kNonFinite,  ///< the matrix contains NaN or infinity
};
/// The status as text.
std::string ToString(FactorizationStatus status);

/// Matrices whose conditioning indicator (reciprocal_condition) is below this value count as
/// singular: a solve would lose all digits (1 / eps).
inline constexpr double kSingularRcond = 1e-15;

/// Factorizes a SystemMatrix and solves with it.
class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  /// Which LU this is (never kAutomatic).
  virtual LinearSolverKind kind() const = 0;
  /// True if this solver wants sparse storage in SystemMatrix.
  bool wants_sparse() const {
    return kind() == LinearSolverKind::kSparseLu || kind() == LinearSolverKind::kKlu;
  }
  /// Factorizes A (whose storage must match wants_sparse()).
  virtual FactorizationStatus Factorize(const SystemMatrix& a) = 0;
  /// Overwrites rhs with A^{-1} rhs (after a successful Factorize).
  virtual void Solve(VectorRef rhs) const = 0;
  /// Solves for several right-hand sides (columns).
  virtual void SolveMatrix(MatrixRef rhs) const;
  /// Overwrites rhs with A^{-T} rhs (after a successful Factorize).
  virtual void SolveTransposed(VectorRef rhs) const = 0;
  /// Conditioning indicator of the last factorization: dense LU, min |u_ii| / max |u_ii| of
  /// its pivots; KLU, its 1-norm reciprocal condition estimate (klu_rcond).
  virtual double reciprocal_condition() const = 0;
  /// Number of factorizations so far.
  int num_factorizations() const { return num_factorizations_; }

 protected:
  /// Counter behind num_factorizations(), incremented by Factorize.
  int num_factorizations_ = 0;
};

/// The kind MakeLinearSolver makes for these arguments: `kind` itself unless kAutomatic,
/// which resolves as documented in LinearSolverKind.
LinearSolverKind ResolveLinearSolverKind(LinearSolverKind kind, int n, double nonzeros);
/// Creates a solver for n-by-n systems with about `nonzeros` structural nonzeros
/// (pass n * n if unknown). kAutomatic resolves as documented in LinearSolverKind.
std::unique_ptr<LinearSolver> MakeLinearSolver(LinearSolverKind kind, int n, double nonzeros);

}  // namespace moreau
