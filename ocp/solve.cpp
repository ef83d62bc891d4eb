// SolveOcp: the shooting NLP handed to IPOPT (exact first derivatives, limited-memory
// Hessian), then verification of the optimal controls by an IDA re-simulation.

#include <IpIpoptApplication.hpp>
#include <IpTNLP.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "internal.hpp"
#include "moreau/core/error.hpp"
#include "moreau/model/projection.hpp"

namespace moreau {
namespace {

using Ipopt::Index;
using Ipopt::Number;

// IPOPT's view of the shooting NLP. IPOPT asks for the objective, its gradient, the
// constraints and their Jacobian separately at the same point; one evaluation with
// derivatives serves all of them.
class ShootingTnlp final : public Ipopt::TNLP {
 public:
  ShootingTnlp(ShootingNlp* nlp, const Vector& start, const OcpOptions& options, OcpResult* result)
      : nlp_(nlp), start_(start), options_(options), result_(result) {}

  bool get_nlp_info(Index& n, Index& m, Index& nnz_jac_g, Index& nnz_h_lag,
                    IndexStyleEnum& index_style) override {
    n = nlp_->num_variables();
    m = nlp_->num_constraints();
    nnz_jac_g = static_cast<Index>(nlp_->JacobianStructure().size());
    nnz_h_lag = 0;  // limited-memory Hessian
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

  bool get_starting_point(Index n, bool init_x, Number* x, bool init_z, Number*, Number*, Index,
                          bool init_lambda, Number*) override {
    if (!init_x || init_z || init_lambda) return false;  // primal starts only
    std::copy_n(start_.data(), n, x);
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
    for (std::size_t k = 0; k < structure.size(); ++k) {
      values[k] = jacobian_(structure[k].first, structure[k].second);
    }
    return true;
  }

  bool intermediate_callback(Ipopt::AlgorithmMode, Index iter, Number obj_value, Number inf_pr,
                             Number inf_du, Number, Number, Number, Number, Number, Index,
                             const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    result_->log.push_back({iter, obj_value, inf_pr, inf_du});
    if (options_.progress) options_.progress(iter, obj_value, inf_pr);
    return true;
  }

  void finalize_solution(Ipopt::SolverReturn status, Index n, const Number* x, const Number*,
                         const Number*, Index, const Number*, const Number*, Number obj_value,
                         const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    solver_return_ = status;
    solution_ = Eigen::Map<const Vector>(x, n);
    final_objective_ = obj_value;
  }

  Ipopt::SolverReturn solver_return() const { return solver_return_; }
  const Vector& solution() const { return solution_; }
  double final_objective() const { return final_objective_; }
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

  ShootingNlp* nlp_;
  Vector start_;
  OcpOptions options_;
  OcpResult* result_;
  Vector point_;
  bool valid_ = false;
  double objective_ = 0.0;
  Vector constraints_, gradient_;
  Matrix jacobian_;
  std::string last_failure_;
  Ipopt::SolverReturn solver_return_ = Ipopt::INTERNAL_ERROR;
  Vector solution_;
  double final_objective_ = 0.0;
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
void Verify(const OcpProblem& problem, OcpResult* result) {
  const auto start = std::chrono::steady_clock::now();
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
      const Vector u = scene.InputValues(scene.final_time);
      const Vector p = scene.ParameterValues();
      double error = 0.0;
      Vector value;
      if (!problem.terminal_equalities.empty()) {
        problem.terminal_equalities.Evaluate(ida.final_state, u, ida.final_time, p, &value);
        error = std::max(error, value.lpNorm<Eigen::Infinity>());
      }
      if (!problem.terminal_inequalities.empty()) {
        problem.terminal_inequalities.Evaluate(ida.final_state, u, ida.final_time, p, &value);
        error = std::max(error, value.cwiseMax(0.0).lpNorm<Eigen::Infinity>());
      }
      result->resimulated_terminal_error = error;
    }
  } catch (const std::exception& error) {
    result->verification_message = std::string("IDA re-simulation refused: ") + error.what();
  }
  result->stats.verification_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

OcpResult SolveOcp(const OcpProblem& problem, const OcpOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ShootingNlp nlp(problem, options);
  OcpResult result;
  Vector z0 = nlp.InitialGuess();
  if (options.warm_start.size() > 0) {
    RequireArgument(options.warm_start.size() == z0.size(), "warm start has ",
                    options.warm_start.size(), " variables, the NLP ", z0.size());
    z0 = options.warm_start;
  }
  std::string message;
  if (!nlp.Evaluate(z0, nullptr, nullptr, nullptr, nullptr, &message)) {
    result.status = OcpStatus::kSimulationFailure;
    result.message = "the initial guess cannot be simulated: " + message;
    return result;
  }

  Ipopt::SmartPtr<Ipopt::IpoptApplication> app = IpoptApplicationFactory();
  app->Options()->SetNumericValue("tol", options.tolerance);
  app->Options()->SetNumericValue("constr_viol_tol", options.tolerance);
  app->Options()->SetIntegerValue("max_iter", options.max_iterations);
  app->Options()->SetIntegerValue("print_level", options.print_level);
  app->Options()->SetStringValue("sb", "yes");  // no banner
  // IPOPT relaxes bounds by 1e-8 (relative) internally; moving the solution back onto the
  // original bounds afterwards (honor_original_bounds) would break the continuity constraints
  // it satisfied by ~1e-7 (sensitivities of order 10). The iterate is returned as converged.
  app->Options()->SetStringValue("honor_original_bounds", "no");
  app->Options()->SetNumericValue("bound_relax_factor", options.bound_relaxation);
  app->Options()->SetStringValue("hessian_approximation", "limited-memory");
  app->Options()->SetIntegerValue("limited_memory_max_history", options.lbfgs_memory);
  if (options.warm_start.size() > 0) {
    app->Options()->SetStringValue("warm_start_init_point", "yes");
  }
  MOREAU_ASSERT(app->Initialize() == Ipopt::Solve_Succeeded, "IPOPT initialization failed");
  auto* tnlp = new ShootingTnlp(&nlp, z0, options, &result);
  Ipopt::SmartPtr<Ipopt::TNLP> holder(tnlp);
  const Ipopt::ApplicationReturnStatus status = app->OptimizeTNLP(holder);
  result.status = StatusOf(status);
  std::ostringstream s;
  s << "IPOPT: " << IpoptStatusName(status);
  if (!tnlp->last_failure().empty() && result.status == OcpStatus::kSolverFailure) {
    s << "; last evaluation failure: " << tnlp->last_failure();
  }
  result.message = s.str();
  result.stats.iterations = result.log.empty() ? 0 : result.log.back().iteration;
  const Vector solution = tnlp->solution().size() == z0.size() ? tnlp->solution() : z0;
  result.objective = tnlp->final_objective();
  nlp.Describe(solution, &result);
  result.stats.simulations = nlp.simulations();
  result.stats.fesd_elements = nlp.fesd_elements();
  result.stats.cpu_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (options.verify) Verify(problem, &result);
  return result;
}

}  // namespace moreau
