#include "smooth_collocation.hpp"

#include <cmath>
#include <limits>

#include "moreau/core/error.hpp"

namespace moreau::internal {

SmoothCollocationSolver::SmoothCollocationSolver(LoweredSystem* system, int stages,
                                                 LinearSolverKind kind, int switching_mode)
    : system_(system),
      switching_mode_(switching_mode),
      tableau_(RadauIIA(stages)),
      n_(system->num_states()),
      s_(stages) {
  const double nonzeros = s_ * static_cast<double>(s_) * system->EstimatedNonzerosFy() + s_ * n_;
  solver_ = MakeLinearSolver(kind, s_ * n_, nonzeros);
  stage_f_.resize(n_, s_);
  stage_eval_.resize(static_cast<std::size_t>(s_));
  rhs_.resize(s_ * n_);
}

SmoothCollocationSolver::Outcome SmoothCollocationSolver::Solve(double h, const Vector& y0,
                                                                const Stopping& stopping, Matrix* z,
                                                                int* iterations) {
  MOREAU_ASSERT(fixed_algebraic_.size() == system_->num_algebraic(),
                "smooth collocation needs n_z = 0 or fixed algebraic values");
  double previous_increment = 0.0;
  // Simplified Newton until an increment contracts too little; then full Newton.
  bool simplified = stopping.simplified;
  bool evaluate_jacobian = !(simplified && stopping.reuse_jacobian && have_jacobian_);
  bool factorize = true;
  // The small vector operations below are plain loops over the n states (Eigen's expressions
  // cost more in set-up than in arithmetic at these sizes); each entry is computed with the
  // operations, in the order, of the expressions they replace (same bits).
  const int n = n_;
  point_.resize(n);
  for (int k = 1; k <= stopping.max_iterations; ++k) {
    *iterations = k;
    ++newton_iterations_;
    const bool with_jacobian = evaluate_jacobian || !simplified;
    if (with_jacobian) have_jacobian_ = false;  // until factorized
    for (int j = 0; j < s_; ++j) {
      const double* z_j = z->col(j).data();
      for (int d = 0; d < n; ++d) point_[d] = y0[d] + z_j[d];  // y0 + Z_j
      PointEvaluation& eval =
          with_jacobian ? stage_eval_[static_cast<std::size_t>(j)] : value_eval_;
      // F and F_y alone (the algebraic unknowns are fixed: G, A, B are not read).
      system_->EvaluateField(point_, fixed_algebraic_,
                             with_jacobian ? Derivatives::kStates : Derivatives::kNone, &eval,
                             switching_mode_);
      ++function_evaluations_;
      if (!eval.F.allFinite()) return Outcome::kNonFinite;
      double* f_j = stage_f_.col(j).data();
      for (int d = 0; d < n; ++d) f_j[d] = eval.F[d];
    }
    if (with_jacobian) {
      factorize = true;
      evaluate_jacobian = false;
    }
    // (Radau IIA collocation) residual -(Z_i - h sum_j a_ij F_j), stacked stage by stage.
    for (int i = 0; i < s_; ++i) {
      double* r = rhs_.data() + static_cast<std::ptrdiff_t>(i) * n;
      const double* z_i = z->col(i).data();
      for (int d = 0; d < n; ++d) r[d] = -z_i[d];
      for (int j = 0; j < s_; ++j) {
        const double c = h * tableau_.a(i, j);  // r += (h a_ij) F_j
        const double* f_j = stage_f_.col(j).data();
        for (int d = 0; d < n; ++d) r[d] += c * f_j[d];
      }
    }
    if (factorize || h != factorized_h_) {
      // Newton matrix: delta_ij I - h a_ij F_y(Y_j).
      matrix_.Reset(s_ * n_, solver_->wants_sparse());
      for (int i = 0; i < s_; ++i) {
        matrix_.AddDiagonal(i * n_, i * n_, n_, 1.0);
        for (int j = 0; j < s_; ++j) {
          matrix_.AddDerivative(i * n_, j * n_, stage_eval_[static_cast<std::size_t>(j)].F_y,
                                -h * tableau_.a(i, j));
        }
      }
      matrix_.Finalize();
      const FactorizationStatus status = solver_->Factorize(matrix_);
      factorized_h_ = h;
      factorize = false;
      have_jacobian_ = status == FactorizationStatus::kSuccess;
      if (status == FactorizationStatus::kNonFinite) return Outcome::kNonFinite;
      if (status == FactorizationStatus::kSingular) return Outcome::kSingular;
    }
    solver_->Solve(rhs_);
    if (!rhs_.allFinite()) return Outcome::kNonFinite;
    double increment = 0.0;
    for (int j = 0; j < s_; ++j) {
      double* z_j = z->col(j).data();
      const double* dz = rhs_.data() + static_cast<std::ptrdiff_t>(j) * n;
      for (int d = 0; d < n; ++d) z_j[d] += dz[d];
      increment = std::max(increment, ScaledIncrement(rhs_.segment(j * n_, n_), y0, stopping));
    }
    last_increment_ = increment;
    if (increment <= stopping.tolerance) return Outcome::kConverged;
    if (simplified) {
      // Jacobians too far from the iterate's: full Newton from here (F_y at this iterate).
      if (k >= 2 && increment > kRefreshContraction * previous_increment) {
        simplified = false;
        evaluate_jacobian = true;
      }
      previous_increment = increment;
      continue;
    }
    // Diverging (contraction rate >= 1 after the first correction) or stalled at round-off.
    if (k >= 3 && increment >= previous_increment) {
      return increment <= 1e3 * stopping.tolerance ? Outcome::kConverged : Outcome::kNotConverged;
    }
    previous_increment = increment;
  }
  return Outcome::kNotConverged;
}

double SmoothCollocationSolver::ScaledIncrement(const Eigen::Ref<const Vector>& dz,
                                                const Vector& y0, const Stopping& stopping) const {
  if (!stopping.weighted_rms) {
    double m = 0.0;
    for (int i = 0; i < n_; ++i) m = std::max(m, std::fabs(dz[i]) / (1.0 + std::fabs(y0[i])));
    return m;
  }
  const int nx = system_->num_scene_states();
  double sum = 0.0;
  for (int i = 0; i < nx; ++i) {
    const double atol = stopping.absolute_tolerances != nullptr ? (*stopping.absolute_tolerances)[i]
                                                                : stopping.absolute_tolerance;
    // A state with no scale yet (the automatic atol at zero): what floating point resolves.
    const double w =
        std::max(atol + stopping.relative_tolerance * std::fabs(y0[i]),
                 10.0 * std::numeric_limits<double>::epsilon() * (1.0 + std::fabs(y0[i])));
    sum += (dz[i] / w) * (dz[i] / w);
  }
  return std::sqrt(sum / nx);
}

}  // namespace moreau::internal
