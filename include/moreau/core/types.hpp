#pragma once
/// @file
/// Basic numeric types shared by every layer of moreau.

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace moreau {

/// Dense column vector of doubles (Eigen).
using Vector = Eigen::VectorXd;
/// Dense matrix of doubles (Eigen).
using Matrix = Eigen::MatrixXd;
/// Compressed column-major sparse matrix of doubles with int indices (Eigen).
using SparseMatrix = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;
/// Writable reference to a vector or a vector expression (no copy).
using VectorRef = Eigen::Ref<Vector>;
/// Read-only reference to a vector or a vector expression (no copy).
using ConstVectorRef = Eigen::Ref<const Vector>;
/// Writable reference to a matrix or a block (no copy).
using MatrixRef = Eigen::Ref<Matrix>;
/// Read-only reference to a matrix or a block (no copy).
using ConstMatrixRef = Eigen::Ref<const Matrix>;

}  // namespace moreau
