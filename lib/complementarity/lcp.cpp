#include "moreau/complementarity/lcp.hpp"

#include "moreau/core/error.hpp"

namespace moreau {
namespace {

// Phi(z) = phi(z_i, (M z + q)_i): n pairs, no smooth equations.
class LcpSystem final : public MixedComplementaritySystem {
 public:
  LcpSystem(const Matrix& m, const Vector& q) : m_(m), q_(q) {}
  int num_unknowns() const override { return static_cast<int>(q_.size()); }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return static_cast<int>(q_.size()); }
  bool Evaluate(const Vector& z, bool, Vector* r, Vector* a, Vector* b) override {
    r->resize(0);
    *a = z;
    b->noalias() = m_ * z + q_;
    return true;
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    const int n = num_unknowns();
    if (!jacobian->sparse()) {
      Matrix block = db.asDiagonal() * m_;
      block.diagonal() += da;
      jacobian->AddBlock(0, 0, block);
      return;
    }
    for (int i = 0; i < n; ++i) {
      jacobian->AddEntry(i, i, da[i]);
      for (int j = 0; j < n; ++j) {
        if (m_(i, j) != 0.0) jacobian->AddEntry(i, j, db[i] * m_(i, j));
      }
    }
  }
  double EstimatedJacobianNonzeros() const override {
    return static_cast<double>((m_.array() != 0.0).count()) + q_.size();
  }

 private:
  const Matrix& m_;
  const Vector& q_;
};

}  // namespace

LcpResult SolveLcp(const Matrix& m, const Vector& q, const SemismoothNewtonOptions& options,
                   const Vector* initial_guess) {
  RequireArgument(m.rows() == q.size() && m.cols() == q.size(), "LCP: M must be ", q.size(), " x ",
                  q.size(), ", got ", m.rows(), " x ", m.cols());
  RequireArgument(m.allFinite() && q.allFinite(), "LCP: M and q must be finite");
  const Vector z0 = initial_guess != nullptr ? *initial_guess : Vector::Zero(q.size());
  RequireArgument(z0.size() == q.size(), "LCP: initial guess must have ", q.size(), " entries");
  LcpSystem system(m, q);
  SemismoothNewton newton(options);
  const SemismoothNewtonResult solved = newton.Solve(system, z0);
  LcpResult result;
  result.status = solved.status;
  result.message = solved.message;
  result.z = solved.solution;
  result.w = m * result.z + q;
  result.residual = 0.0;
  for (Eigen::Index i = 0; i < q.size(); ++i) {
    result.residual = std::max(result.residual, ComplementarityResidual(result.z[i], result.w[i]));
  }
  result.residual_history = solved.residual_history;
  result.stats = solved.stats;
  return result;
}

}  // namespace moreau
