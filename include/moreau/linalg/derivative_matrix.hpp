#pragma once
/// @file
/// DerivativeMatrix: one derivative block of a lowered system's evaluation (F_y, A_z, ...),
/// stored dense for small systems and sparse (compressed columns) for large ones.
///
/// The lowered effects add their contributions block by block; the integrators read the
/// finished matrix. In sparse storage every added entry is structural, including exact zeros
/// of a dense block, so that the pattern depends on the structure of the model and not on the
/// values at the point: a sparse factorization of a matrix assembled from these blocks can
/// reuse its symbolic analysis from one evaluation to the next (docs/sparse-systems.md).
///
/// Sparse storage accumulates (row, column, value) entries and sums duplicates in Finalize(),
/// which the producer calls once all contributions are in. Capacity is kept across
/// SetZero calls, so a steady sequence of evaluations does not allocate.

#include <optional>
#include <vector>

#include "moreau/core/types.hpp"

namespace moreau {

namespace internal {
/// How the last sparse Finalize of a DerivativeMatrix or SystemMatrix placed its entries (an
/// implementation detail kept beside the compressed matrix): a Finalize whose entries come
/// at the same (row, column) positions in the same order, as in every Newton iteration and
/// step between pattern changes, writes the values through it in one pass instead of sorting
/// the entries again. Entry i's value goes to the compressed matrix's value slot slots[i] if
/// slots[i] >= 0 (the first entry at its position: assigned) and is added to slot ~slots[i]
/// otherwise (a later duplicate: summed in entry order, as the sort does). An entry's
/// position is checked against its slot's row and column in the compressed matrix itself.
struct CompressionPlan {
  std::vector<int> slots;     ///< value slot of each entry, as above
  int rows = -1;              ///< the compressed matrix's rows, -1: no plan
  int cols = -1;              ///< its columns
  Eigen::Index nonzeros = 0;  ///< its stored entries
};
}  // namespace internal

/// A derivative block (rows x cols) stored dense or sparse, filled by accumulation and then read:
/// the storage of every Jacobian block of a lowered system (docs/sparse-systems.md).
class DerivativeMatrix {
 public:
  /// A rows x cols matrix of zeros in the given storage (true: sparse).
  void SetZero(int rows, int cols, bool sparse);
  /// SetZero's shape and storage without zeroing the dense entries (their values are then
  /// unspecified): for blocks that will be written but not read (LoweredSystem::EvaluateField's
  /// G, A, B derivatives). Sparse storage starts empty, as after SetZero.
  void SetShape(int rows, int cols, bool sparse) {
    if (sparse || dense_.rows() != rows || dense_.cols() != cols) {
      SetZero(rows, cols, sparse);
      return;
    }
    rows_ = rows;
    cols_ = cols;
    sparse_ = false;
    finalized_ = true;
  }
  /// Number of rows.
  int rows() const { return rows_; }
  /// Number of columns.
  int cols() const { return cols_; }
  /// True for sparse storage.
  bool is_sparse() const { return sparse_; }

  // --- accumulation ------------------------------------------------------------------------
  /// M(row, col) += value.
  void Add(int row, int col, double value) {
    CheckEntry(row, col);
    if (sparse_) {
      entries_.push_back({row, col, value});
    } else {
      dense_(row, col) += value;
    }
  }
  /// M(row0 + i, col0 + j) += scale * block(i, j) for every entry of the block.
  void AddBlock(int row0, int col0, const ConstMatrixRef& block, double scale = 1.0);
  /// M(row0 + i, col0 + j) += scale * block(i, j) for the stored entries of a sparse block
  /// (transposed: M(row0 + j, col0 + i) += scale * block(i, j)).
  void AddSparse(int row0, int col0, const SparseMatrix& block, double scale = 1.0,
                 bool transposed = false);
  /// M(row0 + i, col0 + j) += scale * column(i) * row(j) for the nonzero entries of `row`
  /// (every entry of `column`): a rank-one term whose row factor is sparse in practice.
  void AddOuter(int row0, int col0, const ConstVectorRef& column, const ConstVectorRef& row,
                double scale = 1.0);
  /// M = m (storage per is_sparse(), sizes from m; finished, no Finalize needed).
  void Assign(const Matrix& m);
  /// M = m for a sparse m (storage per is_sparse()).
  void Assign(const SparseMatrix& m);
  /// M *= factor (all entries added so far).
  void Scale(double factor);
  /// Completes the accumulation (sparse: builds the compressed matrix, summing duplicates).
  void Finalize();

  // --- reading (after Finalize) ------------------------------------------------------------
  const Matrix& dense() const;  ///< dense storage only
  /// Dense storage only: the matrix to write in place (sizes from SetZero; writing keeps it
  /// finished). For producers that compute whole rows at once (velocity level).
  Matrix& MutableDense();
  const SparseMatrix& sparse() const;  ///< sparse storage only
  /// A dense copy (either storage).
  Matrix ToDense() const;
  /// f(m) with m the dense Matrix or the SparseMatrix: code written once for both storages.
  template <class F>
  decltype(auto) Visit(F&& f) const {
    return sparse_ ? f(StoredSparse()) : f(dense_);
  }
  /// y += scale * M x.
  void MultiplyAdd(const ConstVectorRef& x, VectorRef y, double scale = 1.0) const;
  /// y += scale * M^T x.
  void TransposedMultiplyAdd(const ConstVectorRef& x, VectorRef y, double scale = 1.0) const;
  /// Row `row` as a dense row vector (O(cols) dense, O(nonzeros) sparse).
  Eigen::RowVectorXd Row(int row) const;
  /// The same into *out (its storage reused: no allocation once sized).
  void Row(int row, Eigen::RowVectorXd* out) const;
  /// Structurally stored entries (dense: rows x cols).
  double NonZeros() const;

  /// One (row, column, value) entry; Eigen's setFromTriplets reads it.
  struct Entry {
    int r;  ///< row index
    int c;  ///< column index
    /// The value.
    double v;
    /// Row index (for Eigen's setFromTriplets).
    int row() const { return r; }
    /// Column index.
    int col() const { return c; }
    /// The value.
    double value() const { return v; }
  };

 private:
  void CheckEntry(int row, int col) const;  // aborts unless 0 <= row < rows, 0 <= col < cols
  // The compressed matrix, or an empty one before the first sparse Finalize or Assign.
  const SparseMatrix& StoredSparse() const;
  int rows_ = 0, cols_ = 0;
  bool sparse_ = false;
  bool finalized_ = true;
  Matrix dense_;
  std::vector<Entry> entries_;
  // Created on first sparse use: Eigen's SparseMatrix allocates even when empty, and
  // evaluations hold dozens of dense derivative matrices (PointEvaluation,
  // VelocityLevelEvaluation), each constructed per run.
  std::optional<SparseMatrix> sparse_matrix_;
  internal::CompressionPlan plan_;  // how Finalize last filled *sparse_matrix_
};

}  // namespace moreau
