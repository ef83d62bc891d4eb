#pragma once
// The shapes in which directions and adjoint weights reach an integrator (FesdOptions::
// sensitivity_directions, adjoint_weights; TimeSteppingOptions likewise). Private to
// moreau::integrators.

#include "moreau/core/types.hpp"

namespace moreau::internal {

// `given` with exactly `rows` (scene coordinates) or `lowered_rows` (lowered coordinates) rows
// and a multiple of `blocks` columns, or a single column of rows * blocks * k entries read
// column by column (front ends pass lists) into rows x (blocks k). Sets *lowered. Throws
// std::invalid_argument naming `what` and the accepted shapes otherwise.
Matrix ShapedSensitivityArgument(const Matrix& given, int rows, int lowered_rows, int blocks,
                                 const char* what, bool* lowered);

}  // namespace moreau::internal
