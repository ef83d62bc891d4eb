#pragma once
// The step transfers a time-stepping run keeps for its adjoint (TimeSteppingAdjoint).
// Private to moreau::integrators.

#include <cstddef>
#include <memory>
#include <vector>

#include "../common/spill_file.hpp"
#include "moreau/core/types.hpp"

namespace moreau::internal {

struct TimeSteppingTape {
  int nx = 0, ny = 0, np = 0, nu = 0, segments = 0;
  // T_k = d y_(k+1) / d(y_k, p, u_segment): n_y x (n_y + n_p + n_u), in memory or, beyond
  // memory_limit bytes, in the file at file_offset (matrix then empty).
  struct Transfer {
    int segment = 0;
    Matrix matrix;
    long file_offset = -1;
  };
  std::vector<Transfer> transfers;
  // Sample j is the state after sample_positions[j] transfers.
  std::vector<std::size_t> sample_positions;
  std::size_t memory_limit = 0;  // bytes (0: none)
  std::size_t bytes = 0;         // transfers in memory
  long file_bytes = 0;           // the file's used length
  std::unique_ptr<SpillFile> file;

  // Keeps one step's transfer (in memory or in the file).
  void Add(int segment, const Matrix& transfer);
  // lambda = W (final) at y(T); for k = N-1 .. 0: the sample weights of a sample reached after
  // k + 1 transfers are added, gradient += T_(p,u)^T lambda, lambda = T_y^T lambda. Returns the
  // gradients over (y0, p, u) and over (x0, p, u). Throws std::invalid_argument for weights
  // of another shape.
  void Sweep(const Matrix& final_weights, const Matrix& sample_weights, Matrix* lowered,
             Matrix* theta) const;
};

}  // namespace moreau::internal
