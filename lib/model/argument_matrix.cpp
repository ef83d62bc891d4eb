// ArgumentMatrix (lowered_block.hpp): model-function derivatives with columns x, [u], t, [p],
// dense (forward-mode AD over all inputs) or sparse (sparsity detection, colouring and
// compressed AD: docs/sparse-derivatives.md), scattered into the lowered system's blocks.

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

#include "lowered_block.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {
// *rows = columns (compressed rows, columns increasing in each row) in the storage *rows
// already has: Eigen's assignment across storage orders builds a new matrix per call.
// (*source)[k] is the position in columns of entry k of *rows, and *outer_kept, *inner_kept
// keep columns' pattern: a call with the same pattern only gathers the values, the same
// assignments as the full copy.
void CopyToRows(const SparseMatrix& columns,
                Eigen::SparseMatrix<double, Eigen::RowMajor, int>* rows,
                std::vector<int>* outer_kept, std::vector<int>* inner_kept,
                std::vector<int>* source) {
  const auto n = static_cast<int>(columns.rows());
  const auto nnz = static_cast<std::size_t>(columns.nonZeros());
  const auto outer_size = static_cast<std::size_t>(columns.outerSize()) + 1;
  const int* col_outer = columns.outerIndexPtr();
  const int* col_inner = columns.innerIndexPtr();
  const double* col_values = columns.valuePtr();
  if (columns.isCompressed() && rows->rows() == n && rows->cols() == columns.cols() &&
      static_cast<std::size_t>(rows->nonZeros()) == nnz && source->size() == nnz &&
      outer_kept->size() == outer_size && inner_kept->size() == nnz &&
      std::equal(col_outer, col_outer + outer_size, outer_kept->begin()) &&
      std::equal(col_inner, col_inner + nnz, inner_kept->begin())) {
    double* values = rows->valuePtr();
    const int* from = source->data();
    for (std::size_t k = 0; k < nnz; ++k) values[k] = col_values[from[k]];
    return;
  }
  rows->resize(n, columns.cols());  // outer indices zero, no entries (their storage kept)
  // outer[r + 1] becomes the start of row r (the count of row r goes to outer[r + 2]); filling
  // advances it to the start of row r + 1.
  int* outer = rows->outerIndexPtr();
  for (Eigen::Index j = 0; j < columns.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(columns, j); it; ++it) {
      if (it.row() + 1 < n) ++outer[it.row() + 2];
    }
  }
  for (int r = 2; r <= n; ++r) outer[r] += outer[r - 1];
  rows->resizeNonZeros(columns.nonZeros());
  int* inner = rows->innerIndexPtr();
  double* values = rows->valuePtr();
  source->resize(nnz);
  for (Eigen::Index j = 0; j < columns.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(columns, j); it; ++it) {
      const int position = outer[it.row() + 1]++;
      inner[position] = static_cast<int>(j);
      values[position] = it.value();
      (*source)[static_cast<std::size_t>(position)] = static_cast<int>(&it.value() - col_values);
    }
  }
  if (columns.isCompressed()) {
    outer_kept->assign(col_outer, col_outer + outer_size);
    inner_kept->assign(col_inner, col_inner + nnz);
  } else {
    outer_kept->clear();  // never replayed: an uncompressed matrix has gaps
    inner_kept->clear();
  }
}
}  // namespace

bool FunctionBounds(const BlockContext& context, const SmoothFunction& function,
                    const ConstVectorRef& y_lower, const ConstVectorRef& y_upper, Vector* lower,
                    Vector* upper, const std::vector<int>* rows) {
  const int nx = context.num_scene_states;
  // The system's threads, as for the function's sparse derivatives (Jacobian below).
  if (function.typed() != nullptr) function.typed()->set_thread_pool(context.pool);
  return function.Bounds(y_lower.head(nx), y_upper.head(nx), *context.inputs,
                         y_lower[context.clock_index], y_upper[context.clock_index],
                         *context.parameters, lower, upper, rows);
}

void ArgumentMatrix::Layout(const BlockContext& context, Derivatives derivatives) {
  is_sparse_ = context.sparse;
  all_ = derivatives == Derivatives::kAll;
  nx_ = context.num_scene_states;
  nu_ = static_cast<int>(context.inputs->size());
  np_ = static_cast<int>(context.parameters->size());
  clock_ = context.clock_index;
}

int ArgumentMatrix::Target(int j, int* index) const {
  if (j < nx_) {
    *index = j;
    return 0;
  }
  if (!all_) {
    *index = clock_;  // Wrt::XT: x, then t
    return 0;
  }
  if (j < nx_ + nu_) {
    *index = j - nx_;
    return 1;
  }
  if (j == nx_ + nu_) {
    *index = clock_;
    return 0;
  }
  *index = j - nx_ - nu_ - 1;
  return 2;
}

void ArgumentMatrix::Jacobian(const BlockContext& context, const SmoothFunction& function,
                              const ConstVectorRef& y, Derivatives derivatives, Vector* values,
                              const std::vector<int>* rows) {
  Layout(context, derivatives);
  x_ = y.head(nx_);
  const double t = y[clock_];
  rows_ = function.num_outputs();
  if (derivatives == Derivatives::kNone) {
    function.Evaluate(x_, *context.inputs, t, *context.parameters, values);
    return;
  }
  const Wrt wrt = all_ ? Wrt::All() : Wrt::XT();
  if (is_sparse_) {
    if (function.typed() != nullptr) function.typed()->set_thread_pool(context.pool);
    // Only the rows in `rows` are differentiated (the near-active filter's working set).
    function.SparseJacobian(x_, *context.inputs, t, *context.parameters, wrt, values, &columns_,
                            rows);
    CopyToRows(columns_, &rows_sparse_, &copied_outer_, &copied_inner_, &row_entry_source_);
  } else {
    function.Jacobian(x_, *context.inputs, t, *context.parameters, wrt, values, &dense_);
  }
}

double ArgumentMatrix::StateRowNorm1(int k) const {
  if (!is_sparse_) return dense_.row(k).head(nx_).lpNorm<1>();
  double sum = 0.0;
  for (decltype(rows_sparse_)::InnerIterator it(rows_sparse_, k); it; ++it) {
    if (it.col() < nx_) sum += std::fabs(it.value());
  }
  return sum;
}

double ArgumentMatrix::TimeEntry(int k) const {
  const int t_col = all_ ? nx_ + nu_ : nx_;
  if (!is_sparse_) return dense_(k, t_col);
  return rows_sparse_.coeff(k, t_col);
}

void ArgumentMatrix::HessianDirections(const BlockContext& context, const SmoothFunction& function,
                                       const ConstVectorRef& y, const ConstVectorRef& direction,
                                       Derivatives derivatives, const std::vector<int>* outputs) {
  Layout(context, derivatives);
  x_ = y.head(nx_);
  const double t = y[clock_];
  rows_ = function.num_outputs();
  const Wrt wrt = all_ ? Wrt::All() : Wrt::XT();
  // The direction in the function's columns: x and clock components only.
  direction_.setZero(wrt.Columns(nx_, nu_, np_));
  direction_.head(nx_) = direction.head(nx_);
  direction_[all_ ? nx_ + nu_ : nx_] = direction[clock_];
  TypedFunction* typed = function.typed();
  if (!is_sparse_ && typed != nullptr && direction_.size() <= Dual1::kCapacity) {
    // Few columns: one dense Dual2 pass, without the sparse path's per-function set-up
    // (sparsity detection, colouring, plans: F1's one switch spent more on it than on the
    // group solve). Rows outside `outputs` are zero, as in the sparse path.
    typed->DenseHessianDirection(x_, *context.inputs, t, *context.parameters, wrt, direction_,
                                 &dense_);
    if (outputs != nullptr) {
      std::size_t next = 0;
      for (int k = 0; k < rows_; ++k) {
        if (next < outputs->size() && (*outputs)[next] == k) {
          ++next;
        } else {
          dense_.row(k).setZero();
        }
      }
    }
    return;
  }
  // Second derivatives along one direction by compressed Dual2 passes (one per 16 colours of
  // the outputs' Hessian supports) in both storages: a dense Hessian per output would cost
  // m times (inputs / 16)^2 passes.
  function.SparseHessianDirection(x_, *context.inputs, t, *context.parameters, wrt, direction_,
                                  &columns_, outputs);
  if (is_sparse_) {
    CopyToRows(columns_, &rows_sparse_, &copied_outer_, &copied_inner_, &row_entry_source_);
  } else {
    dense_ = Matrix(columns_);
  }
}

void ArgumentMatrix::WeightedHessian(const BlockContext& context, const SmoothFunction& function,
                                     const ConstVectorRef& y, const ConstVectorRef& weights,
                                     Derivatives derivatives, const std::vector<int>* rows) {
  Layout(context, derivatives);
  x_ = y.head(nx_);
  const double t = y[clock_];
  const Wrt wrt = all_ ? Wrt::All() : Wrt::XT();
  rows_ = wrt.Columns(nx_, nu_, np_);
  if (is_sparse_) {
    // The pattern is that of the outputs in `rows` (the working set), whatever the weights.
    function.SparseWeightedHessian(x_, *context.inputs, t, *context.parameters, wrt, weights,
                                   &columns_, rows);
    CopyToRows(columns_, &rows_sparse_, &copied_outer_, &copied_inner_, &row_entry_source_);
  } else {
    function.WeightedHessian(x_, *context.inputs, t, *context.parameters, wrt, weights, &dense_);
  }
}

void ArgumentMatrix::AddRow(int k, double weight, int row, DerivativeMatrix* dy,
                            DerivativeMatrix* du, DerivativeMatrix* dp) const {
  DerivativeMatrix* targets[3] = {dy, du, dp};
  int index = 0;
  if (is_sparse_ && !all_) {
    // Columns x, then the clock (Wrt::XT): all into dy, in the order of the general loop below.
    const int* inner = rows_sparse_.innerIndexPtr();
    const double* values = rows_sparse_.valuePtr();
    const int end = rows_sparse_.outerIndexPtr()[k + 1];
    for (int e = rows_sparse_.outerIndexPtr()[k]; e < end; ++e) {
      dy->Add(row, inner[e] < nx_ ? inner[e] : clock_, weight * values[e]);
    }
    return;
  }
  if (is_sparse_) {
    for (decltype(rows_sparse_)::InnerIterator it(rows_sparse_, k); it; ++it) {
      const int target = Target(static_cast<int>(it.col()), &index);
      if (target == 0 || all_) targets[target]->Add(row, index, weight * it.value());
    }
    return;
  }
  for (Eigen::Index j = 0; j < dense_.cols(); ++j) {
    const int target = Target(static_cast<int>(j), &index);
    if (target == 0 || all_) targets[target]->Add(row, index, weight * dense_(k, j));
  }
}

void ArgumentMatrix::AddRows(int first, int count, double weight, int row0, DerivativeMatrix* dy,
                             DerivativeMatrix* du, DerivativeMatrix* dp) const {
  if (!is_sparse_ && !dy->is_sparse()) {
    // Dense fast path: whole column blocks.
    const auto block = dense_.middleRows(first, count);
    dy->AddBlock(row0, 0, block.leftCols(nx_), weight);
    dy->AddBlock(row0, clock_, block.col(all_ ? nx_ + nu_ : nx_), weight);
    if (!all_) return;
    du->AddBlock(row0, 0, block.middleCols(nx_, nu_), weight);
    dp->AddBlock(row0, 0, block.rightCols(np_), weight);
    return;
  }
  for (int k = 0; k < count; ++k) AddRow(first + k, weight, row0 + k, dy, du, dp);
}

void ArgumentMatrix::AddStateGradientProduct(const ConstVectorRef& weights,
                                             const Matrix* projection, VectorRef target,
                                             const std::vector<int>* rows) const {
  gradient_.setZero(nx_);
  if (is_sparse_) {
    // In increasing row order, as over all rows: the same sums.
    const auto add_row = [&](int k) {
      if (weights[k] == 0.0) return;
      for (decltype(rows_sparse_)::InnerIterator it(rows_sparse_, k); it; ++it) {
        if (it.col() < nx_) gradient_[it.col()] += it.value() * weights[k];
      }
    };
    if (rows != nullptr) {
      for (int k : *rows) add_row(k);
    } else {
      for (int k = 0; k < rows_; ++k) add_row(k);
    }
  } else {
    gradient_.noalias() = dense_.leftCols(nx_).transpose() * weights;
  }
  if (projection == nullptr) {
    target += gradient_;
  } else {
    target.noalias() += *projection * gradient_;
  }
}

void ArgumentMatrix::AddStateGradient(int k, int col, const Matrix* projection,
                                      DerivativeMatrix* target) const {
  if (projection == nullptr) {
    if (is_sparse_) {
      for (decltype(rows_sparse_)::InnerIterator it(rows_sparse_, k); it; ++it) {
        if (it.col() < nx_) target->Add(static_cast<int>(it.col()), col, it.value());
      }
    } else {
      // Entry by entry: a row of the column-major Jacobian is strided, which a block reference
      // would copy (an allocation per call).
      for (int i = 0; i < nx_; ++i) target->Add(i, col, dense_(k, i));
    }
    return;
  }
  Vector& row = gradient_row_;
  if (is_sparse_) {
    row.setZero(nx_);
    for (decltype(rows_sparse_)::InnerIterator it(rows_sparse_, k); it; ++it) {
      if (it.col() < nx_) row[it.col()] = it.value();
    }
  } else {
    row = dense_.row(k).head(nx_).transpose();
  }
  projected_row_.noalias() = *projection * row;
  target->AddBlock(0, col, projected_row_);
}

void ArgumentMatrix::AddStateGradients(int col0, const Matrix* projection, double weight,
                                       DerivativeMatrix* target) const {
  if (is_sparse_ && projection == nullptr) {
    // target(i, col0 + k) += weight * dg_k/dx_i: the x columns of the Jacobian, transposed.
    for (int k = 0; k < rows_; ++k) {
      for (decltype(rows_sparse_)::InnerIterator it(rows_sparse_, k); it; ++it) {
        if (it.col() < nx_) target->Add(static_cast<int>(it.col()), col0 + k, weight * it.value());
      }
    }
    return;
  }
  if (!is_sparse_ && projection == nullptr) {
    // The same, dense: entry by entry (no transposed temporaries on every evaluation).
    for (int k = 0; k < rows_; ++k) {
      for (int i = 0; i < nx_; ++i) target->Add(i, col0 + k, weight * dense_(k, i));
    }
    return;
  }
  const Matrix jx =
      is_sparse_ ? Matrix(Matrix(columns_).leftCols(nx_)) : Matrix(dense_.leftCols(nx_));
  if (projection == nullptr) {
    target->AddBlock(0, col0, jx.transpose(), weight);
  } else {
    target->AddBlock(0, col0, *projection * jx.transpose(), weight);
  }
}

void ArgumentMatrix::AddStateRows(const Matrix* projection, double weight, DerivativeMatrix* dy,
                                  DerivativeMatrix* du, DerivativeMatrix* dp) const {
  if (projection == nullptr) {
    AddRows(0, nx_, weight, 0, dy, du, dp);
    return;
  }
  // P times the x rows (P = E E^T is dense in general).
  const Matrix rows =
      is_sparse_ ? Matrix(Matrix(columns_).topRows(nx_)) : Matrix(dense_.topRows(nx_));
  const Matrix projected = *projection * rows;
  dy->AddBlock(0, 0, projected.leftCols(nx_), weight);
  dy->AddBlock(0, clock_, projected.col(all_ ? nx_ + nu_ : nx_), weight);
  if (!all_) return;
  du->AddBlock(0, 0, projected.middleCols(nx_, nu_), weight);
  dp->AddBlock(0, 0, projected.rightCols(np_), weight);
}

}  // namespace moreau::internal
