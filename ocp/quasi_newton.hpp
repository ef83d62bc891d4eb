#pragma once
// Private to moreau::ocp: a dense quasi-Newton approximation of one block of the Lagrangian's
// Hessian (docs/ocp.md, "Second-order information").

#include <deque>

#include "moreau/core/types.hpp"

namespace moreau::ocp_internal {

// B approximates the Hessian of a block's part of the Lagrangian over the block's variables.
// Updated from a step s and the change y of the part's gradient along it (both at the new
// multipliers), as in SQP methods with partitioned quasi-Newton updates (Griewank and Toint;
// Bock and Plitt for multiple shooting). With a limited memory, B is rebuilt from the last
// `memory` pairs on the initial matrix of the newest pair: curvature measured across a kink of
// the nonsmooth NLP is forgotten after `memory` iterations instead of never.
class QuasiNewtonBlock {
 public:
  enum class Kind {
    // Damped BFGS (Powell): y is replaced by theta y + (1 - theta) B s so that
    // s^T y >= 0.2 s^T B s; B stays positive definite.
    kDampedBfgs,
    // Symmetric rank one, skipped when |s^T (y - B s)| < 1e-8 |s| |y - B s|; may be indefinite.
    kSr1,
  };
  // memory 0: every pair is kept (the full quasi-Newton matrix).
  QuasiNewtonBlock(int size, Kind kind, int memory = 0);

  // Back to the initial matrix, the identity (rescaled at the first update with s^T y > 0 by
  // y^T y / s^T y, the usual initial scaling).
  void Reset();
  // One update; returns false if it was skipped (too small a step, or the safeguards above).
  bool Update(const Vector& s, const Vector& y);
  const Matrix& matrix() const { return b_; }
  int size() const { return static_cast<int>(b_.rows()); }

 private:
  // Applies one pair to b_; false if skipped.
  bool Apply(const Vector& s, const Vector& y);
  Kind kind_;
  int memory_;
  Matrix b_;
  bool scaled_ = false;
  std::deque<std::pair<Vector, Vector>> pairs_;
};

}  // namespace moreau::ocp_internal
