#pragma once
// Full Newton for the Radau IIA collocation of a lowered system without algebraic unknowns,
//   Z_i - h sum_j a_ij F(y0 + Z_j) = 0,  i = 1..s,
// with the exact stage Jacobians (matrix delta_ij I - h a_ij F_y(Y_j), dense or sparse LU);
// or of the field y' = F(y, z_fixed) of a system with algebraic unknowns held at fixed values
// (SetFixedAlgebraic: FESD's smooth elements of hysteresis relays, whose statuses fix theta).
// Shared by the smooth Radau IIA integrator and by FESD for elements without complementarity
// pairs, so that a scene without effects costs FESD what it costs Radau IIA (private to
// moreau::integrators).

#include <memory>
#include <vector>

#include "moreau/integrators/radau_tableau.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/lowered_system.hpp"

namespace moreau::internal {

class SmoothCollocationSolver {
 public:
  enum class Outcome { kConverged, kNotConverged, kSingular, kNonFinite };

  // Newton stops when the scaled increment is <= tolerance: max_i |dZ_i| / (1 + |y0_i|)
  // (relative), or the weighted RMS over the scene states with weights
  // atol_i + rtol |y0_i| (weighted_rms; atol_i from absolute_tolerances if given, else
  // absolute_tolerance), never below 10 eps (1 + |y0_i|). Contraction failure (an increment not
  // smaller than the previous one from the third iteration on) ends the solve: converged if the
  // increment is within 1e3 tolerances (round-off stall), not converged otherwise.
  struct Stopping {
    bool weighted_rms = false;
    double tolerance = 1e-12;
    double relative_tolerance = 0.0;
    double absolute_tolerance = 0.0;
    const Vector* absolute_tolerances = nullptr;  // per scene state (see above)
    int max_iterations = 25;
    // Simplified Newton: the stage Jacobians F_y are evaluated at the first iterate only (or
    // not at all with reuse_jacobian), later iterations evaluate F alone; where an increment
    // is not below kRefreshContraction times the previous one the solve goes on as full
    // Newton (F_y at every iterate). Off: full Newton throughout.
    bool simplified = false;
    // With simplified: start from the stage Jacobians of the last evaluation with them (an
    // earlier Solve of the same field), if there is one since SetFixedAlgebraic last changed
    // the field. Where they are too far from this solve's (other points, other parameters or
    // inputs), the contraction test replaces them after the second iteration.
    bool reuse_jacobian = false;
  };

  // Simplified Newton keeps its Jacobians while each increment is at most this fraction of
  // the previous one: the error left after the stopping increment d is then at most
  // d * r / (1 - r) <= d / 9, within the tolerance that d met.
  static constexpr double kRefreshContraction = 0.1;

  // switching_mode >= 0: collocates the field of that Stewart mode alone
  // (LoweredSystem::EvaluateField's switching_mode); -1: the system's field.
  SmoothCollocationSolver(LoweredSystem* system, int stages, LinearSolverKind kind,
                          int switching_mode = -1);

  // Holds the algebraic unknowns at z (size n_z of the system) in every evaluation: the
  // collocation is then that of y' = F(y, z). Required before Solve when n_z > 0.
  void SetFixedAlgebraic(const Vector& z) {
    if (z.size() == fixed_algebraic_.size() && (z.array() == fixed_algebraic_.array()).all()) {
      return;  // the same field: its Jacobians stay
    }
    fixed_algebraic_ = z;
    have_jacobian_ = false;  // another field
  }

  // Solves from the stage increments in z (n_y x s, column j = Z_j); z holds the result.
  Outcome Solve(double h, const Vector& y0, const Stopping& stopping, Matrix* z, int* iterations);

  // The scaled increment (see Stopping) of the last iteration of the last Solve: a bound on
  // the error of the iterate it corrected.
  double last_increment() const { return last_increment_; }
  long num_newton_iterations() const { return newton_iterations_; }
  long num_function_evaluations() const { return function_evaluations_; }
  long num_factorizations() const { return solver_->num_factorizations(); }

 private:
  double ScaledIncrement(const Eigen::Ref<const Vector>& dz, const Vector& y0,
                         const Stopping& stopping) const;

  LoweredSystem* system_;
  const int switching_mode_;
  const RadauTableau& tableau_;
  int n_, s_;
  std::unique_ptr<LinearSolver> solver_;
  SystemMatrix matrix_;
  std::vector<PointEvaluation> stage_eval_;  // per stage: F and F_y (dense or sparse)
  PointEvaluation value_eval_;               // simplified Newton: F alone
  bool have_jacobian_ = false;  // stage_eval_ holds F_y of this field, factorized at factorized_h_
  double factorized_h_ = 0.0;
  Matrix stage_f_;
  Vector rhs_, point_;
  Vector fixed_algebraic_;  // empty, or n_z values (SetFixedAlgebraic)
  double last_increment_ = 0.0;
  long newton_iterations_ = 0;
  long function_evaluations_ = 0;
};

}  // namespace moreau::internal
