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
    has_projection_ = set.projection_basis.size() != 0;
    if (has_projection_) projection_ = set.projection_basis * set.projection_basis.transpose();
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
    const int z0 = layout.z_offset;
    const int k0 = layout.pair_offset;
    const auto lambda = z.segment(z0, nc);
    const Matrix* projection = has_projection_ ? &projection_ : nullptr;
    // grad c is needed for the values too (x' += P grad c lambda).
    jacobian_.Jacobian(context, set_.constraints, y,
                       derivatives == Derivatives::kNone ? Derivatives::kStates : derivatives, &c_);
    // (gradient form) x' += P grad c lambda.
    jacobian_.AddStateGradientProduct(lambda, projection, out->F.head(nx));
    // complementarity pair k: a = c_k(x, t), b = lambda_k.
    out->A.segment(k0, nc) = c_;
    out->B.segment(k0, nc) = lambda;
    if (derivatives == Derivatives::kNone) return;

    // d/dy of P grad c lambda = P sum_k lambda_k Hess c_k (x rows; x, clock, u, p columns).
    hessian_.WeightedHessian(context, set_.constraints, y, lambda, derivatives);
    hessian_.AddStateRows(projection, 1.0, &out->F_y, &out->F_u, &out->F_p);
    jacobian_.AddStateGradients(z0, projection, 1.0, &out->F_z);
    jacobian_.AddRows(0, nc, 1.0, k0, &out->A_y, &out->A_u, &out->A_p);
    for (int k = 0; k < nc; ++k) out->B_z.Add(k0 + k, z0 + k, 1.0);
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

  // With x' = f + P grad c lambda the rates of the constraints are q + J P J^T lambda:
  // symmetric positive semidefinite in lambda (P = E E^T), one velocity for all solutions.
  bool MonotoneVelocityLevel() const override { return true; }
  // x' += P grad c(x, t) lambda, (c(x, t), lambda): affine in lambda.
  bool AffineInAlgebraic() const override { return true; }

  // lambda is a jump variable (it jumps at contact); there are no equations.
  std::vector<bool> ContinuousAlgebraic() const override {
    return std::vector<bool>(static_cast<std::size_t>(num_constraints_), false);
  }
  std::vector<bool> DifferentiatedEquations() const override { return {}; }

  // Continuous side c_k(x, clock): rows of d/d(y, u, p) [grad_y c_k . d] = Hess c_k d.
  void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                    const ConstVectorRef& direction, Derivatives derivatives,
                    CurvatureTerms* out) override {
    directions_.HessianDirections(context, set_.constraints, y, direction, derivatives);
    directions_.AddRows(0, num_constraints_, 1.0, layout.pair_offset, &out->pair_y, &out->pair_u,
                        &out->pair_p);
  }

  // Active constraint (c = 0 kept): its multiplier lambda (velocity level); inactive: c.
  void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                       const ConstVectorRef& v, const std::vector<bool>& a_zero,
                       Derivatives derivatives, IndicatorEvaluation* out) override {
    const int k0 = layout.pair_offset;
    const int z0 = layout.z_offset;
    jacobian_.Jacobian(context, set_.constraints, y, derivatives, &c_);
    for (int k = 0; k < num_constraints_; ++k) {
      if (a_zero[static_cast<std::size_t>(k0 + k)]) {
        out->values[k0 + k] = v[z0 + k];
        if (derivatives != Derivatives::kNone) out->d_v.Add(k0 + k, z0 + k, 1.0);
        continue;
      }
      out->values[k0 + k] = c_[k];
      if (derivatives != Derivatives::kNone) {
        jacobian_.AddRow(k, 1.0, k0 + k, &out->d_y, &out->d_u, &out->d_p);
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
  bool has_projection_ = false;
  Matrix projection_;  // P = E E^T (only with a projection basis E; P = I otherwise)
  Vector c_;
  ArgumentMatrix jacobian_, hessian_, directions_;
};

}  // namespace

std::unique_ptr<LoweredBlock> LowerMovingSet(const Scene& scene, const MovingSet& set) {
  return std::make_unique<MovingSetBlock>(scene, set);
}

}  // namespace moreau::internal
