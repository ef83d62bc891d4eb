#include "active_set_qp.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/QR>
#include <cmath>
#include <limits>

#include "moreau/core/error.hpp"

namespace moreau::internal {

const char* ToString(QpStatus status) {
  switch (status) {
    case QpStatus::kOptimal:
      return "optimal";
    case QpStatus::kInfeasible:
      return "infeasible";
    case QpStatus::kDependentEqualities:
      return "inconsistent dependent equalities";
    case QpStatus::kIterationLimit:
      return "iteration limit";
    case QpStatus::kNotConvex:
      return "Hessian not positive definite";
  }
  return "?";
}

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// A constraint in the active set: normal n = sign * (row of A_eq or A_in), rhs = sign * b.
// Equalities get sign -1 when they are added from the side n^T x > b, so that every added
// constraint is approached from its violated side n^T x < b as in the inequality case.
struct ActiveConstraint {
  bool equality = false;
  int row = 0;
  double sign = 1.0;
};

class GoldfarbIdnani {
 public:
  GoldfarbIdnani(const DenseQp& qp, const QpOptions& options)
      : qp_(qp),
        options_(options),
        n_(static_cast<int>(qp.gradient.size())),
        m_eq_(static_cast<int>(qp.equality_matrix.rows())),
        m_in_(static_cast<int>(qp.inequality_matrix.rows())) {
    MOREAU_ASSERT(qp.hessian.rows() == n_ && qp.hessian.cols() == n_, "QP Hessian size");
    MOREAU_ASSERT(m_eq_ == 0 || qp.equality_matrix.cols() == n_, "QP equality matrix size");
    MOREAU_ASSERT(m_in_ == 0 || qp.inequality_matrix.cols() == n_, "QP inequality matrix size");
    MOREAU_ASSERT(qp.equality_rhs.size() == m_eq_ && qp.inequality_rhs.size() == m_in_,
                  "QP right-hand side sizes");
  }

  QpSolution Solve() {
    QpSolution solution;
    const Eigen::LLT<Matrix> llt(qp_.hessian);
    if (llt.info() != Eigen::Success || !qp_.hessian.allFinite()) {
      solution.status = QpStatus::kNotConvex;
      return solution;
    }
    l_ = llt.matrixL();
    // Unconstrained minimizer x = -G^{-1} g: optimal for the empty active set.
    x_ = llt.solve(-qp_.gradient);
    const int limit =
        options_.max_iterations > 0 ? options_.max_iterations : 10 * (n_ + m_eq_ + m_in_) + 10;
    in_active_.assign(static_cast<std::size_t>(m_in_), false);
    int next_equality = 0;
    int iterations = 0;
    QpStatus status = QpStatus::kOptimal;
    while (true) {
      if (iterations > limit) {
        status = QpStatus::kIterationLimit;
        break;
      }
      // Step 1: pick the constraint to add. Equalities first (in order, whatever their
      // residual), then the most violated inequality (residual relative to its normal).
      ActiveConstraint p;
      if (next_equality < m_eq_) {
        p = {true, next_equality++, 1.0};
        if (Slack(p) > 0.0) p.sign = -1.0;
      } else {
        int worst = -1;
        double worst_score = 0.0;
        for (int i = 0; i < m_in_; ++i) {
          if (in_active_[static_cast<std::size_t>(i)]) continue;
          const ActiveConstraint candidate{false, i, 1.0};
          const double s = Slack(candidate);
          if (s >= -ViolationTolerance(candidate)) continue;
          const double norm = qp_.inequality_matrix.row(i).norm();
          const double score = s / std::max(norm, std::numeric_limits<double>::min());
          if (score < worst_score) {
            worst_score = score;
            worst = i;
          }
        }
        if (worst < 0) break;  // primal feasible: optimal
        p = {false, worst, 1.0};
      }
      const QpStatus step = AddConstraint(p, &iterations, limit);
      if (step != QpStatus::kOptimal) {
        status = step;
        break;
      }
    }
    if (status == QpStatus::kOptimal) Polish();
    solution.status = status;
    solution.x = x_;
    solution.iterations = iterations;
    solution.equality_multipliers = Vector::Zero(m_eq_);
    solution.inequality_multipliers = Vector::Zero(m_in_);
    for (std::size_t j = 0; j < active_.size(); ++j) {
      const ActiveConstraint& a = active_[j];
      if (a.equality) {
        solution.equality_multipliers[a.row] = a.sign * u_[static_cast<Eigen::Index>(j)];
      } else {
        solution.inequality_multipliers[a.row] = u_[static_cast<Eigen::Index>(j)];
        solution.active_inequalities.push_back(a.row);
      }
    }
    return solution;
  }

 private:
  Vector Normal(const ActiveConstraint& a) const {
    return a.sign * (a.equality ? qp_.equality_matrix.row(a.row).transpose()
                                : qp_.inequality_matrix.row(a.row).transpose());
  }
  double Rhs(const ActiveConstraint& a) const {
    return a.sign * (a.equality ? qp_.equality_rhs[a.row] : qp_.inequality_rhs[a.row]);
  }
  // s = n^T x - rhs (>= 0 satisfied for inequalities).
  double Slack(const ActiveConstraint& a) const { return Normal(a).dot(x_) - Rhs(a); }
  double ViolationTolerance(const ActiveConstraint& a) const {
    const Vector normal = Normal(a);
    const double scale = std::max({1.0, std::fabs(Rhs(a)), normal.cwiseAbs().dot(x_.cwiseAbs())});
    return options_.feasibility_tolerance * scale;
  }

  // Factorizes L^{-1} N = Q R for the current active normals N (n x k).
  void Factorize() {
    const int k = static_cast<int>(active_.size());
    Matrix normals(n_, k);
    for (int j = 0; j < k; ++j) normals.col(j) = Normal(active_[static_cast<std::size_t>(j)]);
    if (k == 0) {
      q_ = Matrix::Identity(n_, n_);
      r_.resize(0, 0);
      return;
    }
    const Matrix l_inverse_normals = l_.triangularView<Eigen::Lower>().solve(normals);
    qr_.compute(l_inverse_normals);
    q_ = qr_.householderQ();
    r_ = qr_.matrixQR().topLeftCorner(k, k).triangularView<Eigen::Upper>();
  }

  // Step 2 of Goldfarb-Idnani for the constraint p: primal step along z = H n_p, dual step
  // along (-r, 1) with r = N* n_p, until p is added (full step) or an active inequality is
  // dropped (partial step) and the direction is recomputed.
  QpStatus AddConstraint(const ActiveConstraint& p, int* iterations, int limit) {
    const Vector np = Normal(p);
    double u_p = 0.0;  // multiplier of p, grows with the dual steps
    while (true) {
      if (*iterations > limit) return QpStatus::kIterationLimit;
      Factorize();
      const int k = static_cast<int>(active_.size());
      const Vector w = l_.triangularView<Eigen::Lower>().solve(np);
      const Vector d = q_.transpose() * w;
      const Vector d1 = d.head(k);
      const Vector d2 = d.tail(n_ - k);
      const double outside = d2.norm();
      const bool dependent = outside <= options_.dependence_tolerance * w.norm();
      // z = L^{-T} (w - Q1 d1) = L^{-T} Q2 d2 (w = Q d): the primal direction in the null space
      // of the active normals, formed from d2. The difference w - Q1 d1 would cancel to the
      // round-off of |w| where |d2| << |w| (an index-2 constraint over a short step: the x part
      // of its normal weighs h against the objective's weights), leaving z = 0 and the QP
      // "infeasible".
      Vector z = Vector::Zero(n_);
      if (!dependent) {
        z = l_.transpose().triangularView<Eigen::Upper>().solve(Vector(q_.rightCols(n_ - k) * d2));
      }
      const Vector r = k > 0 ? Vector(r_.triangularView<Eigen::Upper>().solve(d1)) : Vector();
      const double s = Slack(p);
      if (p.equality && dependent && std::fabs(s) <= ViolationTolerance(p)) {
        return QpStatus::kOptimal;  // a consistent, redundant equality: nothing to add
      }
      // Partial step: the largest t keeping the active inequality multipliers >= 0.
      double t1 = kInfinity;
      int drop = -1;
      for (int j = 0; j < k; ++j) {
        if (active_[static_cast<std::size_t>(j)].equality || r[j] <= 0.0) continue;
        const double ratio = u_[j] / r[j];
        if (ratio < t1) {
          t1 = ratio;
          drop = j;
        }
      }
      // Full step: the t that makes p active (z^T n_p = d2^T Q2^T L^{-1} n_p = |d2|^2 > 0,
      // taken in that form for the same reason as z).
      const double t2 = dependent ? kInfinity : -s / d2.squaredNorm();
      const double t = std::min(t1, t2);
      if (t == kInfinity) {
        return p.equality ? QpStatus::kDependentEqualities : QpStatus::kInfeasible;
      }
      if (k > 0) u_ -= t * r;
      u_p += t;
      if (t2 != kInfinity) x_ += t * z;
      ++*iterations;
      if (t2 <= t1) {
        active_.push_back(p);
        if (!p.equality) in_active_[static_cast<std::size_t>(p.row)] = true;
        u_.conservativeResize(k + 1);
        u_[k] = u_p;
        return QpStatus::kOptimal;
      }
      Drop(drop);
    }
  }

  // Recomputes x and the multipliers of the final active set from its KKT system
  //   [ G  -N ] [x]   [-g]
  //   [ N^T 0 ] [u] = [ b]
  // by a pivoted LU. The iterates of the dual method accumulate steps along G^{-1}-sized
  // directions, which loses about log10(cond G) digits when G is badly scaled (the stepper
  // weights x by 1e-8 against u); the KKT matrix itself is well conditioned when the active
  // normals are. The polished point replaces the iterate if it is still optimal: dual
  // feasible and primal feasible for the inactive rows.
  void Polish() {
    const int k = static_cast<int>(active_.size());
    if (k == 0) return;
    Matrix kkt = Matrix::Zero(n_ + k, n_ + k);
    Vector rhs(n_ + k);
    kkt.topLeftCorner(n_, n_) = qp_.hessian;
    rhs.head(n_) = -qp_.gradient;
    for (int j = 0; j < k; ++j) {
      const ActiveConstraint& a = active_[static_cast<std::size_t>(j)];
      const Vector normal = Normal(a);
      kkt.block(0, n_ + j, n_, 1) = -normal;
      kkt.block(n_ + j, 0, 1, n_) = normal.transpose();
      rhs[n_ + j] = Rhs(a);
    }
    const Eigen::FullPivLU<Matrix> lu(kkt);
    if (!lu.isInvertible()) return;
    const Vector solution = lu.solve(rhs);
    if (!solution.allFinite()) return;
    const Vector x = solution.head(n_), u = solution.tail(k);
    const double multiplier_scale = std::max(1.0, u_.cwiseAbs().maxCoeff());
    for (int j = 0; j < k; ++j) {
      if (!active_[static_cast<std::size_t>(j)].equality &&
          u[j] < -options_.feasibility_tolerance * multiplier_scale) {
        return;
      }
    }
    const Vector previous = x_;
    x_ = x;
    for (int i = 0; i < m_in_; ++i) {
      const ActiveConstraint row{false, i, 1.0};
      if (!in_active_[static_cast<std::size_t>(i)] && Slack(row) < -ViolationTolerance(row)) {
        x_ = previous;
        return;
      }
    }
    u_ = u.cwiseMax(0.0);
    for (int j = 0; j < k; ++j) {
      if (active_[static_cast<std::size_t>(j)].equality) u_[j] = u[j];
    }
  }

  void Drop(int j) {
    const ActiveConstraint a = active_[static_cast<std::size_t>(j)];
    if (!a.equality) in_active_[static_cast<std::size_t>(a.row)] = false;
    active_.erase(active_.begin() + j);
    const int k = static_cast<int>(u_.size());
    Vector kept(k - 1);
    kept << u_.head(j), u_.tail(k - 1 - j);
    u_ = kept;
  }

  const DenseQp& qp_;
  QpOptions options_;
  int n_, m_eq_, m_in_;
  Matrix l_;
  Vector x_;
  std::vector<ActiveConstraint> active_;
  std::vector<bool> in_active_;
  Vector u_;
  Eigen::HouseholderQR<Matrix> qr_;
  Matrix q_;
  Matrix r_;
};

}  // namespace

QpSolution SolveQp(const DenseQp& qp, const QpOptions& options) {
  return GoldfarbIdnani(qp, options).Solve();
}

}  // namespace moreau::internal
