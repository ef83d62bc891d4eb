// Gradient form of a moving set (docs/lowering.md, section "Moving sets"):
//   x' += P grad_x c(x, t) lambda,  P = E E^T,   0 <= c(x, t) ⟂ lambda >= 0.
// Time enters through the clock state; the clock row is not projected (E's clock row is 0),
// which is the ePDS reformulation of the sweeping process (sweeping paper, Theorem 4).

#include <Eigen/Dense>

#include "lowered_block.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {

class MovingSetBlock final : public LoweredBlock {
 public:
  MovingSetBlock(const Scene& scene, const MovingSet& set)
      : set_(set),
        num_states_(scene.num_states()),
        num_constraints_(static_cast<int>(set.constraint_names.size())) {
    RequireArgument(!set.constraints.has_sparse_state_jacobian(), "moving set '", set.name,
                    "': constraint functions need second derivatives; write them as generic "
                    "lambdas (MakeSmoothFunction), not with a hand-written Jacobian");
    projection_ = set.projection_basis.size() == 0
                      ? Matrix(Matrix::Identity(num_states_, num_states_))
                      : Matrix(set.projection_basis * set.projection_basis.transpose());
  }
  std::unique_ptr<LoweredBlock> Clone() const override {
    return std::make_unique<MovingSetBlock>(*this);
  }
  int num_algebraic() const override { return num_constraints_; }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return num_constraints_; }
  std::vector<std::string> AlgebraicNames() const override {
    std::vector<std::string> names;
    for (const std::string& c : set_.constraint_names) names.push_back(set_.name + ".lambda_" + c);
    return names;
  }
  std::vector<PairInfo> Pairs() const override {
    std::vector<PairInfo> pairs;
    for (const std::string& c : set_.constraint_names) {
      pairs.push_back({set_.name, set_.name + "." + c, ContinuousSide::kA, 0});
    }
    return pairs;
  }

  void Evaluate(const BlockContext& context, const ConstVectorRef& y, const ConstVectorRef& z,
                Derivatives derivatives, PointEvaluation* out) override {
    const int nx = num_states_;
    const int nc = num_constraints_;
    const int clock = context.clock_index;
    const int nu = static_cast<int>(context.inputs->size());
    const int np = static_cast<int>(context.parameters->size());
    const int z0 = layout.z_offset;
    const int k0 = layout.pair_offset;
    x_ = y.head(nx);
    const double t = y[clock];
    const auto lambda = z.segment(z0, nc);
    const Vector& u = *context.inputs;
    const Vector& p = *context.parameters;

    // Columns of the Jacobian/Hessian: x, [u], t, [p].
    const bool all = derivatives == Derivatives::kAll;
    const Wrt wrt = all ? Wrt::All() : Wrt::XT();
    set_.constraints.Jacobian(x_, u, t, p, wrt, &c_, &jacobian_);
    const int t_col = all ? nx + nu : nx;
    const auto jx = jacobian_.leftCols(nx);  // nc x nx: row k is grad c_k^T

    // (gradient form) x' += P grad c lambda.
    out->F.head(nx) += projection_ * (jx.transpose() * lambda);
    // complementarity pair k: a = c_k(x, t), b = lambda_k.
    out->A.segment(k0, nc) = c_;
    out->B.segment(k0, nc) = lambda;
    if (derivatives == Derivatives::kNone) return;

    // d/dy of P grad c lambda = P sum_k lambda_k Hess c_k (x and clock columns).
    set_.constraints.WeightedHessian(x_, u, t, p, wrt, lambda, &hessian_);
    out->F_y.topLeftCorner(nx, nx) += projection_ * hessian_.topLeftCorner(nx, nx);
    out->F_y.col(clock).head(nx) += projection_ * hessian_.block(0, t_col, nx, 1);
    out->F_z.block(0, z0, nx, nc) += projection_ * jx.transpose();
    out->A_y.block(k0, 0, nc, nx) = jx;
    out->A_y.block(k0, clock, nc, 1) = jacobian_.col(t_col);
    out->B_z.block(k0, z0, nc, nc).setIdentity();
    if (!all) return;
    out->F_u.topRows(nx) += projection_ * hessian_.block(0, nx, nx, nu);
    out->F_p.topRows(nx) += projection_ * hessian_.block(0, t_col + 1, nx, np);
    out->A_u.middleRows(k0, nc) = jacobian_.middleCols(nx, nu);
    out->A_p.middleRows(k0, nc) = jacobian_.rightCols(np);
  }

  // lambda from `previous` (multipliers are not determined by the state alone), else 0.
  void InitialGuess(const BlockContext&, const ConstVectorRef&, const Vector* previous,
                    VectorRef z) override {
    if (previous != nullptr) {
      z.segment(layout.z_offset, num_constraints_) =
          previous->segment(layout.z_offset, num_constraints_);
    } else {
      z.segment(layout.z_offset, num_constraints_).setZero();
    }
  }

  // lambda is a jump variable (it jumps at contact); there are no equations.
  std::vector<bool> ContinuousAlgebraic() const override {
    return std::vector<bool>(static_cast<std::size_t>(num_constraints_), false);
  }
  std::vector<bool> DifferentiatedEquations() const override { return {}; }

  // Continuous side c_k(x, clock): rows of d/d(y, u, p) [grad_y c_k . d] = Hess c_k d.
  void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                    const ConstVectorRef& direction, Derivatives derivatives,
                    CurvatureTerms* out) override {
    const int k0 = layout.pair_offset;
    for (int k = 0; k < num_constraints_; ++k) {
      AddHessianDirection(context, set_.constraints, k, y, direction, derivatives, 1.0,
                          &out->pair_y, &out->pair_u, &out->pair_p, k0 + k);
    }
  }

  // Active constraint (c = 0 kept): its multiplier lambda (velocity level); inactive: c.
  void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                       const ConstVectorRef& v, const std::vector<bool>& a_zero,
                       Derivatives derivatives, IndicatorEvaluation* out) override {
    const int nx = num_states_;
    const int nu = static_cast<int>(context.inputs->size());
    const int np = static_cast<int>(context.parameters->size());
    const int k0 = layout.pair_offset;
    const int z0 = layout.z_offset;
    const bool all = derivatives == Derivatives::kAll;
    x_ = y.head(nx);
    set_.constraints.Jacobian(x_, *context.inputs, y[context.clock_index], *context.parameters,
                              all ? Wrt::All() : Wrt::XT(), &c_, &jacobian_);
    const int t_col = all ? nx + nu : nx;
    for (int k = 0; k < num_constraints_; ++k) {
      if (a_zero[static_cast<std::size_t>(k0 + k)]) {
        out->values[k0 + k] = v[z0 + k];
        if (derivatives != Derivatives::kNone) out->d_v(k0 + k, z0 + k) = 1.0;
        continue;
      }
      out->values[k0 + k] = c_[k];
      if (derivatives == Derivatives::kNone) continue;
      out->d_y.block(k0 + k, 0, 1, nx) = jacobian_.block(k, 0, 1, nx);
      out->d_y(k0 + k, context.clock_index) = jacobian_(k, t_col);
      if (all) {
        out->d_u.row(k0 + k) = jacobian_.block(k, nx, 1, nu);
        out->d_p.row(k0 + k) = jacobian_.block(k, t_col + 1, 1, np);
      }
    }
  }

  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const override {
    std::vector<Event> events;
    for (int k = 0; k < num_constraints_; ++k) {
      const auto i = static_cast<std::size_t>(k);
      if (before[i] == after[i]) continue;
      // a = c_k = 0 means the constraint is active.
      events.push_back({t, after[i] ? EventKind::kEnter : EventKind::kLeave,
                        set_.name + "." + set_.constraint_names[i],
                        after[i] ? "constraint becomes active" : "constraint becomes inactive"});
    }
    return events;
  }

 private:
  MovingSet set_;
  int num_states_;
  int num_constraints_;
  Matrix projection_;  // P = E E^T
  Vector x_, c_;
  Matrix jacobian_, hessian_;
};

}  // namespace

std::unique_ptr<LoweredBlock> LowerMovingSet(const Scene& scene, const MovingSet& set) {
  return std::make_unique<MovingSetBlock>(scene, set);
}

}  // namespace moreau::internal
