// The velocity-level problem of a lowered system (docs/fesd-formulation.md): consistent
// algebraic values for given statuses, event indicators, and the status decision at
// switching points (slow solution).

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <sstream>

#include "lowered_block.hpp"
#include "moreau/core/error.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau {

namespace internal {

void AddHessianDirection(const BlockContext& context, const SmoothFunction& function, int k,
                         const ConstVectorRef& y, const ConstVectorRef& direction,
                         Derivatives derivatives, double weight, Matrix* dy, Matrix* du, Matrix* dp,
                         int row) {
  const int nx = context.num_scene_states;
  const int nu = static_cast<int>(context.inputs->size());
  const int np = static_cast<int>(context.parameters->size());
  const int clock = context.clock_index;
  const bool all = derivatives == Derivatives::kAll;
  const Wrt wrt = all ? Wrt::All() : Wrt::XT();
  Vector weights = Vector::Zero(function.num_outputs());
  weights[k] = 1.0;
  Matrix hessian;
  function.WeightedHessian(y.head(nx), *context.inputs, y[clock], *context.parameters, wrt, weights,
                           &hessian);
  // Direction in the Hessian's columns (x, [u], t, [p]): x and clock components only.
  const int t_col = all ? nx + nu : nx;
  Vector d = Vector::Zero(hessian.cols());
  d.head(nx) = direction.head(nx);
  d[t_col] = direction[clock];
  const Vector hd = hessian * d;
  dy->block(row, 0, 1, nx) += weight * hd.head(nx).transpose();
  (*dy)(row, clock) += weight * hd[t_col];
  if (!all) return;
  du->row(row) += weight * hd.segment(nx, nu).transpose();
  dp->row(row) += weight * hd.segment(t_col + 1, np).transpose();
}

}  // namespace internal

std::vector<PairRole> LoweredSystem::RolesFor(const std::vector<bool>& a_zero) {
  std::vector<PairRole> roles;
  roles.reserve(a_zero.size());
  for (bool a : a_zero) roles.push_back(a ? PairRole::kAZero : PairRole::kBZero);
  return roles;
}

void LoweredSystem::EvaluateVelocityLevel(const ConstVectorRef& y, const ConstVectorRef& v,
                                          const std::vector<PairRole>& roles,
                                          Derivatives derivatives,
                                          VelocityLevelEvaluation* out) const {
  MOREAU_ASSERT(static_cast<int>(roles.size()) == num_pairs_, "wrong number of pair roles");
  MOREAU_ASSERT(!sparse_dynamics_ || num_algebraic_ == 0, "velocity level needs dense Jacobians");
  const int ny = num_states_, nz = num_algebraic_, ng = num_equations_;
  const int nu = scene_.num_inputs(), np = scene_.num_parameters();
  const bool with_y = derivatives != Derivatives::kNone;
  const bool all = derivatives == Derivatives::kAll;
  PointEvaluation e;
  EvaluatePoint(y, v, all ? Derivatives::kAll : Derivatives::kStates, &roles, &e);

  // Rates of continuous variables sit in v's continuous slots; jump variables are values.
  Vector mask(nz);
  for (int i = 0; i < nz; ++i)
    mask[i] = continuous_algebraic_[static_cast<std::size_t>(i)] ? 1.0 : 0.0;
  const Vector rates = mask.cwiseProduct(v);
  CurvatureTerms curvature;
  if (with_y) {
    curvature.pair_y.setZero(num_pairs_, ny);
    curvature.equation_y.setZero(ng, ny);
    curvature.pair_u.setZero(num_pairs_, nu);
    curvature.equation_u.setZero(ng, nu);
    curvature.pair_p.setZero(num_pairs_, np);
    curvature.equation_p.setZero(ng, np);
    internal::BlockContext context{scene_.num_states(), clock_index(), &inputs_, &parameters_};
    context.velocity_roles = &roles;
    context.velocity = &v;
    for (const auto& block : blocks_) block->AddCurvature(context, y, e.F, derivatives, &curvature);
  }

  int num_complementary = 0;
  for (PairRole role : roles) num_complementary += role == PairRole::kComplementary ? 1 : 0;
  const int rows = ng + num_pairs_ - num_complementary;
  out->equations.resize(rows);
  out->a.resize(num_complementary);
  out->b.resize(num_complementary);
  out->equations_v.setZero(rows, nz);
  out->a_v.setZero(num_complementary, nz);
  out->b_v.setZero(num_complementary, nz);
  if (with_y) {
    out->equations_y.setZero(rows, ny);
    out->a_y.setZero(num_complementary, ny);
    out->b_y.setZero(num_complementary, ny);
  }
  if (all) {
    out->equations_u.setZero(rows, nu);
    out->a_u.setZero(num_complementary, nu);
    out->b_u.setZero(num_complementary, nu);
    out->equations_p.setZero(rows, np);
    out->a_p.setZero(num_complementary, np);
    out->b_p.setZero(num_complementary, np);
  }
  // A velocity-level quantity with its derivatives, written into row `row` of a target.
  struct Row {
    double value = 0.0;
    Eigen::RowVectorXd d_v, d_y, d_u, d_p;
  };
  auto write = [&](const Row& r, int row, Vector* value, Matrix* dv, Matrix* dy, Matrix* du,
                   Matrix* dp) {
    (*value)[row] = r.value;
    dv->row(row) = r.d_v;
    if (with_y) dy->row(row) = r.d_y;
    if (all) {
      du->row(row) = r.d_u;
      dp->row(row) = r.d_p;
    }
  };
  // Rate of a continuous quantity X: X_y F + X_z v_c (X_z touches continuous slots only).
  auto rate = [&](const auto& x_y, const auto& x_z, const auto& c_y, const auto& c_u,
                  const auto& c_p, const auto& x_u, const auto& x_p) {
    Row r;
    r.value = x_y.dot(e.F) + x_z.dot(rates);
    r.d_v = x_y * e.F_z + x_z.cwiseProduct(mask.transpose());
    if (with_y) r.d_y = c_y + x_y * e.F_y;
    if (all) {
      r.d_u = c_u + x_y * e.F_u + x_u;
      r.d_p = c_p + x_y * e.F_p + x_p;
    }
    return r;
  };
  // Value of a jump quantity X at (y, v).
  auto value = [&](double x, const auto& x_y, const auto& x_z, const auto& x_u, const auto& x_p) {
    Row r;
    r.value = x;
    r.d_v = x_z;
    if (with_y) r.d_y = x_y;
    if (all) {
      r.d_u = x_u;
      r.d_p = x_p;
    }
    return r;
  };
  const Eigen::RowVectorXd zero_u = Eigen::RowVectorXd::Zero(nu);
  const Eigen::RowVectorXd zero_p = Eigen::RowVectorXd::Zero(np);
  const Eigen::RowVectorXd zero_y = Eigen::RowVectorXd::Zero(ny);
  // Equations G: differentiated rows G_y F + G_z v_c; value rows G.
  for (int r = 0; r < ng; ++r) {
    Row row;
    if (differentiated_[static_cast<std::size_t>(r)]) {
      // d/du, d/dp of G_y F: curvature plus G_y F_u (G_u enters only through G_y's u-dependence).
      row = rate(e.G_y.row(r), e.G_z.row(r),
                 with_y ? Eigen::RowVectorXd(curvature.equation_y.row(r)) : zero_y,
                 with_y ? Eigen::RowVectorXd(curvature.equation_u.row(r)) : zero_u,
                 with_y ? Eigen::RowVectorXd(curvature.equation_p.row(r)) : zero_p, zero_u, zero_p);
    } else {
      row =
          value(e.G[r], e.G_y.row(r), e.G_z.row(r), all ? Eigen::RowVectorXd(e.G_u.row(r)) : zero_u,
                all ? Eigen::RowVectorXd(e.G_p.row(r)) : zero_p);
    }
    write(row, r, &out->equations, &out->equations_v, &out->equations_y, &out->equations_u,
          &out->equations_p);
  }
  int equation_row = ng, complementary_row = 0;
  for (int k = 0; k < num_pairs_; ++k) {
    const ContinuousSide side = pairs_[static_cast<std::size_t>(k)].continuous;
    const bool continuous_a = side != ContinuousSide::kB;
    // Continuous side X and jump side J of pair k. The rate X_y F + X_z v_c depends on u and
    // p through X_y (curvature terms) and F; blocks whose X_z is not constant add its
    // derivatives to the curvature terms. With both sides continuous (kBoth) the "jump" row is
    // the rate of b, an algebraic unknown: its slot v_j.
    const Matrix& x_y = continuous_a ? e.A_y : e.B_y;
    const Matrix& x_z = continuous_a ? e.A_z : e.B_z;
    const Vector& j_value = continuous_a ? e.B : e.A;
    const Matrix& j_y = continuous_a ? e.B_y : e.A_y;
    const Matrix& j_z = continuous_a ? e.B_z : e.A_z;
    const Row continuous_rate =
        rate(x_y.row(k), x_z.row(k), with_y ? Eigen::RowVectorXd(curvature.pair_y.row(k)) : zero_y,
             with_y ? Eigen::RowVectorXd(curvature.pair_u.row(k)) : zero_u,
             with_y ? Eigen::RowVectorXd(curvature.pair_p.row(k)) : zero_p, zero_u, zero_p);
    const Row jump =
        side == ContinuousSide::kBoth
            ? rate(e.B_y.row(k), e.B_z.row(k), zero_y, zero_u, zero_p, zero_u, zero_p)
            : value(j_value[k], j_y.row(k), j_z.row(k),
                    all ? Eigen::RowVectorXd((continuous_a ? e.B_u : e.A_u).row(k)) : zero_u,
                    all ? Eigen::RowVectorXd((continuous_a ? e.B_p : e.A_p).row(k)) : zero_p);
    const PairRole role = roles[static_cast<std::size_t>(k)];
    if (role == PairRole::kComplementary) {
      write(jump, complementary_row, &out->a, &out->a_v, &out->a_y, &out->a_u, &out->a_p);
      write(continuous_rate, complementary_row, &out->b, &out->b_v, &out->b_y, &out->b_u,
            &out->b_p);
      ++complementary_row;
      continue;
    }
    // The kept side: its rate if continuous, its value if a jump variable.
    const bool keeps_a = role == PairRole::kAZero;
    const Row& kept = keeps_a == continuous_a ? continuous_rate : jump;
    write(kept, equation_row++, &out->equations, &out->equations_v, &out->equations_y,
          &out->equations_u, &out->equations_p);
  }
}

void LoweredSystem::EvaluateEventIndicators(const ConstVectorRef& y, const ConstVectorRef& v,
                                            const std::vector<bool>& a_zero,
                                            Derivatives derivatives,
                                            IndicatorEvaluation* out) const {
  MOREAU_ASSERT(static_cast<int>(a_zero.size()) == num_pairs_, "wrong number of statuses");
  out->values.setZero(num_pairs_);
  if (derivatives != Derivatives::kNone) {
    out->d_y.setZero(num_pairs_, num_states_);
    out->d_v.setZero(num_pairs_, num_algebraic_);
    out->d_u.setZero(num_pairs_, scene_.num_inputs());
    out->d_p.setZero(num_pairs_, scene_.num_parameters());
  }
  internal::BlockContext context{scene_.num_states(), clock_index(), &inputs_, &parameters_};
  for (const auto& block : blocks_) {
    block->EventIndicators(context, y, v, a_zero, derivatives, out);
  }
}

namespace {

// Velocity-level problem as a mixed complementarity system in v (roles fixed).
class VelocitySystem final : public MixedComplementaritySystem {
 public:
  VelocitySystem(const LoweredSystem& system, const Vector& y, std::vector<PairRole> roles)
      : system_(system), y_(y), roles_(std::move(roles)) {
    for (PairRole role : roles_) complementary_ += role == PairRole::kComplementary ? 1 : 0;
    // Row scales from the data: the rows are affine in v, and their values at v = 0 (the
    // free velocities grad c . f + c_t) set the size of their terms. Stiff dynamics (|f| ~
    // 1e5) make an absolute tolerance of 1e-12 unreachable in double precision; relative to
    // the data it is (hard-case suite: stiff set).
    system_.EvaluateVelocityLevel(y_, Vector::Zero(num_unknowns()), roles_, Derivatives::kNone,
                                  &values_);
    scale_.resize(num_unknowns());
    for (int i = 0; i < num_equations(); ++i) {
      scale_[i] = 1.0 / (1.0 + std::fabs(values_.equations[i]));
    }
    for (int k = 0; k < complementary_; ++k) {
      const double size = std::max(std::fabs(values_.a[k]), std::fabs(values_.b[k]));
      scale_[num_equations() + k] = 1.0 / (1.0 + size);
    }
    if (!scale_.allFinite()) scale_.setOnes();  // a non-finite model is reported by Evaluate
  }
  void ResidualScale(const Vector& /*v*/, Vector* scale) override { *scale = scale_; }
  int num_unknowns() const override { return system_.num_algebraic(); }
  int num_equations() const override { return system_.num_algebraic() - complementary_; }
  int num_pairs() const override { return complementary_; }
  bool Evaluate(const Vector& v, bool with_jacobian, Vector* r, Vector* a, Vector* b) override {
    VelocityLevelEvaluation& target = with_jacobian ? evaluation_ : values_;
    system_.EvaluateVelocityLevel(y_, v, roles_, Derivatives::kNone, &target);
    *r = target.equations;
    *a = target.a;
    *b = target.b;
    return r->allFinite() && a->allFinite() && b->allFinite();
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    jacobian->AddBlock(0, 0, evaluation_.equations_v);
    if (complementary_ > 0) {
      const Matrix rows = da.asDiagonal() * evaluation_.a_v + db.asDiagonal() * evaluation_.b_v;
      jacobian->AddBlock(num_equations(), 0, rows);
    }
  }

 private:
  const LoweredSystem& system_;
  Vector y_;
  std::vector<PairRole> roles_;
  int complementary_ = 0;
  VelocityLevelEvaluation evaluation_, values_;
  Vector scale_;
};

SemismoothNewtonOptions VelocityNewtonOptions() {
  SemismoothNewtonOptions options;
  options.tolerance = 1e-12;
  options.max_iterations = 30;
  options.linear_solver = LinearSolverKind::kDenseLu;
  return options;
}

}  // namespace

bool LoweredSystem::SolveVelocityLevel(const Vector& y, const std::vector<bool>& a_zero,
                                       const Vector& v0, Vector* v) const {
  if (num_algebraic_ == 0) {
    v->resize(0);
    return true;
  }
  VelocitySystem system(*this, y, RolesFor(a_zero));
  SemismoothNewton newton(VelocityNewtonOptions());
  const SemismoothNewtonResult result = newton.Solve(system, v0);
  *v = result.solution;
  return result.converged();
}

StatusDecision LoweredSystem::DecideStatuses(const Vector& y, double candidate_tolerance) const {
  StatusDecision decision;
  decision.a_zero.assign(static_cast<std::size_t>(num_pairs_), false);
  if (num_pairs_ == 0) {
    decision.solved = true;
    decision.v.resize(0);
    return decision;
  }
  // Continuous sides at y from the index-1 consistent values (e.g. lambda = g - min g).
  const Vector guess = InitialAlgebraicGuess(y);
  PointEvaluation at_y;
  Evaluate(y, guess, Derivatives::kNone, &at_y);
  std::vector<PairRole> roles(static_cast<std::size_t>(num_pairs_));
  std::vector<int> candidates;
  for (int k = 0; k < num_pairs_; ++k) {
    const ContinuousSide side = pairs_[static_cast<std::size_t>(k)].continuous;
    const bool continuous_a = side != ContinuousSide::kB;
    const double continuous_value = continuous_a ? at_y.A[k] : at_y.B[k];
    // kBoth: b is continuous too (an index-1 multiplier, a function of the state).
    const double other_value =
        side == ContinuousSide::kBoth ? at_y.B[k] : std::numeric_limits<double>::infinity();
    if (std::min(continuous_value, other_value) < -candidate_tolerance) {
      std::ostringstream s;
      s << "pair '" << pairs_[static_cast<std::size_t>(k)].name
        << "' is violated at this state (continuous side "
        << std::min(continuous_value, other_value) << " < 0)";
      decision.message = s.str();
      return decision;
    }
    if (continuous_value > candidate_tolerance) {
      // The continuous side is positive: the jump side stays at zero.
      roles[static_cast<std::size_t>(k)] = continuous_a ? PairRole::kBZero : PairRole::kAZero;
    } else if (other_value > candidate_tolerance && side == ContinuousSide::kBoth) {
      // b is positive and continuous: it stays free, a stays at zero.
      roles[static_cast<std::size_t>(k)] = PairRole::kAZero;
    } else {
      roles[static_cast<std::size_t>(k)] = PairRole::kComplementary;
      candidates.push_back(k);
    }
  }
  decision.candidates = static_cast<int>(candidates.size());
  const int nx = scene_.num_states();
  SemismoothNewton newton(VelocityNewtonOptions());

  if (static_cast<int>(candidates.size()) > kMaxEnumeratedCandidates) {
    VelocitySystem system(*this, y, roles);
    const SemismoothNewtonResult result = newton.Solve(system, guess);
    if (!result.converged()) {
      decision.message = "velocity-level complementarity problem: " + result.message;
      return decision;
    }
    decision.v = result.solution;
    VelocityLevelEvaluation e;
    EvaluateVelocityLevel(y, decision.v, roles, Derivatives::kNone, &e);
    for (int k = 0; k < num_pairs_; ++k)
      decision.a_zero[static_cast<std::size_t>(k)] =
          roles[static_cast<std::size_t>(k)] == PairRole::kAZero;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      // Jump side zero: the continuous side is free to leave zero.
      const bool continuous_a =
          pairs_[static_cast<std::size_t>(candidates[i])].continuous != ContinuousSide::kB;
      const bool jump_zero = e.a[static_cast<Eigen::Index>(i)] <= e.b[static_cast<Eigen::Index>(i)];
      decision.a_zero[static_cast<std::size_t>(candidates[i])] = jump_zero != continuous_a;
    }
    decision.solved = true;
    return decision;
  }

  // Enumerate: every candidate keeps either its jump side at zero (the continuous side may
  // leave zero) or its continuous side's rate at zero (it stays at zero).
  struct Valid {
    std::vector<PairRole> roles;
    Vector v;
    Vector velocity;
    int leaving = 0;  // candidates whose continuous side is free
  };
  std::vector<Valid> valid;
  const double sign_tolerance = candidate_tolerance;
  for (unsigned mask = 0; mask < (1u << candidates.size()); ++mask) {
    std::vector<PairRole> trial = roles;
    int leaving = 0;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      const int k = candidates[i];
      const bool continuous_a =
          pairs_[static_cast<std::size_t>(k)].continuous != ContinuousSide::kB;
      const bool jump_zero = (mask >> i) & 1u;
      leaving += jump_zero ? 1 : 0;
      // Keeping the jump side zero means keeping the side that is not continuous.
      trial[static_cast<std::size_t>(k)] =
          (jump_zero == continuous_a) ? PairRole::kBZero : PairRole::kAZero;
    }
    bool admitted = true;
    for (const auto& block : blocks_) {
      const auto first = trial.begin() + block->layout.pair_offset;
      admitted &= block->AdmitsRoles(std::vector<PairRole>(first, first + block->num_pairs()));
    }
    if (!admitted) continue;
    VelocitySystem system(*this, y, trial);
    const SemismoothNewtonResult result = newton.Solve(system, guess);
    if (!result.converged()) continue;
    // The free side of every candidate must be nonnegative.
    VelocityLevelEvaluation e;
    std::vector<PairRole> check = trial;
    for (int k : candidates) check[static_cast<std::size_t>(k)] = PairRole::kComplementary;
    EvaluateVelocityLevel(y, result.solution, check, Derivatives::kNone, &e);
    bool ok = true;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      const bool jump_zero = (mask >> i) & 1u;
      const double free =
          jump_zero ? e.b[static_cast<Eigen::Index>(i)] : e.a[static_cast<Eigen::Index>(i)];
      ok &= free >= -sign_tolerance;
    }
    if (!ok) continue;
    PointEvaluation point;
    EvaluatePoint(y, result.solution, Derivatives::kNone, &trial, &point);
    valid.push_back({trial, result.solution, point.F.head(nx), leaving});
  }
  if (valid.empty()) {
    decision.message = "no consistent continuation of the " + std::to_string(candidates.size()) +
                       " pairs that are zero at this state";
    return decision;
  }
  // Slow solution: least velocity norm; among equal velocities, the most pairs leaving zero.
  std::size_t best = 0;
  for (std::size_t i = 1; i < valid.size(); ++i) {
    const double difference = (valid[i].velocity - valid[best].velocity).norm();
    const double scale = 1.0 + valid[best].velocity.norm();
    if (difference <= 1e-9 * scale) {
      if (valid[i].leaving > valid[best].leaving) best = i;
    } else if (valid[i].velocity.norm() < valid[best].velocity.norm()) {
      best = i;
    }
  }
  for (const Valid& other : valid) {
    if ((other.velocity - valid[best].velocity).norm() >
        1e-9 * (1.0 + valid[best].velocity.norm())) {
      decision.ambiguous = true;
    }
  }
  if (decision.ambiguous) {
    std::ostringstream s;
    s << valid.size() << " consistent continuations with different velocities; the slow one "
      << "(least |x'| = " << valid[best].velocity.norm() << ") is taken";
    decision.message = s.str();
  }
  decision.v = valid[best].v;
  for (int k = 0; k < num_pairs_; ++k) {
    decision.a_zero[static_cast<std::size_t>(k)] =
        valid[best].roles[static_cast<std::size_t>(k)] == PairRole::kAZero;
  }
  decision.solved = true;
  return decision;
}

}  // namespace moreau
