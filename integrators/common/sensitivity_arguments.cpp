#include "sensitivity_arguments.hpp"

#include <sstream>
#include <stdexcept>

#include "moreau/core/error.hpp"

namespace moreau::internal {

Matrix ShapedSensitivityArgument(const Matrix& given, int rows, int lowered_rows, int blocks,
                                 const char* what, bool* lowered) {
  *lowered = false;
  if (given.rows() == rows && given.cols() % blocks == 0) return given;
  if (given.rows() == lowered_rows && given.cols() % blocks == 0) {
    *lowered = true;
    return given;
  }
  const Eigen::Index block = static_cast<Eigen::Index>(rows) * blocks;
  if (given.cols() == 1 && block > 0 && given.size() % block == 0) {
    return given.reshaped(rows, given.size() / rows);
  }
  std::ostringstream s;
  s << what << ": expected " << rows << " rows (or " << lowered_rows
    << " over the lowered state), or a single column of " << rows << " * " << blocks
    << " * k entries; got " << given.rows() << " x " << given.cols();
  throw std::invalid_argument(s.str());
}

Eigen::Index ShapedAdjointWeights(const Matrix& final_weights, const Matrix& sample_weights,
                                  int rows, int lowered_rows, int samples, Matrix* final_shaped,
                                  Matrix* sample_shaped) {
  bool lowered = false;
  *final_shaped = Matrix();
  *sample_shaped = Matrix();
  if (final_weights.size() > 0) {
    *final_shaped = ShapedSensitivityArgument(final_weights, rows, lowered_rows, 1,
                                              "adjoint weights", &lowered);
  }
  if (sample_weights.size() > 0) {
    RequireArgument(samples > 0, "adjoint sample weights need sample_times");
    *sample_shaped = ShapedSensitivityArgument(sample_weights, rows, lowered_rows, samples,
                                               "adjoint sample weights", &lowered);
  }
  RequireArgument(final_shaped->size() > 0 || sample_shaped->size() > 0,
                  "adjoint: no weights (final or sample) given");
  const Eigen::Index q =
      final_shaped->size() > 0 ? final_shaped->cols() : sample_shaped->cols() / samples;
  RequireArgument(sample_shaped->size() == 0 || sample_shaped->cols() == q * samples,
                  "adjoint sample weights: expected ", q * samples, " columns (", q,
                  " per sample time, as the final weights), got ", sample_shaped->cols());
  return q;
}

}  // namespace moreau::internal
