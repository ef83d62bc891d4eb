// Gradient form of a moving set (docs/lowering.md, section "Moving sets"):
//   x' += P grad_x c(x, t) lambda,  P = E E^T,   0 <= c(x, t) ⟂ lambda >= 0.
// Time enters through the clock state; the clock row is not projected (E's clock row is 0),
// which is the ePDS reformulation of the sweeping process (sweeping paper, Theorem 4).
//
// Near-active filter (docs/sparse-systems.md): the block holds a working set of its
// constraints (all of them unless an integrator leaves some out); a left-out constraint has
// lambda = 0 and no pair, unknown or equation. Its value is still computed (the function
// evaluates all its outputs at once) but none of its derivatives.

#include <Eigen/Dense>
#include <cmath>
#include <limits>

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
    working_.resize(static_cast<std::size_t>(num_constraints_));
    for (int k = 0; k < num_constraints_; ++k) working_[static_cast<std::size_t>(k)] = k;
  }
  std::unique_ptr<LoweredBlock> Clone() const override {
    return std::make_unique<MovingSetBlock>(*this);
  }
  int num_algebraic() const override { return num_working(); }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return num_working(); }
  std::vector<std::string> AlgebraicNames() const override {
    std::vector<std::string> names;
    for (int k : working_) names.push_back(LambdaName(k));
    return names;
  }
  std::vector<std::string> DeclaredAlgebraicNames() const override {
    std::vector<std::string> names;
    for (int k = 0; k < num_constraints_; ++k) names.push_back(LambdaName(k));
    return names;
  }
  std::vector<PairInfo> Pairs() const override {
    std::vector<PairInfo> pairs;
    for (int k : working_) {
      pairs.push_back({set_.name,
                       set_.name + "." + set_.constraint_names[static_cast<std::size_t>(k)],
                       ContinuousSide::kA, 0});
    }
    return pairs;
  }

  // --- near-active filter ------------------------------------------------------------------
  int num_declared_pairs() const override { return num_constraints_; }
  bool Filterable() const override { return true; }
  std::vector<int> WorkingPairs() const override { return working_; }
  void SetWorkingPairs(const std::vector<int>& working) override {
    // lambda_ is zero outside the working set (ScatterMultipliers): clear the leaving entries.
    if (!lambda_full_ && lambda_.size() == num_constraints_) {
      for (int k : working_) lambda_[k] = 0.0;
    }
    working_ = working;
    all_working_ = num_working() == num_constraints_;
  }

  // c_k(y) and |grad_x c_k|_1 max |x'| + |dc_k/dt| for every constraint.
  void DeclaredConstraints(const BlockContext& context, const ConstVectorRef& y,
                           const Vector& velocity, VectorRef values,
                           VectorRef rate_bounds) override {
    all_.Jacobian(context, set_.constraints, y, Derivatives::kStates, &c_);
    values = c_;
    const double speed = velocity.head(num_states_).lpNorm<Eigen::Infinity>();
    for (int k = 0; k < num_constraints_; ++k) {
      rate_bounds[k] = all_.StateRowNorm1(k) * speed + std::fabs(all_.TimeEntry(k));
    }
  }
  double MinExcluded(const BlockContext& context, const ConstVectorRef& y) override {
    if (all_working_) return std::numeric_limits<double>::infinity();
    EvaluateValues(context, y);
    double smallest = std::numeric_limits<double>::infinity();
    std::size_t next = 0;
    for (int k = 0; k < num_constraints_; ++k) {
      if (next < working_.size() && working_[next] == k) {
        ++next;
        continue;
      }
      smallest = std::min(smallest, c_[k]);
    }
    return smallest;
  }
  void ExcludedBelow(const BlockContext& context, const ConstVectorRef& y, double threshold,
                     int offset, std::vector<bool>* include) override {
    if (all_working_) return;
    EvaluateValues(context, y);
    std::size_t next = 0;
    for (int k = 0; k < num_constraints_; ++k) {
      if (next < working_.size() && working_[next] == k) {
        ++next;
        continue;
      }
      if (!(c_[k] >= threshold)) (*include)[static_cast<std::size_t>(offset + k)] = true;
    }
  }

  void Evaluate(const BlockContext& context, const ConstVectorRef& y, const ConstVectorRef& z,
                Derivatives derivatives, PointEvaluation* out) override {
    const int nx = num_states_;
    const int nw = num_working();
    const int z0 = layout.z_offset;
    const int k0 = layout.pair_offset;
    const Matrix* projection = has_projection_ ? &projection_ : nullptr;
    // Multipliers of every constraint (zero for those left out).
    ScatterMultipliers(z.segment(z0, nw));
    // complementarity pair k: a = c_k(x, t), b = lambda_k.
    auto set_pairs = [&] {
      for (int j = 0; j < nw; ++j) out->A[k0 + j] = c_[working_[static_cast<std::size_t>(j)]];
      out->B.segment(k0, nw) = z.segment(z0, nw);
    };
    if (derivatives == Derivatives::kNone && !context.sparse && all_working_ &&
        z.segment(z0, nw).isZero(0.0)) {
      // Values without a pushing constraint (every smooth element's certificate): P grad c
      // lambda is zero, so c's values suffice, without its gradient (a Jacobian pass of dual
      // numbers). Dense storage without a filter only: with a filter the gradient path below
      // evaluates the working rows alone, where values would be evaluated for every declared
      // constraint; and sparse Jacobians keep their storage sized by the calls they serve
      // (skipping some made later ones reallocate: the crowd's steps in allocation_tests).
      jacobian_.Jacobian(context, set_.constraints, y, Derivatives::kNone, &c_, nullptr);
      set_pairs();
      return;
    }
    // grad c is needed for the values too (x' += P grad c lambda); only the working rows.
    jacobian_.Jacobian(context, set_.constraints, y,
                       derivatives == Derivatives::kNone ? Derivatives::kStates : derivatives, &c_,
                       rows());
    // (gradient form) x' += P grad c lambda.
    jacobian_.AddStateGradientProduct(lambda_, projection, out->F.head(nx), rows());
    set_pairs();
    if (derivatives == Derivatives::kNone) return;

    // d/dy of P grad c lambda = P sum_k lambda_k Hess c_k (x rows; x, clock, u, p columns),
    // summed over the constraints with lambda_k != 0: the same values, and with sparse storage
    // a pattern that couples only states of pushing constraints. (Inactive constraints of an
    // element system, held at lambda = 0 by their status rows, would otherwise couple every
    // pair of neighbours and fill the sparse LU; the pattern changes when a multiplier becomes
    // zero or nonzero, i.e. at switches.)
    pushing_.clear();
    for (int k : working_) {
      if (lambda_[k] != 0.0) pushing_.push_back(k);
    }
    hessian_.WeightedHessian(context, set_.constraints, y, lambda_, derivatives,
                             context.sparse ? &pushing_ : rows());
    hessian_.AddStateRows(projection, 1.0, &out->F_y, &out->F_u, &out->F_p);
    for (int j = 0; j < nw; ++j) {
      const int k = working_[static_cast<std::size_t>(j)];
      jacobian_.AddStateGradient(k, z0 + j, projection, &out->F_z);
      jacobian_.AddRow(k, 1.0, k0 + j, &out->A_y, &out->A_u, &out->A_p);
      out->B_z.Add(k0 + j, z0 + j, 1.0);
    }
  }

  // lambda from `previous` (multipliers are not determined by the state alone), else 0.
  void InitialGuess(const BlockContext&, const ConstVectorRef&, const Vector* previous,
                    VectorRef z) override {
    if (previous != nullptr) {
      z.segment(layout.z_offset, num_working()) = previous->segment(layout.z_offset, num_working());
    } else {
      z.segment(layout.z_offset, num_working()).setZero();
    }
  }

  // With x' = f + P grad c lambda the rates of the constraints are q + J P J^T lambda:
  // symmetric positive semidefinite in lambda (P = E E^T), one velocity for all solutions.
  bool MonotoneVelocityLevel() const override { return true; }
  // x' += P grad c(x, t) lambda, (c(x, t), lambda): affine in lambda.
  bool AffineInAlgebraic() const override { return true; }

  // lambda is a jump variable (it jumps at contact); there are no equations.
  std::vector<bool> ContinuousAlgebraic() const override {
    return std::vector<bool>(static_cast<std::size_t>(num_working()), false);
  }
  std::vector<bool> DifferentiatedEquations() const override { return {}; }

  // Continuous side c_k(x, clock): rows of d/d(y, u, p) [grad_y c_k . d] = Hess c_k d.
  void AddCurvature(const BlockContext& context, const ConstVectorRef& y,
                    const ConstVectorRef& direction, Derivatives derivatives,
                    CurvatureTerms* out) override {
    directions_.HessianDirections(context, set_.constraints, y, direction, derivatives, rows());
    for (int j = 0; j < num_working(); ++j) {
      directions_.AddRow(working_[static_cast<std::size_t>(j)], 1.0, layout.pair_offset + j,
                         &out->pair_y, &out->pair_u, &out->pair_p);
    }
  }

  // Active constraint (c = 0 kept): its multiplier lambda (velocity level); inactive: c.
  void EventIndicators(const BlockContext& context, const ConstVectorRef& y,
                       const ConstVectorRef& v, const std::vector<bool>& a_zero,
                       Derivatives derivatives, IndicatorEvaluation* out) override {
    const int k0 = layout.pair_offset;
    const int z0 = layout.z_offset;
    jacobian_.Jacobian(context, set_.constraints, y, derivatives, &c_, rows());
    for (int j = 0; j < num_working(); ++j) {
      const int k = working_[static_cast<std::size_t>(j)];
      if (a_zero[static_cast<std::size_t>(k0 + j)]) {
        out->values[k0 + j] = v[z0 + j];
        if (derivatives != Derivatives::kNone) out->d_v.Add(k0 + j, z0 + j, 1.0);
        continue;
      }
      out->values[k0 + j] = c_[k];
      if (derivatives != Derivatives::kNone) {
        jacobian_.AddRow(k, 1.0, k0 + j, &out->d_y, &out->d_u, &out->d_p);
      }
    }
  }

  // Inactive constraint: c_k over the box (only the inactive working constraints' rows).
  void IndicatorBounds(const BlockContext& context, const ConstVectorRef& y_lower,
                       const ConstVectorRef& y_upper, const std::vector<bool>& a_zero,
                       VectorRef lower, VectorRef upper) override {
    const int k0 = layout.pair_offset;
    bound_rows_.clear();
    bound_rows_.reserve(static_cast<std::size_t>(num_constraints_));  // once: no allocation later
    for (int j = 0; j < num_working(); ++j) {
      if (!a_zero[static_cast<std::size_t>(k0 + j)]) {
        bound_rows_.push_back(working_[static_cast<std::size_t>(j)]);
      }
    }
    if (bound_rows_.empty()) return;
    if (!FunctionBounds(context, set_.constraints, y_lower, y_upper, &bound_lower_, &bound_upper_,
                        &bound_rows_)) {
      return;
    }
    for (int j = 0; j < num_working(); ++j) {
      if (a_zero[static_cast<std::size_t>(k0 + j)]) continue;
      const int k = working_[static_cast<std::size_t>(j)];
      lower[k0 + j] = bound_lower_[k];
      upper[k0 + j] = bound_upper_[k];
    }
  }

  std::vector<Event> StatusEvents(double t, const std::vector<bool>& before,
                                  const std::vector<bool>& after) const override {
    std::vector<Event> events;
    for (int j = 0; j < num_working(); ++j) {
      const auto i = static_cast<std::size_t>(j);
      if (before[i] == after[i]) continue;
      // a = c_k = 0 means the constraint is active.
      const std::string& name = set_.constraint_names[static_cast<std::size_t>(working_[i])];
      events.push_back({t, after[i] ? EventKind::kEnter : EventKind::kLeave, set_.name + "." + name,
                        after[i] ? "constraint becomes active" : "constraint becomes inactive"});
    }
    return events;
  }

 private:
  int num_working() const { return static_cast<int>(working_.size()); }
  // The rows to differentiate: all (nullptr) or the working set.
  const std::vector<int>* rows() const { return all_working_ ? nullptr : &working_; }
  std::string LambdaName(int k) const {
    return set_.name + ".lambda_" + set_.constraint_names[static_cast<std::size_t>(k)];
  }
  // Working-set multipliers into lambda_, a vector over every constraint, zero outside the
  // working set: SetWorkingPairs clears the entries of a set that leaves, so an evaluation
  // writes only the working entries (zeroing all declared constraints per evaluation was
  // O(declared), 1 MB per call for the crowd of 10^4).
  void ScatterMultipliers(const ConstVectorRef& working_values) {
    if (all_working_) {
      lambda_ = working_values;
      lambda_full_ = true;
      return;
    }
    if (lambda_full_ || lambda_.size() != num_constraints_) lambda_.setZero(num_constraints_);
    lambda_full_ = false;
    for (std::size_t j = 0; j < working_.size(); ++j) {
      lambda_[working_[j]] = working_values[static_cast<Eigen::Index>(j)];
    }
  }
  void EvaluateValues(const BlockContext& context, const ConstVectorRef& y) {
    x_ = y.head(num_states_);
    set_.constraints.Evaluate(x_, *context.inputs, y[context.clock_index], *context.parameters,
                              &c_);
  }

  MovingSet set_;
  int num_states_;
  int num_constraints_;
  std::vector<int> working_;          // constraints in the system, increasing
  Vector bound_lower_, bound_upper_;  // IndicatorBounds' enclosures of c
  std::vector<int> bound_rows_;       // IndicatorBounds' rows: the inactive working ones
  std::vector<int> pushing_;          // working constraints with lambda != 0 (scratch)
  bool all_working_ = true;
  bool has_projection_ = false;
  Matrix projection_;  // P = E E^T (only with a projection basis E; P = I otherwise)
  Vector c_, x_, lambda_;
  // lambda_ was last written whole (every constraint working): it may be nonzero anywhere.
  bool lambda_full_ = true;
  ArgumentMatrix jacobian_, hessian_, directions_, all_;
};

}  // namespace

std::unique_ptr<LoweredBlock> LowerMovingSet(const Scene& scene, const MovingSet& set) {
  return std::make_unique<MovingSetBlock>(scene, set);
}

}  // namespace moreau::internal
