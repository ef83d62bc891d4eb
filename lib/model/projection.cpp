// Projection onto the moving sets of a scene (include/moreau/model/projection.hpp).

#include "moreau/model/projection.hpp"

#include <Eigen/Dense>
#include <limits>
#include <vector>

#include "moreau/core/error.hpp"
#include "moreau/newton/semismooth_newton.hpp"

namespace moreau {
namespace {

// The moving sets of a scene with their projectors P = E E^T.
struct Sets {
  std::vector<const MovingSet*> sets;
  std::vector<Matrix> projectors;
  std::vector<int> offsets;  // first multiplier of each set
  int constraints = 0;
};

Sets CollectSets(const Scene& scene) {
  Sets out;
  const int nx = scene.num_states();
  for (const Effect& effect : scene.effects) {
    const auto* set = std::get_if<MovingSet>(&effect);
    if (set == nullptr) continue;
    out.sets.push_back(set);
    out.projectors.push_back(
        set->projection_basis.size() == 0
            ? Matrix(Matrix::Identity(nx, nx))
            : Matrix(set->projection_basis * set->projection_basis.transpose()));
    out.offsets.push_back(out.constraints);
    out.constraints += static_cast<int>(set->constraint_names.size());
  }
  return out;
}

// w = (x, lambda):  r = x - x0 - sum_s P_s grad c_s^T lambda_s = 0,  pairs (c(x, t), lambda).
class ProjectionSystem final : public MixedComplementaritySystem {
 public:
  ProjectionSystem(const Sets& sets, const Vector& x0, double t, const Vector& u, const Vector& p)
      : sets_(sets), x0_(x0), t_(t), u_(u), p_(p), nx_(static_cast<int>(x0.size())) {}
  int num_unknowns() const override { return nx_ + sets_.constraints; }
  int num_equations() const override { return nx_; }
  int num_pairs() const override { return sets_.constraints; }

  bool Evaluate(const Vector& w, bool with_jacobian, Vector* r, Vector* a, Vector* b) override {
    const auto x = w.head(nx_);
    const auto lambda = w.tail(sets_.constraints);
    *r = x - x0_;
    a->resize(sets_.constraints);
    *b = lambda;
    if (with_jacobian) {
      r_x_ = Matrix::Identity(nx_, nx_);
      r_lambda_.setZero(nx_, sets_.constraints);
      a_x_.setZero(sets_.constraints, nx_);
    }
    for (std::size_t s = 0; s < sets_.sets.size(); ++s) {
      const MovingSet& set = *sets_.sets[s];
      const int m = static_cast<int>(set.constraint_names.size());
      const int k0 = sets_.offsets[s];
      Vector c;
      Matrix jacobian;
      set.constraints.Jacobian(x, u_, t_, p_, Wrt::X(), &c, &jacobian);
      const Vector l = lambda.segment(k0, m);
      *r -= sets_.projectors[s] * (jacobian.transpose() * l);
      a->segment(k0, m) = c;
      if (!with_jacobian) continue;
      Matrix hessian;
      set.constraints.WeightedHessian(x, u_, t_, p_, Wrt::X(), l, &hessian);
      r_x_ -= sets_.projectors[s] * hessian;
      r_lambda_.middleCols(k0, m) = -sets_.projectors[s] * jacobian.transpose();
      a_x_.middleRows(k0, m) = jacobian;
    }
    return r->allFinite() && a->allFinite();
  }

  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    jacobian->AddBlock(0, 0, r_x_);
    jacobian->AddBlock(0, nx_, r_lambda_);
    jacobian->AddBlock(nx_, 0, da.asDiagonal() * a_x_);
    for (int k = 0; k < sets_.constraints; ++k) jacobian->AddEntry(nx_ + k, nx_ + k, db[k]);
  }

 private:
  const Sets& sets_;
  Vector x0_;
  double t_;
  Vector u_, p_;
  int nx_;
  Matrix r_x_, r_lambda_, a_x_;
};

}  // namespace

double MinimumMovingSetConstraint(const Scene& scene, const Vector& x, double t, const Vector& u,
                                  const Vector& p) {
  double minimum = std::numeric_limits<double>::infinity();
  for (const Effect& effect : scene.effects) {
    const auto* set = std::get_if<MovingSet>(&effect);
    if (set == nullptr) continue;
    Vector c;
    set->constraints.Evaluate(x, u, t, p, &c);
    if (c.size() > 0) minimum = std::min(minimum, c.minCoeff());
  }
  return minimum;
}

// Newton's residual at the projection's solution is round-off below this, relative to the
// size of the start (1e-13 is the absolute tolerance asked; 1e-10 leaves three digits for the
// multipliers' sizes).
constexpr double kProjectionRoundOff = 1e-10;
// ... but never above this: a start so large that its round-off exceeds it (|x| ~ 1e13, a
// shooting iterate gone astray) has no meaningful projection, and the solve fails.
constexpr double kMaxProjectionRoundOff = 1e-8;

MovingSetProjection ProjectOntoMovingSets(const Scene& scene, const Vector& x0, double t,
                                          const Vector& u, const Vector& p, bool derivatives) {
  RequireArgument(x0.size() == scene.num_states(), scene.name, ": projection needs ",
                  scene.num_states(), " states, got ", x0.size());
  const int nx = scene.num_states(), nu = scene.num_inputs(), np = scene.num_parameters();
  const Sets sets = CollectSets(scene);
  MovingSetProjection out;
  out.x = x0;
  out.lambda = Vector::Zero(sets.constraints);
  if (derivatives) {
    out.d_x0 = Matrix::Identity(nx, nx);
    out.d_t = Vector::Zero(nx);
    out.d_u = Matrix::Zero(nx, nu);
    out.d_p = Matrix::Zero(nx, np);
  }
  if (sets.constraints == 0) {
    out.converged = true;
    return out;
  }
  ProjectionSystem system(sets, x0, t, u, p);
  SemismoothNewtonOptions options;
  options.tolerance = 1e-13;
  options.max_iterations = 50;
  options.linear_solver = LinearSolverKind::kDenseLu;
  SemismoothNewton newton(options);
  Vector w0 = Vector::Zero(nx + sets.constraints);
  w0.head(nx) = x0;
  const SemismoothNewtonResult solved = newton.Solve(system, w0);
  // The residual's round-off floor grows with the size of the state and of the multipliers
  // (a far-outside start: the stationarity rows x - x0 + lambda grad c), and Newton's line
  // search can stop on it above 1e-13 (a shooting node at |x| ~ 6 far outside: 3e-12). A
  // solve that stopped there has converged as far as floating point allows.
  const double floor = std::min(kMaxProjectionRoundOff,
                                kProjectionRoundOff * std::max(1.0, w0.lpNorm<Eigen::Infinity>()));
  const bool at_round_off = solved.status != NewtonStatus::kMaxIterations &&
                            solved.status != NewtonStatus::kNonFinite &&
                            solved.residual_norm <= floor;
  if (!solved.converged() && !at_round_off) {
    out.message = "projection onto the moving sets did not converge: " + solved.message;
    return out;
  }
  out.converged = true;
  out.x = solved.solution.head(nx);
  out.lambda = solved.solution.tail(sets.constraints);
  out.distance = (out.x - x0).norm();
  if (!derivatives) return out;

  // Implicit function theorem on the active-set form of the projection: unknowns (x,
  // lambda_A) with
  //   r = x - x0 - sum_s P_s grad c_s^T lambda_s = 0,   c_k(x, t, u, p) = 0 for k in A,
  // and lambda_k = 0 off A, where A holds every constraint at zero (|c_k| <= boundary
  // tolerance), whether its multiplier is positive or zero. A state on the boundary (c = 0,
  // lambda = 0, where Fischer-Burmeister's generalized Jacobian would mix both branches) thus
  // gets the derivative of the outward branch: that of a projection. Both one-sided
  // derivatives of the map are valid generalized derivatives; this one is the limit of the
  // derivatives of strictly outside states, which shooting nodes on the boundary are
  // continuous with (docs/ocp.md). theta = (x0, t, u, p).
  const Vector x = out.x;
  const double boundary_tolerance =
      kMovingSetBoundaryTolerance * std::max(1.0, x.lpNorm<Eigen::Infinity>());
  Matrix r_x = Matrix::Identity(nx, nx);
  Matrix r_lambda = Matrix::Zero(nx, sets.constraints);
  Matrix r_theta = Matrix::Zero(nx, nx + 1 + nu + np);
  r_theta.leftCols(nx) = -Matrix::Identity(nx, nx);  // dr/dx0
  Matrix c_x = Matrix::Zero(sets.constraints, nx);
  Matrix c_theta = Matrix::Zero(sets.constraints, nx + 1 + nu + np);
  std::vector<int> active;
  for (std::size_t s = 0; s < sets.sets.size(); ++s) {
    const MovingSet& set = *sets.sets[s];
    const int m = static_cast<int>(set.constraint_names.size());
    const int k0 = sets.offsets[s];
    Vector c;
    Matrix jacobian;  // columns x, u, t, p
    set.constraints.Jacobian(x, u, t, p, Wrt::All(), &c, &jacobian);
    Matrix hessian;  // of grad_x c^T lambda: rows x, columns x, u, t, p
    set.constraints.WeightedHessian(x, u, t, p, Wrt::All(), out.lambda.segment(k0, m), &hessian);
    const Matrix& projector = sets.projectors[s];
    r_x -= projector * hessian.topLeftCorner(nx, nx);
    r_lambda.middleCols(k0, m) = -projector * jacobian.leftCols(nx).transpose();
    const Matrix mixed = -projector * hessian.topRows(nx);
    r_theta.col(nx) += mixed.col(nx + nu);                       // t
    r_theta.middleCols(nx + 1, nu) += mixed.middleCols(nx, nu);  // u
    r_theta.rightCols(np) += mixed.rightCols(np);                // p
    c_x.middleRows(k0, m) = jacobian.leftCols(nx);
    c_theta.block(k0, nx, m, 1) = jacobian.col(nx + nu);
    c_theta.block(k0, nx + 1, m, nu) = jacobian.middleCols(nx, nu);
    c_theta.block(k0, nx + 1 + nu, m, np) = jacobian.rightCols(np);
    for (int k = 0; k < m; ++k) {
      if (c[k] <= boundary_tolerance) active.push_back(k0 + k);
    }
  }
  const int na = static_cast<int>(active.size());
  Matrix ift = Matrix::Zero(nx + na, nx + na);
  Matrix rhs = Matrix::Zero(nx + na, nx + 1 + nu + np);
  ift.topLeftCorner(nx, nx) = r_x;
  rhs.topRows(nx) = r_theta;
  for (int i = 0; i < na; ++i) {
    const int k = active[static_cast<std::size_t>(i)];
    ift.block(0, nx + i, nx, 1) = r_lambda.col(k);
    ift.block(nx + i, 0, 1, nx) = c_x.row(k);
    rhs.row(nx + i) = c_theta.row(k);
  }
  const Eigen::FullPivLU<Matrix> lu(ift);
  if (!lu.isInvertible()) {
    // Linearly dependent active gradients (e.g. a corner with more active constraints than
    // the projection subspace has dimensions): the multipliers are not unique and the IFT
    // does not apply. The projection itself is fine; its derivative is not defined.
    out.converged = false;
    out.message =
        "projection onto the moving sets: the active constraint gradients are linearly "
        "dependent, so the projection has no unique derivative";
    return out;
  }
  const Matrix dw = -lu.solve(rhs);
  out.d_x0 = dw.topLeftCorner(nx, nx);
  out.d_t = dw.block(0, nx, nx, 1);
  out.d_u = dw.block(0, nx + 1, nx, nu);
  out.d_p = dw.block(0, nx + 1 + nu, nx, np);
  return out;
}

}  // namespace moreau
