#pragma once
/// @file
/// Linear complementarity problems LCP(M, q): find z with w = M z + q,
/// 0 <= z ⟂ w >= 0, solved by the semismooth Newton method (see semismooth_newton.hpp)
/// on Phi(z) = phi(z, M z + q). For P-matrices the solution is unique; for positive
/// semidefinite M (monotone LCP) the solution set is convex.

#include "moreau/core/types.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau {

/// Result of SolveLcp: the solution z, w = M z + q, the natural residual and Newton's statistics.
struct LcpResult {
  /// kConverged, or why Newton stopped.
  NewtonStatus status = NewtonStatus::kConverged;
  /// Why the solve failed (empty on success).
  std::string message;
  /// The solution (0 <= z ⟂ M z + q >= 0 when converged).
  Vector z;
  Vector w;                              ///< M z + q
  double residual = 0.0;                 ///< max_i |min(z_i, w_i)| (natural residual)
  std::vector<double> residual_history;  ///< Newton residual at every iterate
  /// Iterations, evaluations and line-search statistics of the Newton solve.
  SemismoothNewtonStats stats;
  /// True if status is NewtonStatus::kConverged.
  bool converged() const { return status == NewtonStatus::kConverged; }
};

/// Solves LCP(M, q) from z0 (default: z0 = 0). Throws std::invalid_argument for mismatched
/// or non-finite input.
LcpResult SolveLcp(const Matrix& m, const Vector& q, const SemismoothNewtonOptions& options = {},
                   const Vector* initial_guess = nullptr);

}  // namespace moreau
