#pragma once
// Dense strictly convex QP by the Goldfarb-Idnani dual active-set method (private to the
// alpha-method stepper).
//
//   minimize    1/2 x^T G x + g^T x
//   subject to  A_eq x  = b_eq
//               A_in x >= b_in
//
// G symmetric positive definite. The method starts from the unconstrained minimizer and adds
// violated constraints one at a time, keeping the active set's multipliers dual feasible
// (partial steps drop constraints whose multipliers would turn negative). Every iterate is
// optimal for the constraints in its active set, so the first primal-feasible iterate is the
// solution; a violated constraint that cannot be added (its normal lies in the span of the
// active normals and no active multiplier can give way) proves infeasibility.
//
// Reference: D. Goldfarb and A. Idnani, A numerically stable dual method for solving strictly
// convex quadratic programs, Math. Programming 27 (1983) 1-33.
//
// The projections are recomputed from a QR factorization of L^{-1} N (G = L L^T, N the active
// normals) at every iteration instead of being updated by Givens rotations: the QPs of the
// stepper have a few dozen unknowns, where clarity wins over the O(n^2) update.

#include <vector>

#include "moreau/core/types.hpp"

namespace moreau::internal {

struct DenseQp {
  Matrix hessian;            // G (n x n), symmetric positive definite
  Vector gradient;           // g (n)
  Matrix equality_matrix;    // A_eq (m_eq x n)
  Vector equality_rhs;       // b_eq
  Matrix inequality_matrix;  // A_in (m_in x n)
  Vector inequality_rhs;     // b_in
};

enum class QpStatus {
  kOptimal,              // KKT point found (primal feasible within the tolerance, multipliers >= 0)
  kInfeasible,           // the constraints are inconsistent (certificate: a violated constraint
                         // whose normal is a nonnegative combination of active ones)
  kDependentEqualities,  // an equality is a combination of earlier ones but not consistent
  kIterationLimit,       // more active-set changes than the limit
  kNotConvex,            // G is not (numerically) positive definite
};
const char* ToString(QpStatus status);

struct QpSolution {
  QpStatus status = QpStatus::kOptimal;
  Vector x;
  // Multipliers with G x + g = A_eq^T y + A_in^T z, z >= 0, z_i = 0 for inactive rows.
  Vector equality_multipliers;
  Vector inequality_multipliers;
  std::vector<int> active_inequalities;  // rows of A_in in the final active set
  int iterations = 0;                    // constraints added or dropped
};

struct QpOptions {
  // A row counts as violated when A_i x - b_i < -feasibility_tolerance * max(1, |b_i|,
  // |A_i| |x|) (relative to the size of the terms).
  double feasibility_tolerance = 1e-12;
  // A new normal is linearly dependent on the active ones when the norm of its component
  // outside their span (in the G^{-1} metric) is below this times its norm.
  double dependence_tolerance = 1e-12;
  // Limit on additions and drops; <= 0 means 10 (n + m_eq + m_in) + 10.
  int max_iterations = 0;
};

QpSolution SolveQp(const DenseQp& qp, const QpOptions& options = {});

}  // namespace moreau::internal
