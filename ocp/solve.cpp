// SolveOcp: the shooting NLP handed to IPOPT (exact first derivatives as a sparse Jacobian,
// the Hessian approximation of OcpOptions::hessian), level by level through the homotopy,
// then verification of the optimal controls by an IDA re-simulation.

#include <IpIpoptApplication.hpp>
#include <IpTNLP.hpp>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>

#include "collocation.hpp"
#include "internal.hpp"
#include "moreau/core/clock.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/model/projection.hpp"
#include "nlp.hpp"

namespace moreau {
namespace {

using Ipopt::Index;
using Ipopt::Number;

// Warm starts (a level from the previous level's solution, or OcpOptions::warm_start with
// multipliers): IPOPT's push of the starting point off the bounds, relative and absolute
// (warm_start_*_push/frac; IPOPT's default 1e-3 would move a converged point away) and the
// initial barrier parameter (default 0.1, which re-centers the iterate; a converged
// neighbouring problem is already close to the central path's end).
constexpr double kWarmStartPush = 1e-9;
constexpr double kWarmStartBarrier = 1e-6;

// The shooting NLP behind the interface IPOPT's adapter takes.
class ShootingAdapter final : public ocp_internal::Nlp {
 public:
  explicit ShootingAdapter(ShootingNlp* nlp) : nlp_(nlp) {}
  int num_variables() const override { return nlp_->num_variables(); }
  int num_constraints() const override { return nlp_->num_constraints(); }
  const Vector& variable_lower() const override { return nlp_->variable_lower(); }
  const Vector& variable_upper() const override { return nlp_->variable_upper(); }
  const Vector& constraint_lower() const override { return nlp_->constraint_lower(); }
  const Vector& constraint_upper() const override { return nlp_->constraint_upper(); }
  bool Evaluate(const Vector& z, double* objective, Vector* constraints, Vector* gradient,
                Vector* jacobian_values, std::string* message) override {
    return nlp_->Evaluate(z, objective, constraints, gradient, jacobian_values, message);
  }
  const std::vector<std::pair<int, int>>& JacobianStructure() const override {
    return nlp_->JacobianStructure();
  }
  const std::vector<std::pair<int, int>>& HessianStructure() const override {
    return nlp_->HessianStructure();
  }
  bool Hessian(const Vector& z, double objective_factor, const Vector& lambda,
               const Vector& gradient, const Vector& jacobian_values,
               Vector* hessian_values) override {
    return nlp_->HessianApproximation(z, objective_factor, lambda, gradient, jacobian_values,
                                      hessian_values);
  }

 private:
  ShootingNlp* nlp_;
};

// IPOPT's view of an NLP at one level. IPOPT asks for the objective, its gradient, the
// constraints and their Jacobian separately at the same point; one evaluation with
// derivatives serves all of them (and the Hessian, which needs the Jacobian).
class OcpTnlp final : public Ipopt::TNLP {
 public:
  OcpTnlp(ocp_internal::Nlp* nlp, const Vector& start, const OcpMultipliers* multipliers,
          const OcpOptions& options, const OcpHomotopyLevel& parameters, int level, int levels,
          OcpResult* result)
      : nlp_(nlp),
        start_(start),
        multipliers_(multipliers),
        options_(options),
        parameters_(parameters),
        level_(level),
        levels_(levels),
        result_(result) {}

  bool get_nlp_info(Index& n, Index& m, Index& nnz_jac_g, Index& nnz_h_lag,
                    IndexStyleEnum& index_style) override {
    n = nlp_->num_variables();
    m = nlp_->num_constraints();
    nnz_jac_g = static_cast<Index>(nlp_->JacobianStructure().size());
    nnz_h_lag = static_cast<Index>(nlp_->HessianStructure().size());  // 0: limited memory
    index_style = C_STYLE;
    return true;
  }

  bool get_bounds_info(Index n, Number* x_l, Number* x_u, Index m, Number* g_l,
                       Number* g_u) override {
    std::copy_n(nlp_->variable_lower().data(), n, x_l);
    std::copy_n(nlp_->variable_upper().data(), n, x_u);
    std::copy_n(nlp_->constraint_lower().data(), m, g_l);
    std::copy_n(nlp_->constraint_upper().data(), m, g_u);
    return true;
  }

  bool get_starting_point(Index n, bool init_x, Number* x, bool init_z, Number* z_L, Number* z_U,
                          Index m, bool init_lambda, Number* lambda) override {
    if (init_x) std::copy_n(start_.data(), n, x);
    if (init_z || init_lambda) {
      // Only asked for with warm_start_init_point, which is set only with multipliers.
      if (multipliers_ == nullptr || multipliers_->empty()) return false;
      if (init_z) {
        std::copy_n(multipliers_->lower_bounds.data(), n, z_L);
        std::copy_n(multipliers_->upper_bounds.data(), n, z_U);
      }
      if (init_lambda) std::copy_n(multipliers_->constraints.data(), m, lambda);
    }
    return true;
  }

  bool eval_f(Index n, const Number* x, bool new_x, Number& obj_value) override {
    if (!Update(n, x, new_x)) return false;
    obj_value = objective_;
    return true;
  }
  bool eval_grad_f(Index n, const Number* x, bool new_x, Number* grad_f) override {
    if (!Update(n, x, new_x)) return false;
    std::copy_n(gradient_.data(), n, grad_f);
    return true;
  }
  bool eval_g(Index n, const Number* x, bool new_x, Index m, Number* g) override {
    if (!Update(n, x, new_x)) return false;
    std::copy_n(constraints_.data(), m, g);
    return true;
  }
  bool eval_jac_g(Index n, const Number* x, bool new_x, Index, Index, Index* i_row, Index* j_col,
                  Number* values) override {
    const auto& structure = nlp_->JacobianStructure();
    if (values == nullptr) {
      for (std::size_t k = 0; k < structure.size(); ++k) {
        i_row[k] = structure[k].first;
        j_col[k] = structure[k].second;
      }
      return true;
    }
    if (!Update(n, x, new_x)) return false;
    std::copy_n(jacobian_.data(), jacobian_.size(), values);
    return true;
  }
  bool eval_h(Index n, const Number* x, bool new_x, Number obj_factor, Index m,
              const Number* lambda, bool, Index, Index* i_row, Index* j_col,
              Number* values) override {
    const auto& structure = nlp_->HessianStructure();
    if (values == nullptr) {
      for (std::size_t k = 0; k < structure.size(); ++k) {
        i_row[k] = structure[k].first;
        j_col[k] = structure[k].second;
      }
      return true;
    }
    if (!Update(n, x, new_x)) return false;
    const Eigen::Map<const Vector> multipliers(lambda, m);
    if (!nlp_->Hessian(point_, obj_factor, multipliers, gradient_, jacobian_, &hessian_)) {
      return false;
    }
    std::copy_n(hessian_.data(), hessian_.size(), values);
    return true;
  }

  bool intermediate_callback(Ipopt::AlgorithmMode, Index iter, Number obj_value, Number inf_pr,
                             Number inf_du, Number, Number, Number, Number, Number, Index,
                             const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    result_->log.push_back({level_, iter, obj_value, inf_pr, inf_du});
    iterations_ = iter;
    if (options_.progress) {
      OcpProgress progress;
      progress.level = level_;
      progress.levels = levels_;
      progress.stages = options_.stages;
      progress.parameters = parameters_;
      progress.iteration = iter;
      progress.objective = obj_value;
      progress.primal_infeasibility = inf_pr;
      progress.dual_infeasibility = inf_du;
      options_.progress(progress);
    }
    return true;
  }

  void finalize_solution(Ipopt::SolverReturn status, Index n, const Number* x, const Number* z_L,
                         const Number* z_U, Index m, const Number*, const Number* lambda,
                         Number obj_value, const Ipopt::IpoptData*,
                         Ipopt::IpoptCalculatedQuantities*) override {
    solver_return_ = status;
    solution_ = Eigen::Map<const Vector>(x, n);
    solution_multipliers_.lower_bounds = Eigen::Map<const Vector>(z_L, n);
    solution_multipliers_.upper_bounds = Eigen::Map<const Vector>(z_U, n);
    solution_multipliers_.constraints = Eigen::Map<const Vector>(lambda, m);
    final_objective_ = obj_value;
  }

  Ipopt::SolverReturn solver_return() const { return solver_return_; }
  const Vector& solution() const { return solution_; }
  const OcpMultipliers& solution_multipliers() const { return solution_multipliers_; }
  double final_objective() const { return final_objective_; }
  int iterations() const { return iterations_; }
  const std::string& last_failure() const { return last_failure_; }

 private:
  bool Update(Index n, const Number* x, bool new_x) {
    const Eigen::Map<const Vector> z(x, n);
    if (!new_x && valid_ && z == point_) return true;
    point_ = z;
    std::string message;
    valid_ = nlp_->Evaluate(point_, &objective_, &constraints_, &gradient_, &jacobian_, &message);
    // An integration failure is an evaluation error: IPOPT shortens its step.
    if (!valid_) last_failure_ = message;
    return valid_;
  }

  ocp_internal::Nlp* nlp_;
  Vector start_;
  const OcpMultipliers* multipliers_;
  OcpOptions options_;
  OcpHomotopyLevel parameters_;
  int level_, levels_;
  OcpResult* result_;
  Vector point_;
  bool valid_ = false;
  double objective_ = 0.0;
  Vector constraints_, gradient_, jacobian_, hessian_;
  std::string last_failure_;
  Ipopt::SolverReturn solver_return_ = Ipopt::INTERNAL_ERROR;
  Vector solution_;
  OcpMultipliers solution_multipliers_;
  double final_objective_ = 0.0;
  int iterations_ = 0;
};

// IPOPT's name of its return status (IpReturnCodes_inc.h).
std::string IpoptStatusName(Ipopt::ApplicationReturnStatus status) {
  switch (status) {
    case Ipopt::Solve_Succeeded:
      return "Solve_Succeeded";
    case Ipopt::Solved_To_Acceptable_Level:
      return "Solved_To_Acceptable_Level";
    case Ipopt::Infeasible_Problem_Detected:
      return "Infeasible_Problem_Detected";
    case Ipopt::Search_Direction_Becomes_Too_Small:
      return "Search_Direction_Becomes_Too_Small";
    case Ipopt::Diverging_Iterates:
      return "Diverging_Iterates";
    case Ipopt::User_Requested_Stop:
      return "User_Requested_Stop";
    case Ipopt::Feasible_Point_Found:
      return "Feasible_Point_Found";
    case Ipopt::Maximum_Iterations_Exceeded:
      return "Maximum_Iterations_Exceeded";
    case Ipopt::Restoration_Failed:
      return "Restoration_Failed";
    case Ipopt::Error_In_Step_Computation:
      return "Error_In_Step_Computation";
    case Ipopt::Maximum_CpuTime_Exceeded:
      return "Maximum_CpuTime_Exceeded";
    case Ipopt::Not_Enough_Degrees_Of_Freedom:
      return "Not_Enough_Degrees_Of_Freedom";
    case Ipopt::Invalid_Problem_Definition:
      return "Invalid_Problem_Definition";
    case Ipopt::Invalid_Option:
      return "Invalid_Option";
    case Ipopt::Invalid_Number_Detected:
      return "Invalid_Number_Detected";
    default:
      return "IPOPT return status " + std::to_string(static_cast<int>(status));
  }
}

OcpStatus StatusOf(Ipopt::ApplicationReturnStatus status) {
  switch (status) {
    case Ipopt::Solve_Succeeded:
      return OcpStatus::kSolved;
    case Ipopt::Solved_To_Acceptable_Level:
      return OcpStatus::kSolvedToAcceptable;
    case Ipopt::Infeasible_Problem_Detected:
      return OcpStatus::kInfeasible;
    case Ipopt::Maximum_Iterations_Exceeded:
      return OcpStatus::kMaxIterations;
    default:
      return OcpStatus::kSolverFailure;
  }
}

// Re-simulates the optimal controls with IDA (reference settings) in physical time.
// Steps of the FESD re-simulation per control interval.
constexpr double kFesdVerificationRefinement = 10.0;

// max(|g|, h^+) of the terminal constraints at x(T).
double TerminalError(const OcpProblem& problem, const Vector& x, const Vector& u, double t,
                     const Vector& p) {
  double error = 0.0;
  Vector value;
  if (!problem.terminal_equalities.empty()) {
    problem.terminal_equalities.Evaluate(x, u, t, p, &value);
    error = std::max(error, value.lpNorm<Eigen::Infinity>());
  }
  if (!problem.terminal_inequalities.empty()) {
    problem.terminal_inequalities.Evaluate(x, u, t, p, &value);
    error = std::max(error, value.cwiseMax(0.0).lpNorm<Eigen::Infinity>());
  }
  return error;
}

void Verify(const OcpProblem& problem, OcpResult* result) {
  const RunClock run_clock;
  Scene scene = problem.scene;
  scene.initial_time = result->grid.front();
  // An initial state outside the moving sets jumps onto them at t0 (FESD does the same), and
  // IDA starts from the projected state.
  scene.initial_state = result->initial_state;
  if (MinimumMovingSetConstraint(scene, scene.initial_state, scene.initial_time,
                                 scene.InputValues(scene.initial_time),
                                 scene.ParameterValues()) < 0.0) {
    const MovingSetProjection projection = ProjectOntoMovingSets(
        scene, scene.initial_state, scene.initial_time, scene.InputValues(scene.initial_time),
        scene.ParameterValues(), false);
    if (!projection.converged) {
      result->verification_message = "projection of x0 for IDA failed: " + projection.message;
      return;
    }
    scene.initial_state = projection.x;
  }
  scene.final_time = result->grid.back();
  // Controls piecewise constant between the physical grid times (intervals that are entirely
  // frozen have zero physical length and are dropped).
  std::vector<double> breakpoints;
  std::vector<int> rows{0};
  for (std::size_t k = 1; k + 1 < result->grid.size(); ++k) {
    const double t = result->grid[k];
    const double previous = breakpoints.empty() ? scene.initial_time : breakpoints.back();
    if (t > previous + 1e-12 * (1.0 + std::fabs(t)) && t < scene.final_time) {
      breakpoints.push_back(t);
      rows.push_back(static_cast<int>(k));
    } else {
      rows.back() = static_cast<int>(k);  // the later control acts on the merged piece
    }
  }
  for (std::size_t j = 0; j < problem.controls.size(); ++j) {
    PiecewiseConstantSignal& signal =
        scene.inputs[static_cast<std::size_t>(problem.controls[j])].signal;
    signal.breakpoints = breakpoints;
    signal.values.clear();
    for (int k : rows) signal.values.push_back(result->controls(k, static_cast<Eigen::Index>(j)));
  }
  try {
    const IdaResult ida = SimulateIda(scene, IdaOptions::Reference());
    if (ida.status != IdaStatus::kSuccess) {
      result->verification_message = "IDA re-simulation failed: " + ida.message;
    } else {
      result->verified = true;
      result->resimulated_final_state = ida.final_state;
      result->resimulated_state_difference =
          (ida.final_state - result->final_state).lpNorm<Eigen::Infinity>();
      result->resimulated_terminal_error =
          TerminalError(problem, ida.final_state, scene.InputValues(scene.final_time),
                        ida.final_time, scene.ParameterValues());
    }
  } catch (const std::exception& error) {
    result->verification_message = std::string("IDA re-simulation refused: ") + error.what();
  }
  // A second, independent re-simulation: FESD with switch detection on a grid ten times finer
  // than the control grid (three elements per step, s = 3), another discretization than the
  // NLP's: two integrators that agree on the controls' trajectory certify it (on the doorway
  // to 3.5e-11, docs/ocp.md). (Adaptive FESD fails to locate a grazing switch of the doorway at
  // a control breakpoint, hence fixed steps.)
  try {
    FesdOptions fesd;
    fesd.stages = 3;
    fesd.finite_elements = 3;
    fesd.step_size = (result->grid.back() - result->grid.front()) /
                     (static_cast<double>(result->grid.size() - 1) * kFesdVerificationRefinement);
    fesd.keep_elements_after_early_switch = true;
    fesd.estimate_error = false;  // compared with IDA's reference instead
    const FesdResult run = SimulateFesd(scene, fesd);
    if (run.status == FesdStatus::kSuccess) {
      result->fesd_verified = true;
      result->fesd_resimulated_final_state = run.final_state;
      result->fesd_resimulated_state_difference =
          (run.final_state - result->final_state).lpNorm<Eigen::Infinity>();
      result->fesd_resimulated_terminal_error =
          TerminalError(problem, run.final_state, scene.InputValues(scene.final_time),
                        run.final_time, scene.ParameterValues());
    } else {
      result->fesd_verification_message = "FESD re-simulation failed: " + run.message;
    }
  } catch (const std::exception& error) {
    result->fesd_verification_message = std::string("FESD re-simulation refused: ") + error.what();
  }
  result->stats.verification_seconds = run_clock.CpuSeconds();
}

}  // namespace

namespace {

// Solves one level with IPOPT from z (and multipliers, if any): a primal-dual warm start keeps
// the iterate where it is. On return z and multipliers hold IPOPT's last iterate (also when it
// stopped early), and the level's result is appended to result->levels.
OcpLevelResult RunLevel(ocp_internal::Nlp* nlp, const OcpOptions& options,
                        const OcpHomotopyLevel& parameters, int level, int num_levels, bool exact,
                        Vector* z, OcpMultipliers* multipliers, OcpResult* result) {
  const RunClock level_clock;
  Ipopt::SmartPtr<Ipopt::IpoptApplication> app = IpoptApplicationFactory();
  const double tolerance = exact ? options.tolerance : options.level_tolerance;
  app->Options()->SetNumericValue("tol", tolerance);
  app->Options()->SetNumericValue("constr_viol_tol", tolerance);
  app->Options()->SetIntegerValue("max_iter", options.max_iterations);
  app->Options()->SetIntegerValue("print_level", options.print_level);
  app->Options()->SetStringValue("sb", "yes");  // no banner
  // IPOPT relaxes bounds by 1e-8 (relative) internally; moving the solution back onto the
  // original bounds afterwards (honor_original_bounds) would break the continuity
  // constraints it satisfied by ~1e-7 (sensitivities of order 10). The iterate is returned
  // as converged.
  app->Options()->SetStringValue("honor_original_bounds", "no");
  app->Options()->SetNumericValue("bound_relax_factor", options.bound_relaxation);
  if (options.regularize_constraints) {
    app->Options()->SetStringValue("perturb_always_cd", "yes");
  }
  if (nlp->HessianStructure().empty()) {
    app->Options()->SetStringValue("hessian_approximation", "limited-memory");
    app->Options()->SetIntegerValue("limited_memory_max_history", options.lbfgs_memory);
  }
  if (!multipliers->empty()) {
    // A primal-dual warm start (the previous level's solution): keep the iterate where it
    // is instead of pushing it into the interior, and start the barrier parameter small.
    app->Options()->SetStringValue("warm_start_init_point", "yes");
    app->Options()->SetNumericValue("warm_start_bound_push", kWarmStartPush);
    app->Options()->SetNumericValue("warm_start_bound_frac", kWarmStartPush);
    app->Options()->SetNumericValue("warm_start_slack_bound_push", kWarmStartPush);
    app->Options()->SetNumericValue("warm_start_slack_bound_frac", kWarmStartPush);
    app->Options()->SetNumericValue("warm_start_mult_bound_push", kWarmStartPush);
    app->Options()->SetNumericValue("mu_init", kWarmStartBarrier);
  }
  MOREAU_ASSERT(app->Initialize() == Ipopt::Solve_Succeeded, "IPOPT initialization failed");
  auto* tnlp = new OcpTnlp(nlp, *z, multipliers->empty() ? nullptr : multipliers, options,
                           parameters, level, num_levels, result);
  Ipopt::SmartPtr<Ipopt::TNLP> holder(tnlp);
  const Ipopt::ApplicationReturnStatus status = app->OptimizeTNLP(holder);
  OcpLevelResult level_result;
  level_result.parameters = parameters;
  level_result.status = StatusOf(status);
  std::ostringstream s;
  s << "IPOPT: " << IpoptStatusName(status);
  if (!tnlp->last_failure().empty() && level_result.status == OcpStatus::kSolverFailure) {
    s << "; last evaluation failure: " << tnlp->last_failure();
  }
  level_result.message = s.str();
  level_result.iterations = tnlp->iterations();
  level_result.objective = tnlp->final_objective();
  level_result.seconds = level_clock.CpuSeconds();
  result->levels.push_back(level_result);
  result->stats.iterations += level_result.iterations;
  if (tnlp->solution().size() == z->size() && tnlp->solution().allFinite()) {
    *z = tnlp->solution();
    *multipliers = tnlp->solution_multipliers();
  }
  if (exact) {
    result->status = level_result.status;
    result->message = level_result.message;
    result->objective = level_result.objective;
  }
  return level_result;
}

void CheckWarmStart(const ocp_internal::Nlp& nlp, const OcpOptions& options, Vector* z,
                    OcpMultipliers* multipliers) {
  if (options.warm_start.size() > 0) {
    RequireArgument(options.warm_start.size() == z->size(), "warm start has ",
                    options.warm_start.size(), " variables, the NLP ", z->size());
    *z = options.warm_start;
  }
  *multipliers = options.warm_start_multipliers;
  if (!multipliers->empty()) {
    RequireArgument(multipliers->constraints.size() == nlp.num_constraints() &&
                        multipliers->lower_bounds.size() == nlp.num_variables() &&
                        multipliers->upper_bounds.size() == nlp.num_variables(),
                    "warm-start multipliers need ", nlp.num_constraints(), " constraint and ",
                    nlp.num_variables(), " bound multipliers each, got ",
                    multipliers->constraints.size(), ", ", multipliers->lower_bounds.size(),
                    " and ", multipliers->upper_bounds.size());
  }
}

// Decisions of `coarse` (controls, then speeds) held on the intervals of an N-interval grid:
// fine interval k takes the decisions of the coarse interval containing its midpoint (exact
// refinement when N is a multiple of the coarse count).
Matrix ProlongateDecisions(const OcpResult& coarse, int intervals) {
  const auto nc = coarse.controls.cols();
  const bool speeds = coarse.speeds.size() > 0;
  const auto coarse_intervals = coarse.controls.rows();
  Matrix decisions(intervals, nc + (speeds ? 1 : 0));
  for (int k = 0; k < intervals; ++k) {
    const auto j = std::min<Eigen::Index>(
        coarse_intervals - 1,
        static_cast<Eigen::Index>((k + 0.5) * static_cast<double>(coarse_intervals) / intervals));
    decisions.row(k).head(nc) = coarse.controls.row(j);
    if (speeds) decisions(k, nc) = coarse.speeds[j];
  }
  return decisions;
}

// One shooting solve: the homotopy levels of `levels` then the exact problem (`levels` ends
// with it), from `start` (empty: the NLP's initial guess or OcpOptions::warm_start).
void SolveShootingLevels(const OcpProblem& problem, const OcpOptions& options,
                         const std::vector<OcpHomotopyLevel>& levels, const Vector& start,
                         OcpResult* result) {
  ShootingNlp nlp(problem, options);
  ShootingAdapter adapter(&nlp);
  const int num_levels = static_cast<int>(levels.size());
  nlp.SetLevel(levels.front());
  Vector z = start.size() > 0 ? start : nlp.InitialGuess();
  OcpMultipliers multipliers;
  if (start.size() == 0) CheckWarmStart(adapter, options, &z, &multipliers);
  std::string message;
  if (!nlp.Evaluate(z, nullptr, nullptr, nullptr, nullptr, &message)) {
    result->status = OcpStatus::kSimulationFailure;
    result->message = "the initial guess cannot be simulated: " + message;
    return;
  }
  result->stats.jacobian_nonzeros = static_cast<long>(nlp.JacobianStructure().size());
  result->stats.hessian_nonzeros = static_cast<long>(nlp.HessianStructure().size());
  for (int level = 0; level < num_levels; ++level) {
    const bool exact = level == num_levels - 1;
    nlp.SetLevel(levels[static_cast<std::size_t>(level)]);
    RunLevel(&adapter, options, levels[static_cast<std::size_t>(level)], level, num_levels, exact,
             &z, &multipliers, result);
    result->levels.back().intervals = problem.intervals;
  }
  result->multipliers = multipliers;
  nlp.Describe(z, result);
  result->stats.simulations += nlp.simulations();
  result->stats.fesd_elements += nlp.fesd_elements();
}

OcpResult SolveByShooting(const OcpProblem& problem, const OcpOptions& options) {
  const RunClock run_clock;
  RequireArgument(options.hessian != OcpHessian::kSecondOrder, problem.name,
                  ": second-order Hessians need the collocation transcription (FESD computes no "
                  "second-order sensitivities)");
  OcpResult result;
  std::vector<OcpHomotopyLevel> levels = options.homotopy;
  levels.push_back(OcpHomotopyLevel{});
  // The continuation's counts below the problem's N, then N.
  std::vector<int> counts;
  for (int count : options.mesh_continuation) {
    if (count < problem.intervals) counts.push_back(count);
  }
  if (counts.empty()) {
    SolveShootingLevels(problem, options, levels, Vector(), &result);
  } else {
    counts.push_back(problem.intervals);
    Vector free_initial;
    for (std::size_t stage = 0; stage < counts.size(); ++stage) {
      OcpProblem coarse = problem;
      coarse.intervals = counts[stage];
      if (coarse.intervals != problem.intervals && problem.initial_controls.size() > 0) {
        // The problem's guess resampled on the coarser grid.
        OcpResult guess;
        guess.controls = problem.initial_controls;
        coarse.initial_controls = ProlongateDecisions(guess, coarse.intervals);
      }
      if (stage == 0) {
        SolveShootingLevels(coarse, options, levels, Vector(), &result);
      } else {
        ShootingNlp fine(coarse, options);
        const Matrix decisions = ProlongateDecisions(result, coarse.intervals);
        free_initial.resize(static_cast<Eigen::Index>(problem.free_initial_states.size()));
        for (std::size_t i = 0; i < problem.free_initial_states.size(); ++i) {
          free_initial[static_cast<Eigen::Index>(i)] =
              result.initial_state[problem.free_initial_states[i].state];
        }
        const Vector z = fine.PointFromDecisions(decisions, free_initial);
        SolveShootingLevels(coarse, options, {OcpHomotopyLevel{}}, z, &result);
      }
      if (result.status == OcpStatus::kSimulationFailure) break;
    }
  }
  result.stats.cpu_seconds = run_clock.CpuSeconds();
  return result;
}

// The collocation transcription: the relaxed levels of OcpOptions::homotopy (each with
// complementarity > 0), then the exact level on the pieces of the last relaxed solution.
OcpResult SolveByCollocation(const OcpProblem& problem, const OcpOptions& options) {
  const RunClock run_clock;
  ocp_internal::CollocationNlp nlp(problem, options);
  RequireArgument(!options.homotopy.empty(), problem.name,
                  ": the collocation transcription needs homotopy levels with a complementarity "
                  "relaxation > 0 (the exact level takes its pieces from the last of them)");
  for (const OcpHomotopyLevel& level : options.homotopy) nlp.SetRelaxedLevel(level);
  OcpResult result;
  const int num_levels = static_cast<int>(options.homotopy.size()) + 1;
  Vector z = nlp.InitialGuess();
  OcpMultipliers multipliers;
  CheckWarmStart(nlp, options, &z, &multipliers);
  result.stats.jacobian_nonzeros = static_cast<long>(nlp.JacobianStructure().size());
  result.stats.hessian_nonzeros = static_cast<long>(nlp.HessianStructure().size());
  auto record = [&](int stages) {
    result.levels.back().intervals = problem.intervals;
    result.levels.back().stages = stages;
  };
  for (int level = 0; level + 1 < num_levels; ++level) {
    const OcpHomotopyLevel& parameters = options.homotopy[static_cast<std::size_t>(level)];
    nlp.SetRelaxedLevel(parameters);
    RunLevel(&nlp, options, parameters, level, num_levels, false, &z, &multipliers, &result);
    record(options.stages);
  }
  nlp.SetExactLevel(z);
  // The exact level's bounds differ (multipliers fixed to zero on inactive pieces): the bound
  // multipliers carry over, IPOPT's push keeps the point where it is.
  RunLevel(&nlp, options, OcpHomotopyLevel{}, num_levels - 1, num_levels, true, &z, &multipliers,
           &result);
  record(options.stages);
  // Then the same pieces with every free constraint's minimum over each element >= 0, from that
  // solution: the check points leave corners between them that the optimum may cut, and its
  // controls then produce contacts the NLP does not have (docs/ocp.md, "Doorway"). From the
  // exact solution the corners are small; an earlier form of these rows, started from a
  // relaxed solution with corners down to c = -6.5e-2, did not converge in 1000 iterations.
  const int rows = nlp.num_constraints();
  if (options.collocation_element_minima && result.status == OcpStatus::kSolved) {
    nlp.ImposeElementMinima(z, &multipliers.constraints);
    RunLevel(&nlp, options, OcpHomotopyLevel{}, num_levels - 1, num_levels, true, &z, &multipliers,
             &result);
    record(options.stages);
  }
  // The refinement: the exact level once more with more stages, from this solution
  // interpolated (docs/ocp.md, "Doorway": the s = 3 collocation error after contacts begin was
  // most of the gap between the NLP's trajectory and the re-simulation of its controls).
  ocp_internal::CollocationNlp* solved = &nlp;
  std::unique_ptr<ocp_internal::CollocationNlp> refined;
  int solved_rows = rows;  // the solved NLP's rows without the element minima
  if (options.collocation_refinement_stages > 0 && result.status == OcpStatus::kSolved) {
    OcpOptions refined_options = options;
    refined_options.stages = options.collocation_refinement_stages;
    refined_options.collocation_refinement_stages = 0;  // refined once
    refined = std::make_unique<ocp_internal::CollocationNlp>(problem, refined_options);
    solved_rows = refined->num_constraints();
    refined->SetRefinedLevel(nlp);
    OcpMultipliers refined_multipliers;
    Vector refined_z = refined->Interpolate(nlp, z, multipliers, &refined_multipliers);
    const OcpStatus coarse_status = result.status;
    const std::string coarse_message = result.message;
    const double coarse_objective = result.objective;
    RunLevel(refined.get(), refined_options, OcpHomotopyLevel{}, num_levels - 1, num_levels, true,
             &refined_z, &refined_multipliers, &result);
    record(refined_options.stages);
    if (result.status == OcpStatus::kSolved) {
      z = refined_z;
      multipliers = refined_multipliers;
      solved = refined.get();
    } else {
      // The coarse solution stays the answer (solved); the failed refinement is in the levels.
      result.message = coarse_message +
                       "; the refinement to s = " + std::to_string(refined_options.stages) +
                       " ended " + ToString(result.status) + " (" + result.levels.back().message +
                       "), the s = " + std::to_string(options.stages) + " solution is returned";
      result.status = coarse_status;
      result.objective = coarse_objective;
      solved_rows = rows;
    }
  }
  // The returned multipliers warm-start a new solve, which starts without the appended rows.
  if (multipliers.constraints.size() > solved_rows) {
    multipliers.constraints.conservativeResize(solved_rows);
  }
  result.multipliers = multipliers;
  solved->Describe(z, &result);
  result.complementarity_residual = solved->ComplementarityResidual(z);
  result.stats.cpu_seconds = run_clock.CpuSeconds();
  return result;
}

}  // namespace

OcpResult SolveOcp(const OcpProblem& problem, const OcpOptions& options) {
  OcpResult result = options.transcription == OcpTranscription::kCollocation
                         ? SolveByCollocation(problem, options)
                         : SolveByShooting(problem, options);
  if (options.verify && result.status != OcpStatus::kSimulationFailure) {
    Verify(problem, &result);
    // Solved only if a re-simulation reproduces the optimum's trajectory.
    const double infinity = std::numeric_limits<double>::infinity();
    result.verification_gap =
        std::min(result.verified ? result.resimulated_state_difference : infinity,
                 result.fesd_verified ? result.fesd_resimulated_state_difference : infinity);
    const double allowed =
        kOcpVerificationTolerance * std::max(1.0, result.final_state.lpNorm<Eigen::Infinity>());
    const bool solved =
        result.status == OcpStatus::kSolved || result.status == OcpStatus::kSolvedToAcceptable;
    if (solved && !(result.verification_gap <= allowed)) {
      std::ostringstream message;
      message.precision(3);
      message << "the NLP is " << ToString(result.status)
              << (result.message.empty() ? "" : " (" + result.message + ")")
              << ", but its controls re-simulated end ";
      if (std::isfinite(result.verification_gap)) {
        message << result.verification_gap << " from its x(T) (IDA "
                << (result.verified ? result.resimulated_state_difference : infinity) << ", FESD "
                << (result.fesd_verified ? result.fesd_resimulated_state_difference : infinity)
                << "), above the verification tolerance " << allowed << " = "
                << kOcpVerificationTolerance
                << " max(1, |x(T)|): refine the discretization (more intervals N, elements or "
                   "stages)";
      } else {
        message << "nowhere: no re-simulation succeeded (" << result.verification_message << "; "
                << result.fesd_verification_message << ")";
      }
      result.status = OcpStatus::kNotVerified;
      result.message = message.str();
    }
  }
  return result;
}

}  // namespace moreau
