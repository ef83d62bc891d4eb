#pragma once
// The shapes in which directions and adjoint weights reach an integrator (FesdOptions::
// sensitivity_directions, adjoint_weights; TimeSteppingOptions likewise). Private to
// moreau::integrators.

#include <cmath>
#include <cstddef>

#include "moreau/core/error.hpp"
#include "moreau/core/types.hpp"

namespace moreau::internal {

// `given` with exactly `rows` (scene coordinates) or `lowered_rows` (lowered coordinates) rows
// and a multiple of `blocks` columns, or a single column of rows * blocks * k entries read
// column by column (front ends pass lists) into rows x (blocks k). Sets *lowered. Throws
// std::invalid_argument naming `what` and the accepted shapes otherwise.
Matrix ShapedSensitivityArgument(const Matrix& given, int rows, int lowered_rows, int blocks,
                                 const char* what, bool* lowered);

// The adjoint's final weights (rows or lowered_rows rows, q columns) and sample weights (q
// columns per sample time) shaped as above into *final_shaped and *sample_shaped (empty where
// not given); returns q. Throws std::invalid_argument if neither is given, sample weights come
// without samples, or their columns are not q per sample.
Eigen::Index ShapedAdjointWeights(const Matrix& final_weights, const Matrix& sample_weights,
                                  int rows, int lowered_rows, int samples, Matrix* final_shaped,
                                  Matrix* sample_shaped);

// The sensitivity options FESD and time-stepping share (FesdOptions, TimeSteppingOptions):
// finite directions and weights, increasing finite sample times that something tracks, sample
// weights only with sample times, a memory limit >= 0. Throws std::invalid_argument naming the
// first violation.
template <class Options>
void ValidateSensitivityOptions(const Options& o) {
  RequireArgument(o.sensitivity_directions.allFinite(), "sensitivity directions must be finite");
  RequireArgument(o.adjoint_weights.allFinite() && o.adjoint_sample_weights.allFinite(),
                  "adjoint weights must be finite");
  for (std::size_t j = 0; j < o.sample_times.size(); ++j) {
    RequireArgument(
        std::isfinite(o.sample_times[j]) && (j == 0 || o.sample_times[j] > o.sample_times[j - 1]),
        "sample times must be finite and increasing, got ", o.sample_times[j], " at position ", j);
  }
  const bool tracked = o.sensitivities || o.sensitivity_directions.size() > 0 ||
                       o.adjoint_weights.size() > 0 || o.adjoint_sample_weights.size() > 0 ||
                       o.keep_adjoint;
  RequireArgument(o.sample_times.empty() || tracked,
                  "sample_times need sensitivities: directions, adjoint weights or keep_adjoint");
  RequireArgument(o.adjoint_sample_weights.size() == 0 || !o.sample_times.empty(),
                  "adjoint sample weights need sample_times");
  RequireArgument(std::isfinite(o.adjoint_memory_limit_mb) && o.adjoint_memory_limit_mb >= 0.0,
                  "adjoint memory limit must be >= 0 megabytes (0: none), got ",
                  o.adjoint_memory_limit_mb);
}

}  // namespace moreau::internal
