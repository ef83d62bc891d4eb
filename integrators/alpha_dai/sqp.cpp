#include "sqp.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "active_set_qp.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {

const char* ToString(SqpStatus status) {
  switch (status) {
    case SqpStatus::kConverged:
      return "converged";
    case SqpStatus::kInfeasible:
      return "locally infeasible";
    case SqpStatus::kRejectedWorkingSet:
      return "working set rejected";
    case SqpStatus::kMaxIterations:
      return "iteration limit";
    case SqpStatus::kLineSearchFailure:
      return "line search failure";
    case SqpStatus::kQpFailure:
      return "QP failure";
    case SqpStatus::kNonFinite:
      return "non-finite values";
  }
  return "?";
}

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
// Sufficient decrease (Armijo) on the l1 merit function, and the shortest step tried.
constexpr double kArmijo = 1e-4;
constexpr double kMinStepLength = 1e-10;
// Relative round-off of the merit function's terms (100 ulps; see MeritNoise).
constexpr double kMeritNoise = 100.0 * std::numeric_limits<double>::epsilon();
// The penalty mu stays above this factor times the largest constraint multiplier, so that the
// QP direction is a descent direction of the merit function (mu >= ||lambda||_inf suffices).
constexpr double kPenaltyFactor = 2.0;
// Elastic mode: the slacks get this curvature (Goldfarb-Idnani needs H > 0; at a slack of
// order one it changes the penalty by a relative 1e-6/mu) and a penalty at least this large
// relative to the objective gradient; the penalty grows tenfold while that still reduces the
// linearized violation by 10%, at most kMaxEscalations times.
constexpr double kElasticCurvature = 1e-6;
constexpr double kElasticPenaltyMin = 1e2;
constexpr int kMaxEscalations = 4;
// A point is stationary for the l1 violation when the elastic QP with the objective removed
// and this penalty predicts a relative decrease below kStationaryDecrease. The linear model
// ignores curvature, so near a stationary point it still predicts decreases of the order of
// the squared distance; 1e-6 of the violation stops there instead of crawling.
constexpr double kStationarityPenalty = 1e6;
constexpr double kStationaryDecrease = 1e-6;
// kStallIterations elastic iterations in a row that each reduce the l1 violation by less than
// kStallDecrease (relative) end the SQP as locally infeasible: near an infeasible stationary
// point the linearization keeps predicting decreases that curvature (and the zig-zag between
// competing constraints of the nonsmooth l1 function) takes away.
constexpr int kStallIterations = 3;
constexpr double kStallDecrease = 1e-2;

// Rows of the QP's inequality block: c_I rows, then finite lower bounds, then finite upper.
struct RowMap {
  int num_constraints = 0;
  std::vector<int> lower;  // variable of each lower-bound row
  std::vector<int> upper;  // variable of each upper-bound row
  int size() const { return num_constraints + static_cast<int>(lower.size() + upper.size()); }
};

class Sqp {
 public:
  Sqp(const SqpProblem& problem, const SqpOptions& options)
      : problem_(problem), options_(options), n_(problem.num_variables) {
    MOREAU_ASSERT(problem.lower.size() == n_ && problem.upper.size() == n_, "SQP bounds size");
    MOREAU_ASSERT(problem.objective_weights.size() == n_ && problem.reference.size() == n_,
                  "SQP objective size");
    MOREAU_ASSERT(problem.hessian_diagonal.size() == n_, "SQP Hessian size");
    for (int i = 0; i < n_; ++i) {
      if (std::isfinite(problem.lower[i])) rows_.lower.push_back(i);
      if (std::isfinite(problem.upper[i])) rows_.upper.push_back(i);
    }
  }

  SqpResult Solve(const Vector& guess) {
    SqpResult result;
    z_ = guess.cwiseMax(problem_.lower).cwiseMin(problem_.upper);
    result.z = z_;
    if (!Evaluate(z_, true, &eval_, &result)) {
      result.status = SqpStatus::kNonFinite;
      return result;
    }
    m_eq_ = static_cast<int>(eval_.equalities.size());
    rows_.num_constraints = static_cast<int>(eval_.inequalities.size());
    MOREAU_ASSERT(problem_.num_determined == 0 || problem_.num_determined == m_eq_,
                  "SQP: num_determined must equal the number of equalities");
    ReduceInequalities();
    double mu = 1.0;
    for (int iteration = 0; iteration < options_.max_iterations; ++iteration) {
      ++result.iterations;
      const double violation = Violation(eval_);
      Fill(&result);
      // QP at z; elastic mode if its linearization is inconsistent.
      QpSolution qp = SolveQp(BuildQp(), QpOptions{});
      result.qp_iterations += qp.iterations;
      bool elastic = false;
      double linearized_violation = 0.0;
      Vector step;
      Vector slacks;  // elastic slacks (empty for the plain QP)
      std::vector<int> active_rows;
      if (qp.status == QpStatus::kOptimal) {
        step = qp.x;
        active_rows = qp.active_inequalities;
        stalled_ = 0;
        previous_violation_ = std::numeric_limits<double>::infinity();
        result.working_set = WorkingSet(qp.active_inequalities, Vector(), false);
        StoreMultipliers(qp, true, true, &result);
      } else if (qp.status == QpStatus::kInfeasible ||
                 qp.status == QpStatus::kDependentEqualities) {
        elastic = true;
        double penalty =
            std::max(mu, kElasticPenaltyMin * (1.0 + Gradient().lpNorm<Eigen::Infinity>()));
        // Inequalities elastic first (the equalities stay hard, so that an infeasibility is
        // measured on the equality manifold); all constraints elastic if that is inconsistent.
        QpSolution elastic_qp;
        soft_equalities_ = false;
        if (!SolveElastic(Gradient(), penalty, &elastic_qp, &linearized_violation, &result)) {
          soft_equalities_ = true;
          if (!SolveElastic(Gradient(), penalty, &elastic_qp, &linearized_violation, &result)) {
            result.status = SqpStatus::kQpFailure;
            return result;
          }
        }
        for (int escalation = 0; escalation < kMaxEscalations && linearized_violation > 0.0;
             ++escalation) {
          QpSolution stronger;
          double stronger_violation = 0.0;
          if (!SolveElastic(Gradient(), 10.0 * penalty, &stronger, &stronger_violation, &result))
            break;
          if (stronger_violation > 0.9 * linearized_violation) break;
          penalty *= 10.0;
          elastic_qp = stronger;
          linearized_violation = stronger_violation;
        }
        mu = std::max(mu, penalty);
        step = elastic_qp.x.head(n_);
        slacks = elastic_qp.x.tail(SlackCount());
        active_rows = elastic_qp.active_inequalities;
        // The elastic QP's rows start with those of the plain QP: same multiplier layout.
        StoreMultipliers(elastic_qp, !soft_equalities_, false, &result);
        result.working_set = WorkingSet(active_rows, slacks, false);
        // Local infeasibility: no predicted decrease of the violation even without the
        // objective (z is a stationary point of the linearized l1 violation), or elastic
        // iterations that stopped reducing it (see kStallIterations).
        // A point feasible within the tolerances whose linearization is inconsistent (a
        // degenerate vertex, violations of round-off size) is not declared infeasible: it
        // converges below if its KKT residual is small.
        bool stationary = false;
        if (!Feasible(result) && linearized_violation >= violation * (1.0 - kStationaryDecrease)) {
          QpSolution pure;
          double pure_violation = 0.0;
          stationary = SolveElastic(Vector::Zero(n_), kStationarityPenalty, &pure, &pure_violation,
                                    &result) &&
                       pure_violation >= violation * (1.0 - kStationaryDecrease);
        }
        const bool progress =
            !std::isfinite(previous_violation_) ||
            previous_violation_ - violation > kStallDecrease * previous_violation_;
        stalled_ = progress ? 0 : stalled_ + 1;
        previous_violation_ = violation;
        if (!Feasible(result) && (stationary || stalled_ >= kStallIterations)) {
          result.status = SqpStatus::kInfeasible;
          return result;
        }
      } else {
        result.status = SqpStatus::kQpFailure;
        return result;
      }
      result.kkt_residual = KktResidual(result);
      const bool converged =
          Feasible(result) && result.kkt_residual <= options_.optimality_tolerance;
      // At the solution the working set also holds the constraints that sit on zero.
      if (converged) result.working_set = WorkingSet(active_rows, slacks, true);
      if (problem_.check_working_set && !problem_.check_working_set(z_, result.working_set)) {
        result.status = SqpStatus::kRejectedWorkingSet;
        return result;
      }
      if (converged) {
        result.status = SqpStatus::kConverged;
        return result;
      }
      if (!elastic) {
        double largest = 0.0;
        if (m_eq_ > 0) largest = result.equality_multipliers.lpNorm<Eigen::Infinity>();
        if (rows_.num_constraints > 0) {
          largest = std::max(largest, result.inequality_multipliers.lpNorm<Eigen::Infinity>());
        }
        mu = std::max(mu, kPenaltyFactor * largest);
      }
      // Backtracking on the l1 merit function P = J + mu V.
      const double merit = Objective(z_) + mu * violation;
      const double slope =
          std::min(0.0, Gradient().dot(step) - mu * (violation - linearized_violation));
      const double noise = MeritNoise(mu);
      double alpha = 1.0;
      SqpEvaluation trial;
      Vector z_trial;
      bool accepted = false;
      while (alpha >= kMinStepLength) {
        z_trial = (z_ + alpha * step).cwiseMax(problem_.lower).cwiseMin(problem_.upper);
        if (Evaluate(z_trial, false, &trial, &result)) {
          const double trial_merit = Objective(z_trial) + mu * Violation(trial);
          if (trial_merit <= merit + kArmijo * alpha * slope + noise) {
            accepted = true;
            break;
          }
        }
        alpha *= 0.5;
      }
      if (!accepted || z_trial == z_) {
        result.status = SqpStatus::kLineSearchFailure;
        return result;
      }
      z_ = z_trial;
      result.z = z_;
      if (!Evaluate(z_, true, &eval_, &result)) {
        result.status = SqpStatus::kNonFinite;  // finite without Jacobians, not with them
        return result;
      }
      ReduceInequalities();
    }
    Fill(&result);
    result.status = SqpStatus::kMaxIterations;
    return result;
  }

 private:
  bool Evaluate(const Vector& z, bool jacobians, SqpEvaluation* out, SqpResult* result) {
    if (jacobians) {
      ++result->jacobian_evaluations;
    } else {
      ++result->function_evaluations;
    }
    if (!problem_.evaluate(z, jacobians, out)) return false;
    if (!out->equalities.allFinite() || !out->inequalities.allFinite()) return false;
    if (jacobians && (!out->equality_jacobian.allFinite() || !out->inequality_jacobian.allFinite()))
      return false;
    return true;
  }

  double Objective(const Vector& z) const {
    return 0.5 *
           (problem_.objective_weights.array() * (z - problem_.reference).array().square()).sum();
  }
  Vector Gradient() const {
    return problem_.objective_weights.cwiseProduct(z_ - problem_.reference);
  }
  // Round-off level of the merit function at z_: each residual carries an error of a few ulps
  // of the terms it is computed from (scale_i for the equalities, max(1, |c_I,j|) for the
  // inequalities). Below it the sufficient-decrease test compares noise.
  double MeritNoise(double mu) const {
    double scale = problem_.equality_scales.sum();
    for (int j = 0; j < rows_.num_constraints; ++j) {
      scale += std::max(1.0, std::fabs(eval_.inequalities[j]));
    }
    return kMeritNoise * (std::fabs(Objective(z_)) + mu * scale);
  }

  // l1 violation V = ||c_E||_1 + ||max(c_I, 0)||_1 (the bounds always hold).
  static double Violation(const SqpEvaluation& e) {
    return e.equalities.lpNorm<1>() + e.inequalities.cwiseMax(0.0).sum();
  }

  bool Feasible(const SqpResult& result) const {
    if (result.equality_residual > options_.equality_tolerance ||
        result.inequality_violation > options_.inequality_tolerance) {
      return false;
    }
    for (int i = 0; i < rows_.num_constraints; ++i) {
      if (eval_.inequalities[i] > InequalityTolerance(i)) return false;
    }
    return true;
  }

  // Residual and violation of the current point.
  void Fill(SqpResult* result) const {
    result->z = z_;
    result->equality_residual = 0.0;
    for (int i = 0; i < m_eq_; ++i) {
      result->equality_residual = std::max(
          result->equality_residual, std::fabs(eval_.equalities[i]) / problem_.equality_scales[i]);
    }
    result->inequality_violation =
        rows_.num_constraints > 0 ? std::max(0.0, eval_.inequalities.maxCoeff()) : 0.0;
  }

  // Elastic slacks: (s+, s-) for the equalities when they are soft, then t for c_I.
  int EqualitySlacks() const { return soft_equalities_ ? 2 * m_eq_ : 0; }
  int SlackCount() const { return EqualitySlacks() + rows_.num_constraints; }

  // The QP at z_: A_eq d = -c_E; -J_I d >= c_I; d >= lower - z; -d >= z - upper.
  DenseQp BuildQp() const {
    DenseQp qp;
    qp.hessian = problem_.hessian_diagonal.asDiagonal();
    qp.gradient = Gradient();
    qp.equality_matrix = eval_.equality_jacobian;
    qp.equality_rhs = -eval_.equalities;
    qp.inequality_matrix = Matrix::Zero(rows_.size(), n_);
    qp.inequality_rhs.resize(rows_.size());
    AddInequalityRows(0, 0, true, true, &qp);
    return qp;
  }

  // The constraint rows on the equality manifold (SqpProblem::num_determined). With z = (y, v),
  // y the k determined variables and J_E = [E_y E_v], the equalities' linearization
  // E_y d_y + E_v d_v = -c_E gives d_y = -E_y^{-1} (c_E + E_v d_v), so that
  //   c_I + J_I d = (c_I - M c_E) + (J_I,v - M E_v) d_v,   M = J_I,y E_y^{-1},
  // exactly, for every step d on the manifold. The QP's constraint rows become
  // [0, J_I,v - M E_v] with right-hand side c_I - M c_E: the same feasible set, but the row no
  // longer carries the large component along the equalities' normals (J_I,y, which the
  // equalities' rows nearly span), whose difference from their span the QP would have to
  // resolve by cancellation. For the alpha stepper's position constraint, J_I,v - M E_v is the
  // constraint's sensitivity to u through one step, C (I - c h A)^{-1} c h D + G = O(h^2):
  // without the reduction, in the QP's metric (weight 1e-8 on x, 1 on u) the row is within
  // 1e-4 (c h)^2 of the span of the dynamics rows relative to its norm, below the QP's
  // dependence tolerance for h below about 2e-4, and every such QP was declared inconsistent.
  // The multipliers are unchanged for c_I; those of the equalities become y + M^T lambda
  // (StoreMultipliers), so that the certificates are the original problem's.
  void ReduceInequalities() {
    reduction_.resize(0, 0);
    row_scales_.resize(0);
    const int k = problem_.num_determined;
    const int m = rows_.num_constraints;
    if (k == 0 || m == 0) return;
    const Eigen::PartialPivLU<Matrix> lu_transposed(
        eval_.equality_jacobian.leftCols(k).transpose());
    reduction_ = lu_transposed.solve(eval_.inequality_jacobian.leftCols(k).transpose()).transpose();
    reduced_jacobian_ = Matrix::Zero(m, n_);
    reduced_jacobian_.rightCols(n_ - k) = eval_.inequality_jacobian.rightCols(n_ - k) -
                                          reduction_ * eval_.equality_jacobian.rightCols(n_ - k);
    reduced_values_ = eval_.inequalities - reduction_ * eval_.equalities;
    // Rows that see the free variables weakly are stated in their units: c_I,i / s_i with s_i
    // the row's size in them (s_i < 1; an index-3 row's is O(h^2)). The QP's feasibility test
    // (relative to max(1, |b_i|, ...)) and the SQP's tolerance then apply to the change of the
    // free variables a violation asks for, not to the violation itself: a violation of
    // 2 (c h)^2, which u = -2 instead of 0 gives hard_index3's floor in one step, passes an
    // absolute 1e-8 (and the QP's 1e-12) at steps below 1e-4 and accumulates like t^2.
    row_scales_ = Vector::Ones(m);
    for (int i = 0; i < m; ++i) {
      const double size = reduced_jacobian_.row(i).norm();
      if (size > 0.0 && size < 1.0) row_scales_[i] = 1.0 / size;
    }
  }

  // Tolerance on c_I,i: inequality_tolerance in the units of ReduceInequalities' row scaling,
  // at least the round-off of a constraint computed from z (100 ulps of 1 + |z|).
  double InequalityTolerance(int i) const {
    if (row_scales_.size() == 0) return options_.inequality_tolerance;
    return std::max(options_.inequality_tolerance / row_scales_[i],
                    kMeritNoise * (1.0 + z_.lpNorm<Eigen::Infinity>()));
  }

  // Rows of the inequality block starting at row0 (constraint rows, then bounds), with the
  // step d in columns [col0, col0 + n); `reduced`: the constraint rows on the equality manifold
  // (ReduceInequalities), valid only while the equalities are hard; `scaled`: in the units of
  // the free variables (row_scales_).
  void AddInequalityRows(int row0, int col0, bool reduced, bool scaled, DenseQp* qp) const {
    const int m = rows_.num_constraints;
    if (m > 0) {
      if (reduced && reduction_.size() > 0) {
        const Vector scales = scaled ? row_scales_ : Vector::Ones(m);
        qp->inequality_matrix.block(row0, col0, m, n_) = -(scales.asDiagonal() * reduced_jacobian_);
        qp->inequality_rhs.segment(row0, m) = scales.cwiseProduct(reduced_values_);
      } else {
        qp->inequality_matrix.block(row0, col0, m, n_) = -eval_.inequality_jacobian;
        qp->inequality_rhs.segment(row0, m) = eval_.inequalities;
      }
    }
    int row = row0 + m;
    for (int j : rows_.lower) {
      qp->inequality_matrix(row, col0 + j) = 1.0;
      qp->inequality_rhs[row++] = problem_.lower[j] - z_[j];
    }
    for (int j : rows_.upper) {
      qp->inequality_matrix(row, col0 + j) = -1.0;
      qp->inequality_rhs[row++] = z_[j] - problem_.upper[j];
    }
  }

  // Elastic QP in (d, s+, s-, t): minimize 1/2 d^T H d + g^T d + penalty 1^T (s+ + s- + t)
  // + kElasticCurvature/2 |slacks|^2 subject to J_E d - s+ + s- = -c_E, c_I + J_I d <= t,
  // slacks >= 0 and the bounds (always feasible). Without soft_equalities_ there are no s+, s-
  // and J_E d = -c_E is hard. Returns the linearized violation sum(slacks); false if the QP
  // failed (infeasible only with hard equalities).
  bool SolveElastic(const Vector& gradient, double penalty, QpSolution* solution,
                    double* linearized_violation, SqpResult* result) const {
    const int ns = SlackCount();
    const int m = rows_.num_constraints;
    const int nv = n_ + ns;
    DenseQp qp;
    qp.hessian = Matrix::Zero(nv, nv);
    qp.hessian.diagonal().head(n_) = problem_.hessian_diagonal;
    qp.hessian.diagonal().tail(ns).setConstant(kElasticCurvature);
    qp.gradient.resize(nv);
    qp.gradient << gradient, Vector::Constant(ns, penalty);
    qp.equality_matrix = Matrix::Zero(m_eq_, nv);
    if (m_eq_ > 0) {
      qp.equality_matrix.leftCols(n_) = eval_.equality_jacobian;
      if (soft_equalities_) {
        qp.equality_matrix.block(0, n_, m_eq_, m_eq_) = -Matrix::Identity(m_eq_, m_eq_);
        qp.equality_matrix.block(0, n_ + m_eq_, m_eq_, m_eq_) = Matrix::Identity(m_eq_, m_eq_);
      }
    }
    qp.equality_rhs = -eval_.equalities;
    const int rows = rows_.size() + ns;
    qp.inequality_matrix = Matrix::Zero(rows, nv);
    qp.inequality_rhs = Vector::Zero(rows);
    // With soft equalities the step leaves the equality manifold: the rows are not reduced.
    // Not scaled: the slacks measure the violation of c_I itself, as the merit function does.
    AddInequalityRows(0, 0, !soft_equalities_, false, &qp);
    if (m > 0) {
      qp.inequality_matrix.block(0, n_ + EqualitySlacks(), m, m) = Matrix::Identity(m, m);
    }
    qp.inequality_matrix.block(rows_.size(), n_, ns, ns) = Matrix::Identity(ns, ns);
    *solution = SolveQp(qp, QpOptions{});
    result->qp_iterations += solution->iterations;
    ++result->elastic_qps;
    if (solution->status != QpStatus::kOptimal) return false;
    *linearized_violation = solution->x.tail(ns).cwiseMax(0.0).sum();
    return true;
  }

  // Working set from the active rows of the (plain or elastic) QP. In elastic mode a
  // constraint row whose slack t_i is positive is not binding and is left out.
  // With `near_active`, constraints and bounds within options_.activity_tolerance of zero at
  // z_ are added: a constraint that an SQP step pushed onto zero belongs to the working set
  // at the solution although the last QP, at a feasible point, had no reason to hold it.
  // During the iterations only the QP's rows count (a guess may touch a constraint by chance).
  SqpWorkingSet WorkingSet(const std::vector<int>& active_rows, const Vector& slacks,
                           bool near_active) const {
    const int m = rows_.num_constraints;
    const int num_lower = static_cast<int>(rows_.lower.size());
    std::vector<bool> constraint(static_cast<std::size_t>(m), false);
    std::vector<bool> lower(static_cast<std::size_t>(n_), false);
    std::vector<bool> upper(static_cast<std::size_t>(n_), false);
    for (int row : active_rows) {
      if (row < m) {
        if (slacks.size() > 0 && slacks[EqualitySlacks() + row] > 0.0) continue;
        constraint[static_cast<std::size_t>(row)] = true;
      } else if (row < m + num_lower) {
        lower[static_cast<std::size_t>(rows_.lower[static_cast<std::size_t>(row - m)])] = true;
      } else if (row < rows_.size()) {
        upper[static_cast<std::size_t>(
            rows_.upper[static_cast<std::size_t>(row - m - num_lower)])] = true;
      }
    }
    const double tolerance = near_active ? options_.activity_tolerance : -kInfinity;
    for (int i = 0; i < m; ++i) {
      if (eval_.inequalities[i] >= -tolerance) constraint[static_cast<std::size_t>(i)] = true;
    }
    for (int j : rows_.lower) {
      const double bound = problem_.lower[j];
      if (z_[j] - bound <= tolerance * std::max(1.0, std::fabs(bound))) {
        lower[static_cast<std::size_t>(j)] = true;
      }
    }
    for (int j : rows_.upper) {
      const double bound = problem_.upper[j];
      if (bound - z_[j] <= tolerance * std::max(1.0, std::fabs(bound))) {
        upper[static_cast<std::size_t>(j)] = true;
      }
    }
    SqpWorkingSet set;
    for (int i = 0; i < m; ++i) {
      if (constraint[static_cast<std::size_t>(i)]) set.inequalities.push_back(i);
    }
    for (int j = 0; j < n_; ++j) {
      if (lower[static_cast<std::size_t>(j)]) set.lower_bounds.push_back(j);
      if (upper[static_cast<std::size_t>(j)]) set.upper_bounds.push_back(j);
    }
    return set;
  }

  void StoreMultipliers(const QpSolution& qp, bool reduced, bool scaled, SqpResult* result) const {
    const int m = rows_.num_constraints;
    result->equality_multipliers = qp.equality_multipliers;
    result->inequality_multipliers = qp.inequality_multipliers.head(m);
    if (reduced && reduction_.size() > 0) {
      if (scaled) {
        result->inequality_multipliers = result->inequality_multipliers.cwiseProduct(row_scales_);
      }
      result->equality_multipliers += reduction_.transpose() * result->inequality_multipliers;
    }
    result->bound_multipliers = Vector::Zero(n_);
    int row = m;
    for (int j : rows_.lower) result->bound_multipliers[j] += qp.inequality_multipliers[row++];
    for (int j : rows_.upper) result->bound_multipliers[j] -= qp.inequality_multipliers[row++];
  }

  // max(||grad J - J_E^T y + J_I^T lambda - lambda_bounds||_inf, max_i lambda_i |slack_i|) at
  // z_ with the QP's multipliers: stationarity and complementarity of the NLP.
  double KktResidual(const SqpResult& result) const {
    Vector r = Gradient() - result.bound_multipliers;
    if (m_eq_ > 0) r -= eval_.equality_jacobian.transpose() * result.equality_multipliers;
    const int m = rows_.num_constraints;
    double complementarity = 0.0;
    if (m > 0) {
      r += eval_.inequality_jacobian.transpose() * result.inequality_multipliers;
      // A row within its tolerance of zero is active to the resolution of the feasibility
      // test: its multiplier may be positive (with an index-3 row's multiplier of order
      // 1/h^2, the product with phi's round-off would otherwise exceed any tolerance).
      for (int i = 0; i < m; ++i) {
        if (eval_.inequalities[i] >= -InequalityTolerance(i)) continue;
        complementarity = std::max(
            complementarity, result.inequality_multipliers[i] * std::fabs(eval_.inequalities[i]));
      }
    }
    for (int j = 0; j < n_; ++j) {
      const double lambda = result.bound_multipliers[j];
      const double gap = lambda > 0.0 ? z_[j] - problem_.lower[j] : problem_.upper[j] - z_[j];
      if (lambda != 0.0) complementarity = std::max(complementarity, std::fabs(lambda) * gap);
    }
    return std::max(r.lpNorm<Eigen::Infinity>(), complementarity);
  }

  const SqpProblem& problem_;
  SqpOptions options_;
  int n_;
  int m_eq_ = 0;
  RowMap rows_;
  Vector z_;
  SqpEvaluation eval_;
  // ReduceInequalities at eval_: M, [0, J_I,v - M E_v] and c_I - M c_E (empty M: not reduced).
  Matrix reduction_;
  Matrix reduced_jacobian_;
  Vector reduced_values_;
  Vector row_scales_;             // 1 / s_i of the scaled rows, else 1 (empty: not reduced)
  bool soft_equalities_ = false;  // layout of the elastic QP (see SolveElastic)
  int stalled_ = 0;               // elastic iterations without progress (see Solve)
  double previous_violation_ = std::numeric_limits<double>::infinity();
};

}  // namespace

SqpResult SolveSqp(const SqpProblem& problem, const Vector& initial_guess,
                   const SqpOptions& options) {
  return Sqp(problem, options).Solve(initial_guess);
}

}  // namespace moreau::internal
