#pragma once
// Dense SQP for the small constraint-satisfaction problems of the alpha-method stepper
// (private).
//
//   minimize    J(z) = 1/2 sum_i w_i (z_i - ref_i)^2
//   subject to  c_E(z) = 0,  c_I(z) <= 0,  lower <= z <= upper.
//
// Each iteration solves the QP
//   minimize 1/2 d^T H d + grad J^T d  s.t.  c_E + J_E d = 0,  c_I + J_I d <= 0,  bounds on z + d
// with a fixed diagonal H > 0 (the objective's Hessian plus a proximal term; constraint
// curvature is left out, so the local rate is linear when the active constraints leave
// degrees of freedom and quadratic when they determine z), by the Goldfarb-Idnani dual
// active-set method. When the linearization is inconsistent, the QP is re-solved in elastic
// mode (l1 penalty on the equality and inequality residuals, as in SNOPT and Fletcher's
// Sl1QP). Steps are globalized by backtracking on the l1 merit function
// J + mu (||c_E||_1 + ||max(c_I, 0)||_1); bounds are never violated. The fixed point of the
// iteration is a KKT point of the problem whatever H is, and the returned certificates are
// evaluated there.
//
// A caller-supplied check sees the working set of every QP (active inequalities and bounds)
// and may reject it: the alpha stepper stops there when the basis matrix of the working set
// is numerically rank deficient.

#include <functional>
#include <vector>

#include "moreau/core/types.hpp"

namespace moreau::internal {

struct SqpEvaluation {
  Vector equalities;           // c_E(z)
  Vector inequalities;         // c_I(z)
  Matrix equality_jacobian;    // only when requested
  Matrix inequality_jacobian;  // only when requested
};

struct SqpWorkingSet {
  // Active in the QP or within the activity tolerance of zero (SqpOptions), sorted.
  std::vector<int> inequalities;  // rows of c_I
  std::vector<int> lower_bounds;  // variables at their lower bound
  std::vector<int> upper_bounds;  // variables at their upper bound
};

struct SqpProblem {
  int num_variables = 0;
  Vector lower;              // -inf allowed
  Vector upper;              // +inf allowed
  Vector objective_weights;  // w_i >= 0
  Vector reference;          // ref
  Vector hessian_diagonal;   // H_ii > 0
  Vector equality_scales;    // |c_E,i| <= equality_tolerance * scale_i at convergence
  // When positive, the equalities determine the first num_determined variables (one equality
  // per such variable, the leading square block of J_E invertible at every point). The QP then
  // states c_I on the equality manifold, in the remaining variables only (see
  // Sqp::ReduceInequalities): a constraint on determined variables that depends on the free
  // ones only weakly (a position constraint through one step: h^2) is otherwise numerically
  // dependent on the equalities' rows and makes the QP inconsistent.
  int num_determined = 0;
  // Fills c_E, c_I (and their Jacobians if `jacobians`); returns false for non-finite values.
  std::function<bool(const Vector& z, bool jacobians, SqpEvaluation* out)> evaluate;
  // Optional; called after every QP with the point of linearization (the last point passed to
  // evaluate with jacobians) and the QP's working set. Returning false stops the SQP.
  std::function<bool(const Vector& z, const SqpWorkingSet& working_set)> check_working_set;
};

struct SqpOptions {
  double equality_tolerance = 1e-10;   // scaled, see SqpProblem::equality_scales
  double inequality_tolerance = 1e-8;  // max(c_I) <= this
  double optimality_tolerance = 1e-8;  // KKT residual <= this
  // Inequalities with c_I >= -activity_tolerance, and bounds within activity_tolerance
  // (relative to max(1, |bound|)), belong to the working set besides the QP's active rows.
  double activity_tolerance = 1e-8;
  int max_iterations = 50;
};

enum class SqpStatus {
  kConverged,           // feasible within the tolerances and KKT residual <= tolerance
  kInfeasible,          // locally infeasible: the linearized l1 violation cannot be reduced
  kRejectedWorkingSet,  // check_working_set returned false
  kMaxIterations,       // max_iterations without convergence
  kLineSearchFailure,   // no acceptable step along the QP direction
  kQpFailure,           // a QP failed (iteration limit or numerical breakdown)
  kNonFinite,           // the model returned non-finite values at the initial point
};
const char* ToString(SqpStatus status);

struct SqpResult {
  SqpStatus status = SqpStatus::kMaxIterations;
  Vector z;                       // last iterate (the solution when converged)
  Vector equality_multipliers;    // y
  Vector inequality_multipliers;  // lambda_I >= 0
  Vector bound_multipliers;       // lambda_lower - lambda_upper per variable
  SqpWorkingSet working_set;      // of the last QP
  int iterations = 0;             // QPs solved
  int qp_iterations = 0;          // active-set changes over all QPs
  int elastic_qps = 0;
  int jacobian_evaluations = 0;
  int function_evaluations = 0;
  double equality_residual = 0.0;     // max_i |c_E,i| / scale_i at z
  double inequality_violation = 0.0;  // max(0, max c_I) at z
  double kkt_residual = 0.0;          // stationarity and complementarity at z
};

SqpResult SolveSqp(const SqpProblem& problem, const Vector& initial_guess,
                   const SqpOptions& options);

}  // namespace moreau::internal
