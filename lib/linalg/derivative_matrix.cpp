#include "moreau/linalg/derivative_matrix.hpp"

#include "compress_entries.hpp"
#include "dense_columns.hpp"
#include "moreau/core/error.hpp"

namespace moreau {

void DerivativeMatrix::SetZero(int rows, int cols, bool sparse) {
  rows_ = rows;
  cols_ = cols;
  sparse_ = sparse;
  if (sparse_) {
    entries_.clear();
    finalized_ = false;
    if (dense_.size() != 0) dense_.resize(0, 0);
  } else {
    dense_.setZero(rows, cols);
    finalized_ = true;
  }
}

void DerivativeMatrix::CheckEntry(int row, int col) const {
  MOREAU_ASSERT(row >= 0 && row < rows_ && col >= 0 && col < cols_,
                "entry outside the derivative matrix");
}

void DerivativeMatrix::AddBlock(int row0, int col0, const ConstMatrixRef& block, double scale) {
  MOREAU_ASSERT(
      row0 >= 0 && col0 >= 0 && row0 + block.rows() <= rows_ && col0 + block.cols() <= cols_,
      "block outside the derivative matrix");
  if (!sparse_) {
    internal::AddScaledColumns(dense_.data() + col0 * dense_.rows() + row0, dense_.rows(),
                               block.data(), block.outerStride(), block.rows(), block.cols(),
                               scale);
    return;
  }
  for (Eigen::Index j = 0; j < block.cols(); ++j) {
    for (Eigen::Index i = 0; i < block.rows(); ++i) {
      entries_.push_back(
          {row0 + static_cast<int>(i), col0 + static_cast<int>(j), scale * block(i, j)});
    }
  }
}

void DerivativeMatrix::AddSparse(int row0, int col0, const SparseMatrix& block, double scale,
                                 bool transposed) {
  const Eigen::Index block_rows = transposed ? block.cols() : block.rows();
  const Eigen::Index block_cols = transposed ? block.rows() : block.cols();
  MOREAU_ASSERT(row0 >= 0 && col0 >= 0 && row0 + block_rows <= rows_ && col0 + block_cols <= cols_,
                "sparse block outside the derivative matrix");
  for (int j = 0; j < block.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(block, j); it; ++it) {
      const int r = row0 + static_cast<int>(transposed ? it.col() : it.row());
      const int c = col0 + static_cast<int>(transposed ? it.row() : it.col());
      if (sparse_) {
        entries_.push_back({r, c, scale * it.value()});
      } else {
        dense_(r, c) += scale * it.value();
      }
    }
  }
}

void DerivativeMatrix::AddOuter(int row0, int col0, const ConstVectorRef& column,
                                const ConstVectorRef& row, double scale) {
  MOREAU_ASSERT(
      row0 >= 0 && col0 >= 0 && row0 + column.size() <= rows_ && col0 + row.size() <= cols_,
      "outer product outside the derivative matrix");
  for (Eigen::Index j = 0; j < row.size(); ++j) {
    if (row[j] == 0.0) continue;
    const double factor = scale * row[j];
    if (!sparse_) {
      dense_.col(col0 + j).segment(row0, column.size()) += factor * column;
      continue;
    }
    for (Eigen::Index i = 0; i < column.size(); ++i) {
      entries_.push_back(
          {row0 + static_cast<int>(i), col0 + static_cast<int>(j), factor * column[i]});
    }
  }
}

void DerivativeMatrix::Assign(const Matrix& m) {
  if (sparse_) {
    // Every entry is structural, as with AddBlock.
    SetZero(static_cast<int>(m.rows()), static_cast<int>(m.cols()), true);
    AddBlock(0, 0, m);
    Finalize();
    return;
  }
  rows_ = static_cast<int>(m.rows());
  cols_ = static_cast<int>(m.cols());
  dense_ = m;
  finalized_ = true;
}

void DerivativeMatrix::Assign(const SparseMatrix& m) {
  rows_ = static_cast<int>(m.rows());
  cols_ = static_cast<int>(m.cols());
  if (sparse_) {
    sparse_matrix_ = m;
    sparse_matrix_->makeCompressed();
    entries_.clear();
    plan_.rows = -1;  // the stored pattern is no longer the plan's
  } else {
    dense_ = Matrix(m);
  }
  finalized_ = true;
}

void DerivativeMatrix::Scale(double factor) {
  if (!sparse_) {
    dense_ *= factor;
    return;
  }
  MOREAU_ASSERT(!finalized_, "Scale after Finalize");
  for (Entry& entry : entries_) entry.v *= factor;
}

void DerivativeMatrix::Finalize() {
  if (!sparse_ || finalized_) return;
  if (!sparse_matrix_) sparse_matrix_.emplace();
  internal::CompressEntries(entries_, rows_, cols_, &*sparse_matrix_, &plan_);
  finalized_ = true;
}

const Matrix& DerivativeMatrix::dense() const {
  MOREAU_ASSERT(!sparse_, "dense() of a sparse derivative matrix");
  return dense_;
}

Matrix& DerivativeMatrix::MutableDense() {
  MOREAU_ASSERT(!sparse_, "MutableDense() of a sparse derivative matrix");
  return dense_;
}

const SparseMatrix& DerivativeMatrix::sparse() const {
  MOREAU_ASSERT(sparse_ && finalized_, "sparse() of a dense or unfinished derivative matrix");
  return StoredSparse();
}

const SparseMatrix& DerivativeMatrix::StoredSparse() const {
  static const SparseMatrix kEmpty;
  return sparse_matrix_ ? *sparse_matrix_ : kEmpty;
}

Matrix DerivativeMatrix::ToDense() const {
  if (!sparse_) return dense_;
  MOREAU_ASSERT(finalized_, "ToDense of an unfinished derivative matrix");
  return Matrix(StoredSparse());
}

void DerivativeMatrix::MultiplyAdd(const ConstVectorRef& x, VectorRef y, double scale) const {
  MOREAU_ASSERT(x.size() == cols_ && y.size() == rows_, "MultiplyAdd: wrong sizes");
  if (sparse_) {
    y.noalias() += scale * (sparse() * x);
  } else {
    y.noalias() += scale * (dense_ * x);
  }
}

void DerivativeMatrix::TransposedMultiplyAdd(const ConstVectorRef& x, VectorRef y,
                                             double scale) const {
  MOREAU_ASSERT(x.size() == rows_ && y.size() == cols_, "TransposedMultiplyAdd: wrong sizes");
  if (sparse_) {
    y.noalias() += scale * (sparse().transpose() * x);
  } else {
    y.noalias() += scale * (dense_.transpose() * x);
  }
}

Eigen::RowVectorXd DerivativeMatrix::Row(int row) const {
  Eigen::RowVectorXd out;
  Row(row, &out);
  return out;
}

void DerivativeMatrix::Row(int row, Eigen::RowVectorXd* out) const {
  MOREAU_ASSERT(row >= 0 && row < rows_, "Row: index outside the matrix");
  if (!sparse_) {
    *out = dense_.row(row);
    return;
  }
  out->setZero(cols_);
  const SparseMatrix& m = sparse();
  for (int j = 0; j < m.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(m, j); it; ++it) {
      if (it.row() == row) (*out)[j] += it.value();
    }
  }
}

double DerivativeMatrix::NonZeros() const {
  if (!sparse_) return static_cast<double>(rows_) * cols_;
  return finalized_ ? static_cast<double>(StoredSparse().nonZeros())
                    : static_cast<double>(entries_.size());
}

}  // namespace moreau
