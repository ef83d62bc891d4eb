#pragma once
// The dense block update shared by DerivativeMatrix and SystemMatrix.

#include <Eigen/Core>

namespace moreau::internal {

// target(i, j) += scale * source(i, j) for i < rows, j < cols, both column-major with the given
// column strides. Plain loops: the blocks of lowered systems and collocation matrices are small,
// where Eigen's block expressions cost more in set-up than in arithmetic.
inline void AddScaledColumns(double* target, Eigen::Index target_stride, const double* source,
                             Eigen::Index source_stride, Eigen::Index rows, Eigen::Index cols,
                             double scale) {
  for (Eigen::Index j = 0; j < cols; ++j) {
    double* to = target + j * target_stride;
    const double* from = source + j * source_stride;
    for (Eigen::Index i = 0; i < rows; ++i) to[i] += scale * from[i];
  }
}

}  // namespace moreau::internal
