#include "moreau/integrators/alpha_dai.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "inside_constraints.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "sqp.hpp"

namespace moreau {

// ---------------------------------------------------------------------------------------------
// Coefficients, amplification matrix, basis matrices.

AlphaCoefficients AlphaCoefficients::FromRho(double rho) {
  RequireArgument(std::isfinite(rho) && rho >= 0.0 && rho < 1.0,
                  "alpha method: rho must be in [0, 1), got ", rho);
  AlphaCoefficients c;
  c.rho = rho;
  c.gamma = 2.0 / (rho + 1.0) - 0.5;           // (3a)
  c.beta = 1.0 / ((rho + 1.0) * (rho + 1.0));  // (3b)
  return c;
}

Eigen::Matrix2cd AlphaAmplificationMatrix(double rho, std::complex<double> omega) {
  const AlphaCoefficients co = AlphaCoefficients::FromRho(rho);
  const double c = co.beta / co.gamma;
  // (2a) on y' = lambda y:  (1 - c Omega) y1 = (1 + (1 - c) Omega) y0 + (1/2 - c) h^2 a0;
  // (2b):                   h^2 a1 = (Omega / gamma) (y1 - y0) + (1 - 1/gamma) h^2 a0.
  // y1 - y0 = Omega / (1 - c Omega) y0 + ... is formed directly (no cancellation at large Omega).
  const std::complex<double> denominator = 1.0 - c * omega;
  Eigen::Matrix2cd a;
  a(0, 0) = (1.0 + (1.0 - c) * omega) / denominator;
  a(0, 1) = (0.5 - c) / denominator;
  a(1, 0) = omega * omega / (co.gamma * denominator);
  a(1, 1) = omega * (0.5 - c) / (co.gamma * denominator) + (1.0 - 1.0 / co.gamma);
  return a;
}

namespace {

void CheckBasisSizes(const Matrix& a, const Matrix& d, const Matrix& c, const Matrix& g, double h) {
  const Eigen::Index m = a.rows(), r = d.cols();
  RequireArgument(a.cols() == m && d.rows() == m && c.rows() == r && c.cols() == m &&
                      g.rows() == r && g.cols() == r,
                  "basis matrix: expected A m x m, D m x r, C r x m, G r x r, got A ", a.rows(),
                  " x ", a.cols(), ", D ", d.rows(), " x ", d.cols(), ", C ", c.rows(), " x ",
                  c.cols(), ", G ", g.rows(), " x ", g.cols());
  RequireArgument(std::isfinite(h) && h > 0.0, "basis matrix: step h must be positive, got ", h);
}

// The blocks of (14) with the coefficients (row1_x, row1_u) = -(c1 h) (A, D) and
// (row2_x, row2_u) = -(c2 / h) (A, D) added to the identity pattern when `identity`.
Matrix AssembleBasis(const Matrix& a, const Matrix& d, const Matrix& c, const Matrix& g, double c1h,
                     double c2_over_h, bool identity) {
  const Eigen::Index m = a.rows(), r = d.cols();
  Matrix b = Matrix::Zero(2 * m + r, 2 * m + r);
  b.block(0, 0, m, m) = -c1h * a;
  b.block(0, 2 * m, m, r) = -c1h * d;
  b.block(m, 0, m, m) = -c2_over_h * a;
  b.block(m, 2 * m, m, r) = -c2_over_h * d;
  if (identity) {
    b.block(0, 0, m, m).diagonal().array() += 1.0;
    b.block(m, m, m, m).diagonal().array() += 1.0;
    b.block(2 * m, 0, r, m) = c;
    b.block(2 * m, 2 * m, r, r) = g;
  }
  return b;
}

}  // namespace

Matrix AlphaBasisMatrix(const Matrix& a, const Matrix& d, const Matrix& c, const Matrix& g,
                        double h, double rho) {
  CheckBasisSizes(a, d, c, g, h);
  const AlphaCoefficients co = AlphaCoefficients::FromRho(rho);
  return AssembleBasis(a, d, c, g, co.beta / co.gamma * h, 1.0 / (co.gamma * h), true);
}

Matrix AlphaBasisMatrixRhoDerivative(const Matrix& a, const Matrix& d, const Matrix& c,
                                     const Matrix& g, double h, double rho) {
  CheckBasisSizes(a, d, c, g, h);
  AlphaCoefficients::FromRho(rho);  // validates rho
  // beta/gamma = 2 / ((rho+1)(3-rho)), 1/gamma = 2 (rho+1) / (3-rho).
  const double d_beta_over_gamma =
      -4.0 * (1.0 - rho) / ((rho + 1.0) * (rho + 1.0) * (3.0 - rho) * (3.0 - rho));
  const double d_inverse_gamma = 8.0 / ((3.0 - rho) * (3.0 - rho));
  return AssembleBasis(a, d, c, g, d_beta_over_gamma * h, d_inverse_gamma / h, false);
}

Matrix AlphaScaledBasisMatrix(const Matrix& a, const Matrix& d, const Matrix& c, const Matrix& g,
                              double h, double rho) {
  CheckBasisSizes(a, d, c, g, h);
  const AlphaCoefficients co = AlphaCoefficients::FromRho(rho);
  const Eigen::Index m = a.rows(), r = d.cols();
  const double c1 = co.beta / co.gamma, c2 = 1.0 / co.gamma;
  // Rows (13b) times h^2, unknowns (x, h^2 a, h u_b): Sec. 6.1.1's scaling (x/h, h a, u) up
  // to the common factor h.
  Matrix b = Matrix::Zero(2 * m + r, 2 * m + r);
  b.block(0, 0, m, m) = Matrix::Identity(m, m) - c1 * h * a;
  b.block(0, 2 * m, m, r) = -c1 * d;
  b.block(m, 0, m, m) = -c2 * h * a;
  b.block(m, m, m, m) = Matrix::Identity(m, m);
  b.block(m, 2 * m, m, r) = -c2 * d;
  for (Eigen::Index i = 0; i < r; ++i) {
    b.block(2 * m + i, 0, 1, m) = c.row(i);
    b.block(2 * m + i, 2 * m, 1, r) = g.row(i) / h;
    const double norm = b.row(2 * m + i).norm();
    if (norm > 0.0) b.row(2 * m + i) /= norm;
  }
  return b;
}

// ---------------------------------------------------------------------------------------------
// Options, statuses, statistics.

std::string ToString(AlphaDaiObjective objective) {
  switch (objective) {
    case AlphaDaiObjective::kFeasibility:
      return "feasibility";
    case AlphaDaiObjective::kLeastChange:
      return "least-change";
    case AlphaDaiObjective::kReference:
      return "reference";
  }
  return "?";
}

AlphaDaiObjective ParseAlphaDaiObjective(const std::string& name) {
  if (name == "feasibility") return AlphaDaiObjective::kFeasibility;
  if (name == "least-change") return AlphaDaiObjective::kLeastChange;
  if (name == "reference") return AlphaDaiObjective::kReference;
  ThrowInvalidArgument("unknown alpha-method objective '", name,
                       "'; expected feasibility, least-change or reference");
}

void AlphaDaiOptions::Validate() const {
  RequireArgument(std::isfinite(rho) && rho >= 0.0 && rho < 1.0,
                  "alpha option rho must be in [0, 1), got ", rho);
  RequireArgument(std::isfinite(step_size) && step_size >= 0.0,
                  "alpha option step_size (h) must be >= 0 and finite (0: error-controlled "
                  "steps), got ",
                  step_size);
  RequireArgument(std::isfinite(max_step_size) && max_step_size >= 0.0,
                  "alpha option max_step_size (h_max) must be >= 0 and finite (0: no bound), got ",
                  max_step_size);
  RequireArgument(std::isfinite(initial_step_size) && initial_step_size >= 0.0,
                  "alpha option initial_step_size (h0) must be >= 0 and finite (0: automatic), "
                  "got ",
                  initial_step_size);
  RequireArgument(std::isfinite(relative_tolerance) && relative_tolerance > 0.0,
                  "alpha option relative_tolerance (rtol) must be positive, got ",
                  relative_tolerance);
  RequireArgument(std::isfinite(absolute_tolerance) && absolute_tolerance >= 0.0,
                  "alpha option absolute_tolerance (atol) must be >= 0 (0: per state), got ",
                  absolute_tolerance);
  RequireArgument(error_tolerance > 0.0,
                  "alpha option error_tolerance (ERRTOL) must be positive "
                  "(infinity for fixed steps), got ",
                  error_tolerance);
  RequireArgument(!std::isfinite(error_tolerance) || (step_size > 0.0 && !adaptive),
                  "alpha option error_tolerance (ERRTOL) is the paper's rule for fixed steps: "
                  "it needs a fixed step h (step_size > 0) without adaptive");
  RequireArgument(std::isfinite(min_step_size) && min_step_size > 0.0 &&
                      (step_size == 0.0 || min_step_size <= step_size),
                  "alpha option min_step_size must be positive and at most the step h, got ",
                  min_step_size);
  RequireArgument(std::isfinite(constraint_tolerance) && constraint_tolerance > 0.0,
                  "alpha option constraint_tolerance (TOL) must be positive, got ",
                  constraint_tolerance);
  RequireArgument(std::isfinite(dynamics_tolerance) && dynamics_tolerance > 0.0,
                  "alpha option dynamics_tolerance must be positive, got ", dynamics_tolerance);
  RequireArgument(std::isfinite(optimality_tolerance) && optimality_tolerance > 0.0,
                  "alpha option optimality_tolerance must be positive, got ", optimality_tolerance);
  RequireArgument(std::isfinite(rank_tolerance) && rank_tolerance > 0.0 && rank_tolerance < 1.0,
                  "alpha option rank_tolerance must be in (0, 1), got ", rank_tolerance);
  RequireArgument(max_sqp_iterations >= 1,
                  "alpha option max_sqp_iterations (MAXIT) must be >= 1, got ", max_sqp_iterations);
  RequireArgument(max_retries >= 0, "alpha option max_retries (MAXTRY) must be >= 0, got ",
                  max_retries);
  RequireArgument(max_steps >= 1, "alpha option max_steps must be >= 1, got ", max_steps);
}

std::string ToString(AlphaDaiStatus status) {
  switch (status) {
    case AlphaDaiStatus::kSuccess:
      return "success";
    case AlphaDaiStatus::kInfeasibleConstraints:
      return "infeasible_constraints";
    case AlphaDaiStatus::kRegularizationFailed:
      return "regularization_failed";
    case AlphaDaiStatus::kRetriesExhausted:
      return "retries_exhausted";
    case AlphaDaiStatus::kStepSizeTooSmall:
      return "step_size_too_small";
    case AlphaDaiStatus::kMaxStepsReached:
      return "max_steps_reached";
    case AlphaDaiStatus::kNonFinite:
      return "non_finite";
  }
  return "?";
}

AlphaDaiStats& AlphaDaiStats::operator+=(const AlphaDaiStats& other) {
  num_steps += other.num_steps;
  num_tries += other.num_tries;
  num_rho_reductions += other.num_rho_reductions;
  num_guess_retries += other.num_guess_retries;
  num_rank_deficient += other.num_rank_deficient;
  num_infeasible += other.num_infeasible;
  num_sqp_iterations += other.num_sqp_iterations;
  num_qp_iterations += other.num_qp_iterations;
  num_elastic_qps += other.num_elastic_qps;
  num_jacobian_evaluations += other.num_jacobian_evaluations;
  num_function_evaluations += other.num_function_evaluations;
  num_basis_factorizations += other.num_basis_factorizations;
  max_constraint_violation = std::max(max_constraint_violation, other.max_constraint_violation);
  max_dynamics_residual = std::max(max_dynamics_residual, other.max_dynamics_residual);
  max_kkt_residual = std::max(max_kkt_residual, other.max_kkt_residual);
  min_basis_sigma = std::min(min_basis_sigma, other.min_basis_sigma);
  min_rho = std::min(min_rho, other.min_rho);
  min_step = std::min(min_step, other.min_step);
  num_rejected_steps += other.num_rejected_steps;
  num_event_rejections += other.num_event_rejections;
  num_failed_steps += other.num_failed_steps;
  // Estimates of consecutive runs add up; -1 (not estimated) only if neither has one.
  if (other.error_estimate >= 0.0)
    error_estimate = std::max(error_estimate, 0.0) + other.error_estimate;
  num_unestimated_steps += other.num_unestimated_steps;
  num_inside_crossings += other.num_inside_crossings;
  num_unresolved_crossings += other.num_unresolved_crossings;
  num_bound_evaluations += other.num_bound_evaluations;
  cpu_seconds += other.cpu_seconds;
  return *this;
}

std::string AlphaDaiStats::Summary() const {
  std::ostringstream s;
  s << num_steps << " steps, " << num_tries << " SQP solves (" << num_rho_reductions
    << " rho reductions, " << num_guess_retries << " new guesses, " << num_rank_deficient
    << " rank deficient, " << num_infeasible << " infeasible), " << num_sqp_iterations
    << " SQP iterations, " << num_qp_iterations << " QP iterations, max phi+ "
    << max_constraint_violation << ", min sigma(B) " << min_basis_sigma << ", min rho " << min_rho
    << ", " << num_rejected_steps << " rejected (" << num_event_rejections << " at events, "
    << num_failed_steps << " failed), " << num_inside_crossings << " inside crossings ("
    << num_unresolved_crossings << " unresolved), error estimate " << error_estimate << ", "
    << cpu_seconds << " s";
  return s.str();
}

namespace {

// rho is lowered by this amount per regularization retry (paper Sec. 7, Step 2b).
constexpr double kRhoDecrement = 0.1;
constexpr double kRhoRoundOff = 1e-12;
// Below this many candidate column sets the basis with the least condition number is found
// by enumeration; above, column-pivoted QR of the constraints' sensitivity picks the columns.
constexpr long kMaxEnumeratedBases = 64;
// Weight of x in the QP Hessian relative to u (see Try): small enough that the drift of u it
// causes (about this weight times |x correction| |du/dx|) stays below the tolerances, large
// enough for the Cholesky factor of the dual active-set method (condition 1e8).
constexpr double kStateProximalWeight = 1e-8;
// A segment end closer than this fraction of the step counts as reached (round-off in t).
constexpr double kLandingFraction = 1e-9;
// Error control (Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.4): the next step is
// h min(kMaxGrowth, max(kMinShrink, kSafety err^{-1/2})) (the error per unit step of an
// order-2 method is O(h^2)); a step whose SQP fails is retried with kFailureShrink h.
constexpr double kSafety = 0.9;
constexpr double kMaxGrowth = 5.0;
constexpr double kMinShrink = 0.2;
constexpr double kFailureShrink = 0.25;
// Stall guard: steps below kStallFraction times the event resolution rtol (tf - t0) should pass
// the error test easily when the solution is smooth and the SQP converges; more than
// kMaxStalledAttempts rejected or failed ones in a run end it with a status naming the cause
// instead of crawling on (the estimate of a non-smooth solution does not fall with h).
constexpr double kStallFraction = 1e-2;
constexpr long kMaxStalledAttempts = 50;
// Crawl guard: kMaxCrawlingSteps accepted steps in a row each so short that the rest of the
// horizon would need more than kCrawlMargin times the steps max_steps leaves end the run with
// a status at once instead of after max_steps (dai_index2 at rtol 1e-9 accepted 10^6 steps of
// 9e-11 after its floor's return, 451 s of CPU, before max_steps stopped it).
constexpr long kMaxCrawlingSteps = 1000;
constexpr double kCrawlMargin = 100.0;
// States whose scale is below this fraction of the largest state scale are weighted by that
// fraction (a state that starts at zero has no scale of its own yet).
constexpr double kScaleFloor = 1e-6;
// Round-off of a step's solution in units of eps (1 + |x|), as Radau's error test (kNoise)
// takes it: differences of the coarse and fine solutions below this pass.
constexpr double kRoundOffNoise = 10.0;
// Error control: the SQP solves (2a) to this fraction of the step's error allowance (Radau's
// Newton iterations stop at a like fraction of the tolerance).
constexpr double kSolveFraction = 1e-2;
// Error control's rank test: a sensitivity row below this fraction of the size of its terms is
// round-off (an index-3 row is O(h) of them, so this holds down to steps of about 1e-12).
constexpr double kNegligibleSensitivity = 1e-12;
// Constraints between step ends (docs/alpha-method.md, "Constraints between step ends"): a
// step of the error control in which a path constraint is found above its tolerance on the
// step's continuous extension is retried ending on the crossing, at most kMaxInsideRetries
// times in a row (each retry ends on the first zero of the new step's extension, which is
// about the old one's, so two or three suffice; the cap bounds the work where the extension and
// the SQP's end points disagree); a search the bounds cannot decide is retried with half the
// step at most kMaxUnresolvedRetries times in a row (FESD's rule: a graze within the bounds'
// overestimate of the tolerance stays undecided at every resolution). Steps at the event
// resolution rtol (tf - t0) are not shortened. Then the step is accepted and counted
// (AlphaDaiStats::num_unresolved_crossings, a warning).
constexpr int kMaxInsideRetries = 8;
constexpr int kMaxUnresolvedRetries = 2;

long Binomial(long n, long k) {
  if (k < 0 || k > n) return 0;
  long value = 1;
  for (long i = 1; i <= k; ++i) {
    value = value * (n - k + i) / i;
    if (value > kMaxEnumeratedBases) return value;
  }
  return value;
}

// Why one SQP try failed.
enum class TryFailure { kNone, kRankDeficient, kInfeasible, kNotConverged };

// What the working-set check learned about the basis matrix of the last QP.
struct BasisInfo {
  int num_active = 0;
  int num_input_bounds = 0;
  double sigma_min = 0.0;
  double condition = 0.0;
  std::vector<int> basic;  // basic algebraic inputs (indices among the algebraic inputs)
};

class AlphaDaiRun {
 public:
  AlphaDaiRun(const Scene& scene, const AlphaDaiOptions& options, const ProgressCallback& progress)
      : scene_(scene), options_(options), progress_(progress) {
    adaptive_ = options.ErrorControlled();
    nx_ = scene.num_states();
    dynamics_ = scene.dynamics;
    parameters_ = scene.ParameterValues();
    for (int i = 0; i < scene.num_inputs(); ++i) {
      if (scene.inputs[static_cast<std::size_t>(i)].kind == InputSpec::Kind::kAlgebraic) {
        algebraic_.push_back(i);
      }
    }
    nq_ = static_cast<int>(algebraic_.size());
    x_lower_ = Vector::Constant(nx_, -std::numeric_limits<double>::infinity());
    x_upper_ = Vector::Constant(nx_, std::numeric_limits<double>::infinity());
    for (const Effect& effect : scene.effects) {
      const auto& dai = std::get<PathConstraints>(effect);
      if (!dai.constraint_names.empty()) {
        constraints_.push_back(dai.constraints);
        for (const std::string& name : dai.constraint_names) {
          constraint_names_.push_back(dai.name + "." + name);
        }
      }
      if (dai.state_lower.size() > 0) x_lower_ = x_lower_.cwiseMax(dai.state_lower);
      if (dai.state_upper.size() > 0) x_upper_ = x_upper_.cwiseMin(dai.state_upper);
    }
    nphi_ = static_cast<int>(constraint_names_.size());
    for (const std::string& state : scene.state_names) {
      constraint_names_.push_back(state + ".lower");
      constraint_names_.push_back(state + ".upper");
    }
    u_lower_.resize(nq_);
    u_upper_.resize(nq_);
    for (int j = 0; j < nq_; ++j) {
      const InputSpec& input = scene.inputs[static_cast<std::size_t>(algebraic_[j])];
      u_lower_[j] = input.lower;
      u_upper_[j] = input.upper;
      constraint_names_.push_back(input.name + ".lower");
      constraint_names_.push_back(input.name + ".upper");
    }
  }

  AlphaDaiResult Run() {
    const RunClock run_clock;
    AlphaDaiResult result;
    result.constraint_names = constraint_names_;
    result.trajectory.state_names = scene_.state_names;
    for (int j : algebraic_) {
      result.trajectory.algebraic_names.push_back(scene_.inputs[static_cast<std::size_t>(j)].name);
    }
    const std::vector<double> ends =
        SegmentEnds(scene_.initial_time, scene_.final_time, scene_.ControlBreakpoints());
    // Fixed steps are at most h: fewer than FixedStepCount is impossible, so a horizon that
    // needs more than max_steps is refused before any work.
    if (!adaptive_) RequireFixedStepsWithin(ends, options_.step_size, options_.max_steps);
    t_ = scene_.initial_time;
    x_ = scene_.initial_state;
    horizon_ = scene_.final_time - scene_.initial_time;
    scale_ = x_.cwiseAbs();
    inputs_ = scene_.InputValues(t_);
    InitializeAlgebraic();  // Step 1: consistent u_0 (throws if none)
    result.trajectory.Append(t_, x_, u_, 0.0);
    h_previous_ = options_.step_size;
    h_next_ = InitialStep();
    if (adaptive_ || options_.estimate_error) stats_.error_estimate = 0.0;
    bool ok = true;
    for (std::size_t segment = 0; ok && segment + 1 < ends.size(); ++segment) {
      inputs_ = scene_.InputValues(ends[segment]);
      // a_0 = df/dt at the segment start (t_0 or a control breakpoint, where f jumps).
      if (!RestartAcceleration()) {
        ok = Fail(&result, AlphaDaiStatus::kNonFinite, "f or df/dt is not finite");
        break;
      }
      ok = RunSegment(ends[segment + 1], &result);
    }
    if (!adaptive_ && ok) {
      const std::string warning =
          ErrorEstimateWarning(stats_.error_estimate, options_.relative_tolerance);
      if (!warning.empty()) result.warnings.push_back(warning);
    }
    if (stats_.num_unresolved_crossings > 0) result.warnings.push_back(UnresolvedWarning());
    result.final_time = t_;
    result.final_state = x_;
    result.final_inputs = u_;
    result.final_acceleration = a_;
    if (!options_.record_trajectory && result.trajectory.t.back() != t_) {
      result.trajectory.Append(t_, x_, u_, last_step_);
    }
    stats_.cpu_seconds = run_clock.CpuSeconds();
    result.stats = stats_;
    return result;
  }

 private:
  // ------------------------------------------------------------------------- model evaluation
  Vector FullInputs(const Eigen::Ref<const Vector>& u) const {
    Vector full = inputs_;
    for (int j = 0; j < nq_; ++j) full[algebraic_[j]] = u[j];
    return full;
  }

  Vector EvaluateF(const Vector& x, const Vector& u, double t) const {
    Vector f;
    if (dynamics_.empty()) return Vector::Zero(nx_);
    dynamics_.Evaluate(x, FullInputs(u), t, parameters_, &f);
    return f;
  }

  // f and its Jacobians A = df/dx and D = df/du (algebraic columns).
  void JacobianF(const Vector& x, const Vector& u, double t, Vector* f, Matrix* a,
                 Matrix* d) const {
    if (dynamics_.empty()) {
      *f = Vector::Zero(nx_);
      *a = Matrix::Zero(nx_, nx_);
      *d = Matrix::Zero(nx_, nq_);
      return;
    }
    Matrix jac;
    dynamics_.Jacobian(x, FullInputs(u), t, parameters_, Wrt{true, true, false, false}, f, &jac);
    *a = jac.leftCols(nx_);
    d->resize(nx_, nq_);
    for (int j = 0; j < nq_; ++j) d->col(j) = jac.col(nx_ + algebraic_[j]);
  }

  // phi and, with jacobians, dphi/dx and dphi/du (algebraic columns), and dphi/dt when phi_t
  // is given (with the Jacobians).
  void EvaluatePhi(const Vector& x, const Vector& u, double t, Vector* phi, Matrix* phi_x,
                   Matrix* phi_u, Vector* phi_t = nullptr) const {
    phi->resize(nphi_);
    if (phi_x != nullptr) {
      phi_x->resize(nphi_, nx_);
      phi_u->resize(nphi_, nq_);
    }
    if (phi_t != nullptr) phi_t->resize(nphi_);
    const Vector full = FullInputs(u);
    int row = 0;
    for (const SmoothFunction& g : constraints_) {
      const int k = g.num_outputs();
      Vector value;
      if (phi_x == nullptr) {
        g.Evaluate(x, full, t, parameters_, &value);
      } else {
        Matrix jac;
        g.Jacobian(x, full, t, parameters_, Wrt{true, true, phi_t != nullptr, false}, &value, &jac);
        phi_x->middleRows(row, k) = jac.leftCols(nx_);
        for (int j = 0; j < nq_; ++j)
          phi_u->block(row, j, k, 1) = jac.block(0, nx_ + algebraic_[j], k, 1);
        if (phi_t != nullptr) phi_t->segment(row, k) = jac.col(jac.cols() - 1);
      }
      phi->segment(row, k) = value;
      row += k;
    }
  }

  // a = df/dt = f_x f + f_t (du/dt = 0 for the algebraic inputs, constant controls).
  bool RestartAcceleration() {
    f_ = EvaluateF(x_, u_, t_);
    if (dynamics_.empty()) {
      a_ = Vector::Zero(nx_);
    } else {
      Vector f;
      Matrix jac;
      dynamics_.Jacobian(x_, FullInputs(u_), t_, parameters_, Wrt{true, false, true, false}, &f,
                         &jac);
      a_ = jac.leftCols(nx_) * f + jac.col(nx_);
    }
    max_acceleration_ = std::max(max_acceleration_, a_.lpNorm<Eigen::Infinity>());
    return f_.allFinite() && a_.allFinite();
  }

  // --------------------------------------------------------------------------- initialization
  // Step 1: x_0 must lie within the state bounds; u_0 is the feasible point closest to the
  // initial guesses (least change) for the path constraints at t_0.
  void InitializeAlgebraic() {
    for (int i = 0; i < nx_; ++i) {
      RequireArgument(x_[i] >= x_lower_[i] && x_[i] <= x_upper_[i], scene_.name,
                      ": initial state x0.", scene_.state_names[static_cast<std::size_t>(i)], " = ",
                      x_[i], " is outside its bounds [", x_lower_[i], ", ", x_upper_[i],
                      "] (path constraints)");
    }
    Vector guess(nq_);
    for (int j = 0; j < nq_; ++j) {
      guess[j] = scene_.inputs[static_cast<std::size_t>(algebraic_[j])].initial_guess;
    }
    guess = guess.cwiseMax(u_lower_).cwiseMin(u_upper_);
    u_ = guess;
    if (nphi_ == 0) return;
    Vector phi;
    EvaluatePhi(x_, u_, t_, &phi, nullptr, nullptr);
    if (phi.maxCoeff() <= options_.constraint_tolerance) return;
    int worst = 0;
    phi.maxCoeff(&worst);
    RequireArgument(nq_ > 0, scene_.name, ": infeasible initial state: path constraint '",
                    constraint_names_[static_cast<std::size_t>(worst)], "' is phi = ", phi[worst],
                    " > 0 at t0 = ", t_,
                    " and the scene has no algebraic inputs (expected phi(x0, t0) <= ",
                    options_.constraint_tolerance, ")");
    internal::SqpProblem problem;
    problem.num_variables = nq_;
    problem.lower = u_lower_;
    problem.upper = u_upper_;
    problem.objective_weights = Vector::Ones(nq_);
    problem.reference = guess;
    problem.hessian_diagonal = Vector::Ones(nq_);
    problem.evaluate = [this](const Vector& z, bool jacobians, internal::SqpEvaluation* out) {
      out->equalities.resize(0);
      out->equality_jacobian.resize(0, nq_);
      Matrix phi_x;
      EvaluatePhi(x_, z, t_, &out->inequalities, jacobians ? &phi_x : nullptr,
                  jacobians ? &out->inequality_jacobian : nullptr);
      return true;
    };
    internal::SqpOptions sqp_options;
    sqp_options.inequality_tolerance = options_.constraint_tolerance;
    sqp_options.optimality_tolerance = options_.optimality_tolerance;
    sqp_options.max_iterations = options_.max_sqp_iterations;
    const internal::SqpResult sqp = internal::SolveSqp(problem, guess, sqp_options);
    if (sqp.status != internal::SqpStatus::kConverged) {
      EvaluatePhi(x_, sqp.z, t_, &phi, nullptr, nullptr);
      phi.maxCoeff(&worst);
      ThrowInvalidArgument(scene_.name,
                           ": inconsistent initial values: no algebraic inputs satisfying the path "
                           "constraints at t0 = ",
                           t_, " were found from the initial guesses (SQP: ",
                           internal::ToString(sqp.status), "; largest violation phi = ", phi[worst],
                           " in constraint '", constraint_names_[static_cast<std::size_t>(worst)],
                           "'; expected phi(x0, u0, t0) <= ", options_.constraint_tolerance, ")");
    }
    u_ = sqp.z;
  }

  // ------------------------------------------------------------------------------- stepping
  // A solved step from (t_, x_, u_, f_, a_), not yet accepted.
  struct Candidate {
    double t1 = 0.0, h = 0.0, h_rule = 0.0, rho = 0.0;
    int tries = 0;
    internal::SqpResult sqp;
    BasisInfo basis;
    Vector x1, u1, f1, a1;
    std::vector<int> active;
    std::vector<int> binding;                          // BindingIndices
    AlphaDaiStatus status = AlphaDaiStatus::kSuccess;  // why no step was found
    std::string reason;
  };

  // The run's state at t_ (what a rejected or comparison step restores).
  struct Snapshot {
    double t = 0.0;
    Vector x, u, f, a;
    std::vector<int> active;
    double max_acceleration = 0.0;
  };
  Snapshot Save() const { return {t_, x_, u_, f_, a_, active_, max_acceleration_}; }
  void Restore(const Snapshot& snapshot) {
    t_ = snapshot.t;
    x_ = snapshot.x;
    u_ = snapshot.u;
    f_ = snapshot.f;
    a_ = snapshot.a;
    active_ = snapshot.active;
    max_acceleration_ = snapshot.max_acceleration;
  }
  // Moves the state to a candidate's end without recording it (the first half step of a
  // comparison).
  void Advance(const Candidate& c) {
    t_ = c.t1;
    x_ = c.x1;
    u_ = c.u1;
    f_ = c.f1;
    a_ = c.a1;
    active_ = c.active;
  }

  // ---------------------------------------------------------------- consistent algebraic inputs
  // After an event the algebraic inputs must also satisfy the hidden constraints of the binding
  // constraints of index 2, not only phi <= 0. A step's SQP enforces
  // phi(x_{n+1}) = 0 on such a constraint, and with x_n on it that is, to first order,
  //   phi_x ((1 - beta/gamma) f_n + (beta/gamma) f_{n+1}) = 0,
  // so an inconsistent u_n (phi_x f_n != 0) makes phi_x f_{n+1} = -(1 - beta/gamma)/(beta/gamma)
  // phi_x f_n: u oscillates about the consistent value by that factor per step (-0.875 at
  // rho = 0.5), an O(h) local error in x that step doubling measures but that does not fall
  // with h (D3's heat flux stalled the error control so). This solves, at fixed x = x_n and
  // t = t_n, for u only,
  //   minimize    the step's objective J(u) (Try: the reference w(t_n), or u_n)
  //   subject to  phi_i(x, u, t) <= 0               for every row that depends on u (index 1),
  //               phi_x,i(x, t) f(x, u, t) + phi_t,i(x, t) <= 0
  //                                                 for every binding row that does not, and
  //                                                 whose derivative does (index 2),
  //               +-f_i(x, u, t) <= 0               for every binding state bound (index 2),
  //               u_lower <= u <= u_upper,
  // the hidden constraint d/dt phi <= 0 of index-2 rows (= 0 while they stay active; < 0 lets
  // them leave). The Jacobian of an index-2 row in u is phi_x f_u, exact from the model's AD
  // (phi_x and phi_t do not depend on u for such a row). Rows of index 3 (phi_x f_u = 0 too)
  // are left out: u enters them only at the next level. `binding` (constraint indices as in
  // ActiveIndices) are the rows the last step's SQP enforces (BindingIndices), not the whole
  // working set: a row within the activity tolerance but short of zero (phi = -1e-8) must not
  // have its approach stopped there (dai_index2 at rtol 1e-9 then failed before the contact).
  // Does nothing when no binding row is of index 2; otherwise replaces u_ (f_ and a_ are then
  // restarted by the caller). Returns false with a status and reason when no such u is found.
  bool MakeAlgebraicConsistent(const std::vector<int>& binding, AlphaDaiStatus* status,
                               std::string* reason) {
    if (nq_ == 0) return true;
    Vector phi, phi_t;
    Matrix phi_x, phi_u;
    EvaluatePhi(x_, u_, t_, &phi, &phi_x, &phi_u, &phi_t);
    Vector f;
    Matrix a, d;
    JacobianF(x_, u_, t_, &f, &a, &d);
    // AD gives exact zeros for rows that do not depend on u, so the classification is exact
    // (a row whose u-derivative vanishes only at this point is taken as of higher index).
    std::vector<int> index1;
    for (int i = 0; i < nphi_; ++i) {
      if (phi_u.row(i).cwiseAbs().maxCoeff() > 0.0) index1.push_back(i);
    }
    Matrix hidden_x(0, nx_);  // rows c with c f(x, u, t) + b <= 0
    Vector hidden_b(0);
    auto add_hidden = [&](const Eigen::RowVectorXd& c, double b) {
      if ((c * d).cwiseAbs().maxCoeff() == 0.0) return;  // index 3 or more
      hidden_x.conservativeResize(hidden_x.rows() + 1, Eigen::NoChange);
      hidden_b.conservativeResize(hidden_b.size() + 1);
      hidden_x.row(hidden_x.rows() - 1) = c;
      hidden_b[hidden_b.size() - 1] = b;
    };
    for (int k : binding) {
      if (k < nphi_) {
        if (phi_u.row(k).cwiseAbs().maxCoeff() == 0.0) add_hidden(phi_x.row(k), phi_t[k]);
      } else if (k < nphi_ + 2 * nx_) {
        const int i = (k - nphi_) / 2;
        Eigen::RowVectorXd c = Eigen::RowVectorXd::Zero(nx_);
        c[i] = (k - nphi_) % 2 == 1 ? 1.0 : -1.0;  // upper: x_i' <= 0; lower: -x_i' <= 0
        add_hidden(c, 0.0);
      }
    }
    if (hidden_x.rows() == 0) return true;
    const int n1 = static_cast<int>(index1.size());
    const Eigen::Index n2 = hidden_x.rows();
    internal::SqpProblem problem;
    problem.num_variables = nq_;
    problem.lower = u_lower_;
    problem.upper = u_upper_;
    problem.objective_weights = options_.objective == AlphaDaiObjective::kFeasibility
                                    ? Vector(Vector::Zero(nq_))
                                    : Vector(Vector::Ones(nq_));
    problem.reference = u_;
    if (options_.objective == AlphaDaiObjective::kReference) {
      for (int j = 0; j < nq_; ++j) {
        problem.reference[j] =
            scene_.inputs[static_cast<std::size_t>(algebraic_[j])].signal.ValueAt(t_);
      }
    }
    problem.hessian_diagonal = Vector::Ones(nq_);
    problem.evaluate = [&](const Vector& z, bool jacobians, internal::SqpEvaluation* out) {
      out->equalities.resize(0);
      out->equality_jacobian.resize(0, nq_);
      out->inequalities.resize(n1 + n2);
      Vector phi_z, fz;
      Matrix phi_zx, phi_zu, az, dz;
      if (jacobians) {
        ++stats_.num_jacobian_evaluations;
        EvaluatePhi(x_, z, t_, &phi_z, &phi_zx, &phi_zu);
        JacobianF(x_, z, t_, &fz, &az, &dz);
        out->inequality_jacobian.resize(n1 + n2, nq_);
        for (int r = 0; r < n1; ++r) {
          out->inequality_jacobian.row(r) = phi_zu.row(index1[static_cast<std::size_t>(r)]);
        }
        out->inequality_jacobian.bottomRows(n2) = hidden_x * dz;
      } else {
        ++stats_.num_function_evaluations;
        EvaluatePhi(x_, z, t_, &phi_z, nullptr, nullptr);
        fz = EvaluateF(x_, z, t_);
      }
      for (int r = 0; r < n1; ++r)
        out->inequalities[r] = phi_z[index1[static_cast<std::size_t>(r)]];
      out->inequalities.tail(n2) = hidden_x * fz + hidden_b;
      return fz.allFinite() && phi_z.allFinite();
    };
    internal::SqpOptions sqp_options;
    sqp_options.inequality_tolerance = options_.constraint_tolerance;
    sqp_options.activity_tolerance = options_.constraint_tolerance;
    sqp_options.optimality_tolerance = options_.optimality_tolerance;
    sqp_options.max_iterations = options_.max_sqp_iterations;
    const internal::SqpResult sqp = internal::SolveSqp(problem, u_, sqp_options);
    stats_.num_sqp_iterations += sqp.iterations;
    stats_.num_qp_iterations += sqp.qp_iterations;
    stats_.num_elastic_qps += sqp.elastic_qps;
    if (sqp.status != internal::SqpStatus::kConverged) {
      *status = sqp.status == internal::SqpStatus::kInfeasible
                    ? AlphaDaiStatus::kInfeasibleConstraints
                : sqp.status == internal::SqpStatus::kNonFinite ? AlphaDaiStatus::kNonFinite
                                                                : AlphaDaiStatus::kRetriesExhausted;
      std::ostringstream s;
      s << "no algebraic inputs consistent with the active constraints (phi <= 0 and "
           "d/dt phi <= 0 for the active ones of index 2) were found at fixed x (SQP "
        << internal::ToString(sqp.status) << " after " << sqp.iterations
        << " iterations, largest violation " << sqp.inequality_violation << ", KKT residual "
        << sqp.kkt_residual << ")";
      *reason = s.str();
      return false;
    }
    u_ = sqp.z;
    return true;
  }

  // The rows of a step's working set that its SQP enforces: a positive multiplier (path
  // constraints and state bounds; input bounds are bounds of MakeAlgebraicConsistent's problem).
  std::vector<int> BindingIndices(const Candidate& c) const {
    std::vector<int> binding;
    for (int k : c.active) {
      if (k < nphi_) {
        if (c.sqp.inequality_multipliers[k] > 0.0) binding.push_back(k);
      } else if (k < nphi_ + 2 * nx_) {
        const int i = (k - nphi_) / 2;
        const double lambda = c.sqp.bound_multipliers[i];  // lower - upper
        if ((k - nphi_) % 2 == 1 ? lambda < 0.0 : lambda > 0.0) binding.push_back(k);
      }
    }
    return binding;
  }

  double InitialStep() const {
    double h = options_.initial_step_size > 0.0 ? options_.initial_step_size
               : options_.step_size > 0.0       ? options_.step_size
                                                : horizon_ * std::sqrt(options_.relative_tolerance);
    if (options_.max_step_size > 0.0) h = std::min(h, options_.max_step_size);
    return std::max(h, options_.min_step_size);
  }

  bool RunSegment(double t_end, AlphaDaiResult* result) {
    return adaptive_ ? RunAdaptiveSegment(t_end, result) : RunFixedSegment(t_end, result);
  }

  bool RunFixedSegment(double t_end, AlphaDaiResult* result) {
    while (t_ < t_end) {
      if (stats_.num_steps >= options_.max_steps) {
        return Fail(result, AlphaDaiStatus::kMaxStepsReached, "reached max_steps");
      }
      // Step 2: h_i = sqrt(min{h^2, h_{i-1}^2, ERRTOL / (2.25 max_j ||a_j||_inf)}).
      double h2 = std::min(options_.step_size * options_.step_size, h_previous_ * h_previous_);
      if (std::isfinite(options_.error_tolerance) && max_acceleration_ > 0.0) {
        h2 = std::min(h2, options_.error_tolerance / (2.25 * max_acceleration_));
      }
      double h_nominal = std::sqrt(h2);
      if (!(h_nominal >= options_.min_step_size)) {
        std::ostringstream s;
        s << "the step-size rule gives h = " << h_nominal
          << " < min_step_size = " << options_.min_step_size
          << " (max ||a||_inf = " << max_acceleration_ << ", ERRTOL = " << options_.error_tolerance
          << ")";
        return Fail(result, AlphaDaiStatus::kStepSizeTooSmall, s.str());
      }
      Candidate step;
      if (!Solve(t_end, &h_nominal, &step)) return Fail(result, step.status, step.reason);
      Vector margin = Vector::Zero(nx_);
      if (options_.estimate_error) EstimateFixedStep(step, &margin);
      // A fixed step is not shortened: a constraint that may exceed its tolerance between the
      // step's ends is counted and warned about (see kMaxInsideRetries).
      if (nphi_ > 0) {
        const InsideResult inside = SearchInside(Save(), step, margin);
        if (inside.outcome != internal::CrossingOutcome::kNone) CountUnresolved(inside);
      }
      Commit(step, h_nominal, result);
      h_previous_ = h_nominal;
      if (progress_) progress_(t_);
    }
    return true;
  }

  // Fixed steps: the step-doubling estimate of an accepted step (two half steps from the same
  // start), accumulated into error_estimate, and its size per state into *margin (left as it
  // is when a half step fails); the state is left as it was.
  void EstimateFixedStep(const Candidate& step, Vector* margin) {
    const Snapshot start = Save();
    Candidate first, second;
    bool ok = Solve(t_ + 0.5 * step.h, nullptr, &first);
    if (ok) {
      Advance(first);
      ok = Solve(step.t1, nullptr, &second);
    }
    Restore(start);
    if (!ok) {
      ++stats_.num_unestimated_steps;
      return;
    }
    // Every state per unit step, the velocity-level ones too (see VelocityLevelStates): at the
    // paper's coarse fixed steps their error is larger than one step's estimate (hard_index3 at
    // h = 0.1: x2(T) 1.1e-3 off, about the sum of the 30 steps' estimates), and the sum over
    // the steps is what GivenStepIsFixedAndItsErrorEstimated checks.
    const double err = ErrorPerUnitStep(start.x, step.x1, second.x1, step.h,
                                        std::vector<bool>(static_cast<std::size_t>(nx_), false));
    stats_.error_estimate += options_.relative_tolerance * step.h / horizon_ * err;
    *margin = (second.x1 - step.x1).cwiseAbs() / 3.0;
  }

  // ------------------------------------------------------------- constraints between step ends
  // Where a path constraint may exceed its tolerance between a step's ends: the first time, the
  // row, and whether a value above it was found (kFound) or the bounds could not decide
  // (kUnresolved).
  struct InsideResult {
    internal::CrossingOutcome outcome = internal::CrossingOutcome::kNone;
    double time = 0.0;
    int constraint = -1;
  };

  // Searches the step from `start` to `end` (internal::InsideConstraintSearch, the box of x
  // widened by `margin`): the rows in the working set at neither end. Active rows are the
  // step's business (the SQP keeps them at zero at the ends; an event's steps are short).
  InsideResult SearchInside(const Snapshot& start, const Candidate& end, const Vector& margin) {
    InsideResult inside;
    if (nphi_ == 0) return inside;
    std::vector<char> watched(static_cast<std::size_t>(nphi_), 1);
    for (const std::vector<int>* active : {&start.active, &end.active}) {
      for (int k : *active) {
        if (k < nphi_) watched[static_cast<std::size_t>(k)] = 0;
      }
    }
    // What the tolerances resolve in phi: tol plus phi's change under a state error of one
    // tolerance weight per state, sum_i |dphi/dx_i| w_i at the step's end. A value above tol by
    // less on the continuous extension is within the solution's accuracy (the exact solution
    // may graze the constraint there or not); and the interval bounds, which overestimate by
    // about sum_i |dphi/dx_i| times the box's widths, decide rows within that distance of zero
    // (a constraint just left, as D3's heat flux) only on pieces of about this size.
    auto thresholds = [&]() {
      Vector phi;
      Matrix phi_x, phi_u;
      EvaluatePhi(end.x1, end.u1, end.t1, &phi, &phi_x, &phi_u);
      Vector weights(nx_);
      for (Eigen::Index i = 0; i < nx_; ++i) {
        weights[i] = ToleranceWeight(i, std::max(std::fabs(start.x[i]), std::fabs(end.x1[i])));
      }
      return Vector((phi_x.cwiseAbs() * weights).array() + options_.constraint_tolerance);
    };
    const internal::Crossing crossing = inside_.Search(
        {start.t, &start.x, &start.u, &start.f}, {end.t1, &end.x1, &end.u1, &end.f1}, inputs_,
        std::move(watched), margin, options_.constraint_tolerance, thresholds);
    stats_.num_bound_evaluations += crossing.bound_evaluations;
    inside.outcome = crossing.outcome;
    inside.constraint = crossing.function;
    const double theta =
        crossing.outcome == internal::CrossingOutcome::kFound ? crossing.theta : crossing.sample;
    inside.time = start.t + theta * (end.t1 - start.t);
    return inside;
  }

  // A step accepted with a constraint that may exceed its tolerance between its ends.
  void CountUnresolved(const InsideResult& inside) {
    if (inside.outcome == internal::CrossingOutcome::kFound) ++stats_.num_inside_crossings;
    ++stats_.num_unresolved_crossings;
    if (!std::isfinite(first_unresolved_time_)) {
      first_unresolved_time_ = inside.time;
      first_unresolved_constraint_ = inside.constraint;
    }
  }

  std::string UnresolvedWarning() const {
    std::ostringstream s;
    s.precision(10);
    s << stats_.num_unresolved_crossings
      << (stats_.num_unresolved_crossings == 1 ? " step" : " steps")
      << " (the first at t = " << first_unresolved_time_;
    if (first_unresolved_constraint_ >= 0) {
      s << ", constraint '"
        << constraint_names_[static_cast<std::size_t>(first_unresolved_constraint_)] << "'";
    }
    s << ") where a path constraint may exceed tol = " << options_.constraint_tolerance
      << " between the step's ends (a value above it was found on the step's continuous "
         "extension, or its interval bound admits one) and the step was not shortened onto it "
         "("
      << (adaptive_ ? "the step was at the event resolution rtol (tf - t0) or its retries were "
                      "used up"
                    : "fixed steps are not shortened")
      << "): the constraint may have been stepped over; bound the step (h_max"
      << (adaptive_ ? ", or a smaller rtol" : ", or a smaller h") << ")";
    return s.str();
  }

  // Error control by step doubling (see the header): one step of h and two of h/2 from t_;
  // the half steps are kept when the estimate passes (or, when the working set changes in
  // the step, when h <= rtol (tf - t0)).
  bool RunAdaptiveSegment(double t_end, AlphaDaiResult* result) {
    const double rtol = options_.relative_tolerance;
    const double event_step = std::max(rtol * horizon_, options_.min_step_size);
    while (t_ < t_end) {
      if (stats_.num_steps >= options_.max_steps) {
        return Fail(result, AlphaDaiStatus::kMaxStepsReached, "reached max_steps");
      }
      const double remaining = t_end - t_;
      double h = std::min(h_next_, remaining);
      if (remaining - h <= kLandingFraction * h) h = remaining;
      const double t1 = h == remaining ? t_end : t_ + h;
      const Snapshot start = Save();
      Candidate coarse, first, second;
      const Candidate* failed = &coarse;
      bool ok = Solve(t1, nullptr, &coarse);
      if (ok) {
        failed = &first;
        ok = Solve(t_ + 0.5 * h, nullptr, &first);
      }
      if (ok) {
        Advance(first);
        failed = &second;
        ok = Solve(t1, nullptr, &second);
      }
      Restore(start);
      // Steps far below the event resolution pass the error test easily when the solution is
      // smooth and the SQP converges: many rejections there mean neither holds.
      const double err =
          ok ? ErrorPerUnitStep(start.x, coarse.x1, second.x1, h, VelocityLevelStates(second))
             : 0.0;
      if ((!ok || err > 1.0) && h < kStallFraction * event_step &&
          ++stalled_attempts_ > kMaxStalledAttempts) {
        std::ostringstream s;
        s << "the error control stalled: " << stalled_attempts_ << " steps shorter than "
          << kStallFraction << " rtol (tf - t0) = " << kStallFraction * event_step
          << " were rejected or failed (the last at h = " << h
          << "): the SQP fails or the estimate does not fall with h (the solution is not "
             "smooth at this resolution); last: ";
        if (ok) {
          s << "estimated error per unit step " << err << " of the tolerance";
        } else {
          s << failed->reason;
        }
        return Fail(result, ok ? AlphaDaiStatus::kStepSizeTooSmall : failed->status, s.str());
      }
      if (!ok) {
        // Step 2c's retries did not help at this h: a shorter step (FESD and Radau do the same).
        ++stats_.num_failed_steps;
        h_next_ = kFailureShrink * h;
        if (h_next_ < options_.min_step_size) {
          std::ostringstream s;
          s << failed->reason << "; the step was retried shorter down to h = " << h
            << " (min_step_size = " << options_.min_step_size << ")";
          return Fail(result, failed->status, s.str());
        }
        continue;
      }
      const bool event = first.active != start.active || second.active != first.active ||
                         coarse.active != start.active;
      if (event && h > event_step) {
        ++stats_.num_rejected_steps;
        ++stats_.num_event_rejections;
        h_next_ = std::max(kFailureShrink * h, event_step);
        continue;
      }
      if (!event && err > 1.0) {
        ++stats_.num_rejected_steps;
        h_next_ = h * std::max(kMinShrink, kSafety / std::sqrt(err));
        if (h_next_ < options_.min_step_size) {
          std::ostringstream s;
          s << "the error control needs h = " << h_next_
            << " < min_step_size = " << options_.min_step_size << " (estimated error per unit step "
            << err << " of the tolerance)";
          return Fail(result, AlphaDaiStatus::kStepSizeTooSmall, s.str());
        }
        continue;
      }
      // Constraints between the ends of the two half steps (see kMaxInsideRetries); the
      // distance of the fine solution from the exact one, the estimate, widens the box.
      InsideResult inside;
      if (nphi_ > 0) {
        const Vector margin = (second.x1 - coarse.x1).cwiseAbs() / 3.0;
        inside = SearchInside(start, first, margin);
        if (inside.outcome == internal::CrossingOutcome::kNone) {
          inside = SearchInside(
              Snapshot{first.t1, first.x1, first.u1, first.f1, first.a1, first.active, 0.0}, second,
              margin);
        }
      }
      const bool shortenable = h > event_step;
      if (inside.outcome == internal::CrossingOutcome::kFound && shortenable &&
          inside_retries_ < kMaxInsideRetries) {
        // Again, ending on the crossing: the SQP then sees the constraint at the step's end.
        ++inside_retries_;
        ++stats_.num_rejected_steps;
        ++stats_.num_inside_crossings;
        h_next_ = std::max(inside.time - t_, event_step);
        continue;
      }
      if (inside.outcome == internal::CrossingOutcome::kUnresolved && shortenable &&
          unresolved_retries_ < kMaxUnresolvedRetries) {
        ++unresolved_retries_;
        ++stats_.num_rejected_steps;
        h_next_ = std::max(0.5 * h, event_step);
        continue;
      }
      if (inside.outcome == internal::CrossingOutcome::kNone) {
        inside_retries_ = 0;
        unresolved_retries_ = 0;
      } else {
        CountUnresolved(inside);
      }
      Commit(first, h, result);
      Commit(second, h, result);
      stats_.error_estimate += rtol * h / horizon_ * err;
      // Crawl guard: accepted steps so short that the rest of the horizon would need far more
      // steps than max_steps leaves end the run now, not at max_steps (see kMaxCrawlingSteps).
      const double needed = 2.0 * (scene_.final_time - t_) / h;  // two half steps per step
      const double budget = static_cast<double>(options_.max_steps - stats_.num_steps);
      if (needed > kCrawlMargin * budget) {
        if (++crawling_steps_ >= kMaxCrawlingSteps) {
          std::ostringstream s;
          s << "the error control crawls: " << crawling_steps_
            << " accepted steps in a row as short as h = " << h
            << ", at which the rest of the horizon needs " << needed << " steps, more than "
            << kCrawlMargin << " times the " << budget << " that max_steps leaves";
          if (options_.max_step_size > 0.0 && h >= options_.max_step_size) {
            s << " (h_max = " << options_.max_step_size << " bounds the steps)";
          } else {
            s << " (the estimate does not fall with h: the solution is not smooth at this "
                 "resolution, or an algebraic input is not consistent after an event)";
          }
          return Fail(result, AlphaDaiStatus::kStepSizeTooSmall, s.str());
        }
      } else {
        crawling_steps_ = 0;
      }
      // At an event f jumps, and (2b) turns the jump into a ~ jump / (gamma h) that decays
      // only by (1 - 1/gamma) per step: its h^2 a term in (2a) would be an O(h) local error
      // in every following step. a restarts from df/dt as at a control breakpoint.
      // The algebraic inputs are made consistent with the new working set first (see
      // MakeAlgebraicConsistent): an inconsistent u oscillates and stalls the error control.
      if (event) {
        AlphaDaiStatus status = AlphaDaiStatus::kSuccess;
        std::string reason;
        if (!MakeAlgebraicConsistent(second.binding, &status, &reason)) {
          return Fail(result, status, "after the event: " + reason);
        }
        if (!RestartAcceleration()) {
          return Fail(result, AlphaDaiStatus::kNonFinite, "f or df/dt is not finite");
        }
      }
      // After an event the estimate (O(h) local error) says nothing about the smooth part.
      const double growth =
          event || err == 0.0
              ? kMaxGrowth
              : std::min(kMaxGrowth, std::max(kMinShrink, kSafety / std::sqrt(err)));
      h_next_ = h * growth;
      if (options_.max_step_size > 0.0) h_next_ = std::min(h_next_, options_.max_step_size);
      if (progress_) progress_(t_);
    }
    return true;
  }

  // States at the velocity level of an active index-3 constraint: when the working set of the
  // step's end point holds a row g (a path constraint or a state bound) that does not see the
  // algebraic inputs directly (g_u = 0) nor through its derivative (g_x f_u = 0), the states
  // driven by the basic inputs (nonzero rows of f_u for them). The position constraint fixes
  // their integral at every step, so the errors of the step in these states do not add up over
  // the steps: the local error of the step in them is O(h^2), one order below the other
  // states', and its global error of the same size (hard_index3 with no options: |x2 - cos t|
  // between 4.8e-7 and 9.2e-7 over 433 double steps, not growing with their number). Judged
  // per unit step,
  // as the other states, the estimate is O(h) and drives h to rtol (tf - t0) and then, with the
  // round-off eps |x| / (c h) of a velocity recovered from positions, below min_step_size. They
  // are judged per step instead (ErrorPerUnitStep), as RADAU5 multiplies the error estimate of
  // index-2 variables by h (Hairer & Wanner, "Solving Ordinary Differential Equations II", 1996,
  // Sec. VII.8; Hairer, Lubich & Roche, "The numerical solution of differential-algebraic
  // systems by Runge-Kutta methods", 1989).
  std::vector<bool> VelocityLevelStates(const Candidate& c) const {
    std::vector<bool> velocity(static_cast<std::size_t>(nx_), false);
    if (c.active.empty() || c.basis.basic.empty()) return velocity;
    Vector f, phi;
    Matrix a, d, phi_x, phi_u;
    JacobianF(c.x1, c.u1, c.t1, &f, &a, &d);
    EvaluatePhi(c.x1, c.u1, c.t1, &phi, &phi_x, &phi_u);
    bool index3 = false;
    for (int i : c.active) {
      Eigen::RowVectorXd gx = Eigen::RowVectorXd::Zero(nx_);
      Eigen::RowVectorXd gu = Eigen::RowVectorXd::Zero(nq_);
      if (i < nphi_) {
        gx = phi_x.row(i);
        gu = phi_u.row(i);
      } else if (i < nphi_ + 2 * nx_) {
        gx[(i - nphi_) / 2] = 1.0;  // a state bound
      } else {
        continue;  // an input bound: index 1
      }
      const double scale = gx.norm() * d.norm();
      if (gu.norm() <= kNegligibleSensitivity * (gu.norm() + scale) &&
          (gx * d).norm() <= kNegligibleSensitivity * scale) {
        index3 = true;
      }
    }
    if (!index3) return velocity;
    for (int k : c.basis.basic) {
      for (int i = 0; i < nx_; ++i) {
        if (d(i, k) != 0.0) velocity[static_cast<std::size_t>(i)] = true;
      }
    }
    return velocity;
  }

  // The step-doubling estimate (fine - coarse) / (2^2 - 1) of the order-2 method, in the
  // tolerance weights atol_i + rtol max(|x_n,i|, |x_n+1,i|), per unit step: <= 1 passes. The
  // states at the velocity level of an active index-3 constraint (`per_step`, see
  // VelocityLevelStates) are judged per step, the estimate times h / (tf - t0).
  double ErrorPerUnitStep(const Vector& x0, const Vector& coarse, const Vector& fine, double h,
                          const std::vector<bool>& per_step) const {
    double worst = 0.0;
    for (Eigen::Index i = 0; i < nx_; ++i) {
      const double size = std::max(std::fabs(x0[i]), std::fabs(fine[i]));
      const double weight = ToleranceWeight(i, size);
      // The difference this step may have, never below what floating point resolves in the
      // compared solutions: a state near zero has a weight near the floor, and over short
      // steps the per-unit-step allowance would fall below the round-off of the two solves.
      const double allowed =
          std::max(per_step[static_cast<std::size_t>(i)] ? weight : weight * h / horizon_,
                   kRoundOffNoise * std::numeric_limits<double>::epsilon() * (1.0 + size));
      worst = std::max(worst, std::fabs(fine[i] - coarse[i]) / 3.0 / allowed);
    }
    return worst;
  }

  // The tolerance weight of state i of size `size` (its largest magnitude over a step):
  // atol_i + rtol size, at least the floor kScaleFloor rtol max_j scale_j.
  double ToleranceWeight(Eigen::Index i, double size) const {
    const double rtol = options_.relative_tolerance;
    const double floor =
        rtol * kScaleFloor * std::max(scale_.maxCoeff(), std::numeric_limits<double>::min());
    const double atol =
        options_.absolute_tolerance > 0.0 ? options_.absolute_tolerance : rtol * scale_[i];
    return std::max(atol + rtol * size, floor);
  }

  // End of the next fixed step: equal steps of at most h_nominal over the rest of the
  // segment; the last one lands exactly on t_end.
  double StepEnd(double t_end, double h_nominal) const {
    const double remaining = t_end - t_;
    const double count = std::max(1.0, std::ceil(remaining / h_nominal - kLandingFraction));
    return count == 1.0 ? t_end : t_ + remaining / count;
  }

  // One step with the retry logic of Sec. 7 (Steps 2, 2a-2c). Fixed steps (h_nominal given):
  // the step ends at StepEnd(t_end, *h_nominal), and a regularization at rho = 0 retries with
  // h = h (Step 2b); error control (h_nominal null): the step ends at t_end.
  bool Solve(double t_end, double* h_nominal, Candidate* out) {
    double rho = options_.rho;
    int retries = 0;
    int guess_index = 0;
    std::ostringstream history;
    TryFailure failure = TryFailure::kNone;
    while (true) {
      const double t1 = h_nominal != nullptr ? StepEnd(t_end, *h_nominal) : t_end;
      const double h = t1 - t_;
      const internal::SqpResult sqp = Try(t1, rho, guess_index, &failure);
      ++stats_.num_tries;
      if (failure == TryFailure::kNone) {
        return Finish(t1, h_nominal != nullptr ? *h_nominal : h, rho, retries + 1, sqp, out);
      }
      history << (retries == 0 ? "" : "; ") << "try " << retries + 1 << " (rho = " << rho
              << ", h = " << h << ", guess " << guess_index << "): " << Describe(failure, sqp);
      bool regularize = false;
      if (failure == TryFailure::kRankDeficient) {
        ++stats_.num_rank_deficient;
        // Step 2b: lower rho by 0.1 (fixed steps: h = h_max once rho = 0) unless that is
        // exhausted.
        regularize = retries < options_.max_retries &&
                     !(rho == 0.0 && (h_nominal == nullptr || *h_nominal == options_.step_size));
      } else if (failure == TryFailure::kInfeasible) {
        ++stats_.num_infeasible;
      }
      if (regularize) {
        // Repeated decrements leave round-off (0.5 - 5 x 0.1 = 2.8e-17): such values are 0.
        rho = rho - kRhoDecrement > kRhoRoundOff ? rho - kRhoDecrement : 0.0;
        if (rho == 0.0 && h_nominal != nullptr) *h_nominal = options_.step_size;
        ++stats_.num_rho_reductions;
        ++retries;
        continue;
      }
      // Step 2c: new initial guesses while retries remain.
      if (retries < options_.max_retries) {
        ++guess_index;
        ++stats_.num_guess_retries;
        ++retries;
        continue;
      }
      out->status = failure == TryFailure::kInfeasible      ? AlphaDaiStatus::kInfeasibleConstraints
                    : failure == TryFailure::kRankDeficient ? AlphaDaiStatus::kRegularizationFailed
                                                            : AlphaDaiStatus::kRetriesExhausted;
      out->reason = "no acceptable step after " + std::to_string(retries + 1) + " tries (" +
                    std::to_string(options_.max_retries) + " retries allowed): " + history.str();
      return false;
    }
  }

  std::string Describe(TryFailure failure, const internal::SqpResult& sqp) const {
    std::ostringstream s;
    s.precision(6);
    switch (failure) {
      case TryFailure::kRankDeficient:
        s << "basis matrix rank deficient (sigma_min = " << basis_.sigma_min
          << " <= rank_tolerance = " << options_.rank_tolerance
          << ", active: " << ActiveNames(sqp.working_set) << ")";
        break;
      case TryFailure::kInfeasible: {
        s << "constraints locally infeasible (l1-stationary point with max phi = "
          << sqp.inequality_violation << ", dynamics residual " << sqp.equality_residual << ")";
        break;
      }
      case TryFailure::kNotConverged:
        s << "SQP " << internal::ToString(sqp.status) << " after " << sqp.iterations
          << " iterations (max phi = " << sqp.inequality_violation << ", dynamics residual "
          << sqp.equality_residual << ", KKT residual " << sqp.kkt_residual << ")";
        break;
      case TryFailure::kNone:
        s << "accepted";
        break;
    }
    return s.str();
  }

  std::string ActiveNames(const internal::SqpWorkingSet& set) const {
    const std::vector<int> active = ActiveIndices(set);
    std::string names;
    for (int k : active)
      names += (names.empty() ? "" : ", ") + constraint_names_[static_cast<std::size_t>(k)];
    return names.empty() ? "none" : names;
  }

  std::vector<int> ActiveIndices(const internal::SqpWorkingSet& set) const {
    std::vector<int> active(set.inequalities.begin(), set.inequalities.end());
    for (int j : set.lower_bounds) active.push_back(BoundIndex(j, false));
    for (int j : set.upper_bounds) active.push_back(BoundIndex(j, true));
    std::sort(active.begin(), active.end());
    return active;
  }

  int BoundIndex(int variable, bool upper) const {
    return nphi_ + 2 * variable + (upper ? 1 : 0);  // states, then algebraic inputs
  }

  // Initial guesses (Step 2c): k = 0 is the paper's (x_n, u_n); then the explicit predictor
  // x_n + h f_n with u_n, then u_n shifted by +-0.1, +-0.5, +-1 times the input's scale (half
  // its bound range, or max(1, |u_n|)), clamped to the bounds.
  Vector Guess(int k, double h) const {
    Vector z(nx_ + nq_);
    z.head(nx_) = k == 0 ? x_ : Vector(x_ + h * f_);
    z.tail(nq_) = u_;
    if (k >= 2) {
      static constexpr double kShifts[] = {0.1, 0.5, 1.0};
      const double shift = kShifts[std::min((k - 2) / 2, 2)] * (k % 2 == 0 ? 1.0 : -1.0);
      for (int j = 0; j < nq_; ++j) {
        const double range = u_upper_[j] - u_lower_[j];
        const double scale = std::isfinite(range) ? 0.5 * range : std::max(1.0, std::fabs(u_[j]));
        z[nx_ + j] += shift * scale;
      }
    }
    Vector lower(nx_ + nq_), upper(nx_ + nq_);
    lower << x_lower_, u_lower_;
    upper << x_upper_, u_upper_;
    return z.cwiseMax(lower).cwiseMin(upper);
  }

  // One SQP solve of (2a)-(2d) for the step from t_n to t1.
  internal::SqpResult Try(double t1, double rho, int guess_index, TryFailure* failure) {
    const AlphaCoefficients co = AlphaCoefficients::FromRho(rho);
    const double c = co.beta / co.gamma;
    const double h = t1 - t_;
    // Known part of (2a): x_n + (1 - beta/gamma) h f_n + (1/2 - beta/gamma) h^2 a_n.
    const Vector known = x_ + (1.0 - c) * h * f_ + (0.5 - c) * h * h * a_;
    internal::SqpProblem problem;
    problem.num_variables = nx_ + nq_;
    problem.lower.resize(nx_ + nq_);
    problem.upper.resize(nx_ + nq_);
    problem.lower << x_lower_, u_lower_;
    problem.upper << x_upper_, u_upper_;
    problem.objective_weights = Vector::Zero(nx_ + nq_);
    problem.reference.resize(nx_ + nq_);
    problem.reference << x_, u_;
    if (options_.objective != AlphaDaiObjective::kFeasibility) {
      problem.objective_weights.tail(nq_).setOnes();
    }
    if (options_.objective == AlphaDaiObjective::kReference) {
      for (int j = 0; j < nq_; ++j) {
        problem.reference[nx_ + j] =
            scene_.inputs[static_cast<std::size_t>(algebraic_[j])].signal.ValueAt(t1);
      }
    }
    // QP Hessian: the objective's (unit weights on u; a unit proximal term for J = 0) and a
    // tiny proximal term on x, which the dynamics (2a) determine: the QP step is then the
    // smallest change of u (a unit weight on x would trade u for the size of the Newton
    // correction of x and let u drift while no constraint is active).
    problem.hessian_diagonal = Vector::Ones(nx_ + nq_);
    problem.hessian_diagonal.head(nx_).setConstant(kStateProximalWeight);
    problem.equality_scales = (1.0 + x_.array().abs()).matrix();
    // (2a) determines x_{n+1} (I - c h A is invertible for the steps taken): the QP states the
    // path constraints in u through the step (index 3 rows are O(h^2) in u; see
    // SqpProblem::num_determined).
    problem.num_determined = nx_;
    problem.evaluate = [&](const Vector& z, bool jacobians, internal::SqpEvaluation* out) {
      const Vector x = z.head(nx_), u = z.tail(nq_);
      Vector f;
      if (jacobians) {
        ++stats_.num_jacobian_evaluations;
        JacobianF(x, u, t1, &f, &a_matrix_, &d_matrix_);
        out->equality_jacobian.resize(nx_, nx_ + nq_);
        out->equality_jacobian.leftCols(nx_) = Matrix::Identity(nx_, nx_) - c * h * a_matrix_;
        out->equality_jacobian.rightCols(nq_) = -c * h * d_matrix_;
        EvaluatePhi(x, u, t1, &out->inequalities, &phi_x_, &phi_u_);
        out->inequality_jacobian.resize(nphi_, nx_ + nq_);
        out->inequality_jacobian << phi_x_, phi_u_;
      } else {
        ++stats_.num_function_evaluations;
        f = EvaluateF(x, u, t1);
        EvaluatePhi(x, u, t1, &out->inequalities, nullptr, nullptr);
      }
      out->equalities = x - known - c * h * f;  // (2a) with a_{n+1} eliminated by (2b)
      return f.allFinite();
    };
    problem.check_working_set = [&](const Vector&, const internal::SqpWorkingSet& set) {
      return CheckBasis(set, h, rho);
    };
    internal::SqpOptions sqp_options;
    sqp_options.equality_tolerance = options_.dynamics_tolerance;
    if (adaptive_) {
      // The solve's residual must stay below the error control's allowance for this step
      // (about rtol h / (tf - t0) relative to the states), else the first guess x_n passes
      // (2a) once h |f| < dynamics_tolerance (1 + |x|) and x freezes while t advances: both
      // halves of step doubling agree and the frozen steps are accepted (D3 at rtol 1e-9 ran so
      // for 1000 steps of 1.5e-9 after its heat-flux contact). Round-off bounds it below.
      sqp_options.equality_tolerance =
          std::min(options_.dynamics_tolerance,
                   std::max(kSolveFraction * options_.relative_tolerance * h / horizon_,
                            kRoundOffNoise * std::numeric_limits<double>::epsilon()));
    }
    sqp_options.inequality_tolerance = options_.constraint_tolerance;
    sqp_options.activity_tolerance = options_.constraint_tolerance;
    sqp_options.optimality_tolerance = options_.optimality_tolerance;
    sqp_options.max_iterations = options_.max_sqp_iterations;
    const internal::SqpResult sqp = internal::SolveSqp(problem, Guess(guess_index, h), sqp_options);
    stats_.num_sqp_iterations += sqp.iterations;
    stats_.num_qp_iterations += sqp.qp_iterations;
    stats_.num_elastic_qps += sqp.elastic_qps;
    switch (sqp.status) {
      case internal::SqpStatus::kConverged:
        *failure = TryFailure::kNone;
        break;
      case internal::SqpStatus::kRejectedWorkingSet:
        *failure = TryFailure::kRankDeficient;
        break;
      case internal::SqpStatus::kInfeasible:
        *failure = TryFailure::kInfeasible;
        break;
      default:
        *failure = TryFailure::kNotConverged;
        break;
    }
    return sqp;
  }

  // The basis matrix of the working set (Sec. 3.1, eq. 14): rows of the active path
  // constraints and state bounds; algebraic inputs at a bound are non-basic; r_a basic
  // columns among the others are chosen for the least condition number of the scaled B.
  // Returns false when its smallest singular value is <= rank_tolerance.
  bool CheckBasis(const internal::SqpWorkingSet& set, double h, double rho) {
    std::vector<bool> at_bound(static_cast<std::size_t>(nq_), false);
    std::vector<int> state_rows;
    for (const std::vector<int>* bounds : {&set.lower_bounds, &set.upper_bounds}) {
      for (int j : *bounds) {
        if (j >= nx_) {
          at_bound[static_cast<std::size_t>(j - nx_)] = true;
        } else {
          state_rows.push_back(j);
        }
      }
    }
    std::vector<int> candidates;
    for (int j = 0; j < nq_; ++j) {
      if (!at_bound[static_cast<std::size_t>(j)]) candidates.push_back(j);
    }
    const int r = static_cast<int>(set.inequalities.size() + state_rows.size());
    basis_ = BasisInfo{};
    basis_.num_active = r;
    basis_.num_input_bounds = nq_ - static_cast<int>(candidates.size());
    if (r > static_cast<int>(candidates.size())) {
      basis_.sigma_min = 0.0;  // more active constraints than free algebraic variables
      basis_.condition = std::numeric_limits<double>::infinity();
      return false;
    }
    Matrix c(r, nx_), g_all(r, nq_);
    int row = 0;
    for (int i : set.inequalities) {
      c.row(row) = phi_x_.row(i);
      g_all.row(row++) = phi_u_.row(i);
    }
    for (int i : state_rows) {
      c.row(row).setZero();
      c(row, i) = 1.0;
      g_all.row(row++).setZero();
    }
    const AlphaCoefficients co = AlphaCoefficients::FromRho(rho);
    auto evaluate = [&](const std::vector<int>& basic, Eigen::VectorXd* sigma) {
      Matrix d(nx_, r), g(r, r);
      for (int k = 0; k < r; ++k) {
        d.col(k) = d_matrix_.col(basic[static_cast<std::size_t>(k)]);
        g.col(k) = g_all.col(basic[static_cast<std::size_t>(k)]);
      }
      const Eigen::JacobiSVD<Matrix> svd(AlphaScaledBasisMatrix(a_matrix_, d, c, g, h, rho));
      ++stats_.num_basis_factorizations;
      *sigma = svd.singularValues();
    };
    const long count = Binomial(static_cast<long>(candidates.size()), r);
    std::vector<int> best;
    Eigen::VectorXd best_sigma;
    double best_condition = std::numeric_limits<double>::infinity();
    if (count <= kMaxEnumeratedBases) {
      // All r-subsets of the candidates in lexicographic order.
      std::vector<int> pick(static_cast<std::size_t>(r));
      for (int k = 0; k < r; ++k) pick[static_cast<std::size_t>(k)] = k;
      while (true) {
        std::vector<int> basic;
        for (int k : pick) basic.push_back(candidates[static_cast<std::size_t>(k)]);
        Eigen::VectorXd sigma;
        evaluate(basic, &sigma);
        const double condition = sigma[0] / sigma[sigma.size() - 1];
        if (best_sigma.size() == 0 || condition < best_condition) {
          best = basic;
          best_sigma = sigma;
          best_condition = condition;
        }
        int k = r - 1;
        while (k >= 0 &&
               pick[static_cast<std::size_t>(k)] == static_cast<int>(candidates.size()) - r + k) {
          --k;
        }
        if (k < 0) break;
        ++pick[static_cast<std::size_t>(k)];
        for (int l = k + 1; l < r; ++l) {
          pick[static_cast<std::size_t>(l)] = pick[static_cast<std::size_t>(l - 1)] + 1;
        }
      }
    } else {
      // Column pivoting on the active constraints' sensitivity to the candidates through
      // (2a): dg/du = C (I - c1 h A)^{-1} c1 h D + G.
      const double c1 = co.beta / co.gamma;
      Matrix d(nx_, static_cast<Eigen::Index>(candidates.size()));
      Matrix g(r, static_cast<Eigen::Index>(candidates.size()));
      for (std::size_t k = 0; k < candidates.size(); ++k) {
        d.col(static_cast<Eigen::Index>(k)) = d_matrix_.col(candidates[k]);
        g.col(static_cast<Eigen::Index>(k)) = g_all.col(candidates[k]);
      }
      const Matrix m = Matrix::Identity(nx_, nx_) - c1 * h * a_matrix_;
      const Matrix sensitivity = c * m.partialPivLu().solve(c1 * h * d) + g;
      const Eigen::ColPivHouseholderQR<Matrix> qr(sensitivity);
      for (int k = 0; k < r; ++k) {
        best.push_back(candidates[static_cast<std::size_t>(qr.colsPermutation().indices()[k])]);
      }
      evaluate(best, &best_sigma);
      best_condition = best_sigma[0] / best_sigma[best_sigma.size() - 1];
    }
    basis_.basic = best;
    basis_.sigma_min = best_sigma[best_sigma.size() - 1];
    basis_.condition = best_condition;
    if (adaptive_ && r > 0) {
      // Error control picks h for accuracy, so the test must not depend on h: the active
      // constraints' sensitivity to the basic inputs through one step (the Schur complement
      // of B), S = C (I - c1 h A)^{-1} c1 h D_b + G_b, each row scaled to unit norm. Its
      // singular values measure the linear independence of the active constraints (LICQ),
      // O(1) for every index, where the scaled basis matrix's are O(h) for index 3.
      const double c1 = co.beta / co.gamma;
      Matrix d(nx_, r), g(r, r);
      for (int k = 0; k < r; ++k) {
        d.col(k) = d_matrix_.col(best[static_cast<std::size_t>(k)]);
        g.col(k) = g_all.col(best[static_cast<std::size_t>(k)]);
      }
      const Matrix through =
          (Matrix::Identity(nx_, nx_) - c1 * h * a_matrix_).partialPivLu().solve(c1 * h * d);
      Matrix sensitivity = c * through + g;
      const double through_norm = through.norm();
      for (int i = 0; i < r; ++i) {
        const double size = sensitivity.row(i).norm();
        const double bound = c.row(i).norm() * through_norm + g.row(i).norm();
        // A row at round-off level of its terms: the constraint does not see the inputs.
        if (size <= kNegligibleSensitivity * bound) {
          sensitivity.row(i).setZero();
        } else {
          sensitivity.row(i) /= size;
        }
      }
      const Eigen::VectorXd sigma = Eigen::JacobiSVD<Matrix>(sensitivity).singularValues();
      ++stats_.num_basis_factorizations;
      basis_.sigma_min = sigma[sigma.size() - 1];
      basis_.condition = sigma[0] / basis_.sigma_min;
    }
    return basis_.sigma_min > options_.rank_tolerance;
  }

  // The converged SQP of a step as a candidate: x, u, f and a (2b) at t1.
  bool Finish(double t1, double h_rule, double rho, int tries, const internal::SqpResult& sqp,
              Candidate* c) {
    const AlphaCoefficients co = AlphaCoefficients::FromRho(rho);
    c->t1 = t1;
    c->h = t1 - t_;
    c->h_rule = h_rule;
    c->rho = rho;
    c->tries = tries;
    c->sqp = sqp;
    c->basis = basis_;
    c->x1 = sqp.z.head(nx_);
    c->u1 = sqp.z.tail(nq_);
    c->f1 = EvaluateF(c->x1, c->u1, t1);
    // (2b)
    c->a1 = (c->f1 - f_) / (c->h * co.gamma) + (1.0 - 1.0 / co.gamma) * a_;
    c->active = ActiveIndices(sqp.working_set);
    c->binding = BindingIndices(*c);
    if (!c->f1.allFinite() || !c->a1.allFinite() || !c->x1.allFinite()) {
      c->status = AlphaDaiStatus::kNonFinite;
      c->reason = "f or a is not finite at the new point";
      return false;
    }
    return true;
  }

  // Accepts a candidate from the current state: certificates, events, statistics, trajectory.
  void Commit(const Candidate& c, double h_rule, AlphaDaiResult* result) {
    const AlphaCoefficients co = AlphaCoefficients::FromRho(c.rho);
    const double h = c.h;
    const double cc = co.beta / co.gamma;
    const Vector residual =
        c.x1 - x_ - (1.0 - cc) * h * f_ - cc * h * c.f1 - (0.5 - cc) * h * h * a_;
    AlphaDaiStep step;
    step.t = c.t1;
    step.h = h;
    step.h_rule = h_rule;
    step.rho = c.rho;
    step.tries = c.tries;
    step.sqp_iterations = c.sqp.iterations;
    step.dynamics_residual = (residual.array().abs() / (1.0 + x_.array().abs())).maxCoeff();
    step.acceleration_norm = c.a1.lpNorm<Eigen::Infinity>();
    Vector phi;
    EvaluatePhi(c.x1, c.u1, c.t1, &phi, nullptr, nullptr);
    double violation = nphi_ > 0 ? std::max(0.0, phi.maxCoeff()) : 0.0;
    violation = std::max(violation, (x_lower_ - c.x1).maxCoeff());
    violation = std::max(violation, (c.x1 - x_upper_).maxCoeff());
    if (nq_ > 0) {
      violation = std::max(violation, (u_lower_ - c.u1).maxCoeff());
      violation = std::max(violation, (c.u1 - u_upper_).maxCoeff());
    }
    step.constraint_violation = violation;
    step.kkt_residual = c.sqp.kkt_residual;
    step.num_active = c.basis.num_active;
    step.num_active_input_bounds = c.basis.num_input_bounds;
    step.basis_sigma_min = c.basis.sigma_min;
    step.basis_condition = c.basis.condition;
    step.active = c.active;
    for (int k : step.active) {
      if (!std::binary_search(active_.begin(), active_.end(), k)) {
        result->events.push_back(
            {c.t1, EventKind::kEnter, constraint_names_[static_cast<std::size_t>(k)], "active"});
      }
    }
    for (int k : active_) {
      if (!std::binary_search(step.active.begin(), step.active.end(), k)) {
        result->events.push_back(
            {c.t1, EventKind::kLeave, constraint_names_[static_cast<std::size_t>(k)], "inactive"});
      }
    }

    ++stats_.num_steps;
    stats_.max_constraint_violation = std::max(stats_.max_constraint_violation, violation);
    stats_.max_dynamics_residual = std::max(stats_.max_dynamics_residual, step.dynamics_residual);
    stats_.max_kkt_residual = std::max(stats_.max_kkt_residual, step.kkt_residual);
    stats_.min_basis_sigma = std::min(stats_.min_basis_sigma, step.basis_sigma_min);
    stats_.min_rho = std::min(stats_.min_rho, c.rho);
    stats_.min_step = std::min(stats_.min_step, h);

    Advance(c);
    scale_ = scale_.cwiseMax(x_.cwiseAbs());
    max_acceleration_ = std::max(max_acceleration_, a_.lpNorm<Eigen::Infinity>());
    last_step_ = h;
    if (options_.record_trajectory) {
      result->trajectory.Append(t_, x_, u_, h);
      result->steps.push_back(std::move(step));
    }
  }

  bool Fail(AlphaDaiResult* result, AlphaDaiStatus status, const std::string& reason) {
    result->status = status;
    std::ostringstream s;
    s.precision(17);
    s << ToString(status) << " at t = " << t_ << ": " << reason;
    result->message = s.str();
    return false;
  }

  const Scene& scene_;
  AlphaDaiOptions options_;
  ProgressCallback progress_;
  int nx_ = 0, nq_ = 0, nphi_ = 0;
  SmoothFunction dynamics_;
  std::vector<SmoothFunction> constraints_;
  std::vector<std::string> constraint_names_;
  std::vector<int> algebraic_;  // indices of the algebraic inputs among the scene's inputs
  Vector parameters_;
  Vector x_lower_, x_upper_, u_lower_, u_upper_;
  Vector inputs_;  // all inputs: controls of the current segment (algebraic entries unused)

  double t_ = 0.0;
  Vector x_, u_, f_, a_;
  double max_acceleration_ = 0.0;
  double h_previous_ = 0.0;  // fixed steps: the previous rule step
  double h_next_ = 0.0;      // error control: the next step
  double last_step_ = 0.0;
  bool adaptive_ = false;
  long crawling_steps_ = 0;    // accepted steps in a row that the crawl guard counts
  long stalled_attempts_ = 0;  // rejected or failed error-controlled steps below kStallFraction
  double horizon_ = 0.0;
  Vector scale_;  // largest |x_i| so far (atol = 0)
  std::vector<int> active_;

  // Jacobians at the SQP's last linearization point (for the basis matrix).
  Matrix a_matrix_, d_matrix_, phi_x_, phi_u_;
  BasisInfo basis_;
  AlphaDaiStats stats_;
  // Constraints between step ends (see kMaxInsideRetries).
  internal::InsideConstraintSearch inside_{constraints_, parameters_, algebraic_};
  int inside_retries_ = 0;      // consecutive retries for a crossing found inside a step
  int unresolved_retries_ = 0;  // consecutive retries for an undecided search
  double first_unresolved_time_ = std::numeric_limits<double>::infinity();
  int first_unresolved_constraint_ = -1;
};

}  // namespace

AlphaDaiResult SimulateAlphaDai(const Scene& scene, const AlphaDaiOptions& options,
                                const ProgressCallback& progress) {
  options.Validate();
  RequireSupportedEffects(scene, "alpha");
  ValidateScene(scene);
  AlphaDaiRun run(scene, options, progress);
  return run.Run();
}

}  // namespace moreau
