#include "sensitivity_arguments.hpp"

#include <sstream>
#include <stdexcept>

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

}  // namespace moreau::internal
