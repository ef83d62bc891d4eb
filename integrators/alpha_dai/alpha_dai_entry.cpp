// The alpha-method DAI stepper as Simulate() sees it (integrators/common/integrator_entry.hpp).
#include "../common/integrator_entry.hpp"
#include "moreau/integrators/alpha_dai.hpp"

namespace moreau::internal {

IntegratorEntry AlphaDaiEntry() {
  using O = AlphaDaiOptions;
  IntegratorSpec spec;
  spec.name = "alpha";
  spec.title = "the alpha-method DAI stepper";
  spec.description =
      "alpha-method DAI stepper with an active-set SQP per step (order 2 in x, rho "
      "regularization)";
  spec.supported_effects = {"path constraints"};
  spec.step_unit = "step";
  spec.iteration_unit = "SQP";
  std::vector<OptionBinding<O>> options = {
      BindReal("rho", &O::rho, "regularization rho in [0, 1) (spectral radius at infinity)"),
      BindReal("h", &O::max_step_size, "largest step h_max > 0 (the fixed step without errtol)"),
      BindReal("errtol", &O::error_tolerance,
               "ERRTOL > 0 of the step-size rule (inf: fixed steps h_max)"),
      BindReal("h_min", &O::min_step_size, "smallest step the rule may produce, > 0"),
      BindReal("tol", &O::constraint_tolerance, "phi <= tol at every accepted step, > 0"),
      BindReal("dynamics_tol", &O::dynamics_tolerance,
               "discretized dynamics hold to dynamics_tol (1 + |x|), > 0"),
      BindReal("optimality_tol", &O::optimality_tolerance,
               "stationarity of the local problem, > 0"),
      BindReal("rank_tol", &O::rank_tolerance,
               "singular-value cut-off of the scaled basis matrix, in (0, 1)"),
      BindInteger("max_sqp_iterations", &O::max_sqp_iterations, "SQP iterations per try, >= 1"),
      BindInteger("max_retries", &O::max_retries, "retries per step after the first try, >= 0"),
      BindChoice("objective", &O::objective, {"feasibility", "least-change", "reference"},
                 ParseAlphaDaiObjective, ToString,
                 "local objective for the algebraic inputs (docs/alpha-method.md)"),
      BindInteger("max_steps", &O::max_steps, "accepted steps before the run stops, >= 1"),
      BindBool("record_trajectory", &O::record_trajectory,
               "record every step and its certificates (false: initial and final points)"),
  };
  using S = AlphaDaiStats;
  std::vector<StatBinding<S>> stats = {
      BindStat("num_steps", &S::num_steps, "accepted steps"),
      BindStat("num_tries", &S::num_tries, "SQP solves (first tries and retries)"),
      BindStat("num_rho_reductions", &S::num_rho_reductions, "retries with rho lowered"),
      BindStat("num_guess_retries", &S::num_guess_retries, "retries from new initial guesses"),
      BindStat("num_rank_deficient", &S::num_rank_deficient,
               "tries stopped by a rank-deficient basis matrix"),
      BindStat("num_infeasible", &S::num_infeasible, "tries that ended locally infeasible"),
      BindStat("num_sqp_iterations", &S::num_sqp_iterations, "SQP iterations"),
      BindStat("num_qp_iterations", &S::num_qp_iterations, "active-set changes in all QPs"),
      BindStat("num_elastic_qps", &S::num_elastic_qps, "QPs re-solved in elastic mode"),
      BindStat("num_jacobian_evaluations", &S::num_jacobian_evaluations,
               "evaluations of f and phi with Jacobians"),
      BindStat("num_function_evaluations", &S::num_function_evaluations,
               "evaluations without Jacobians"),
      BindStat("num_basis_factorizations", &S::num_basis_factorizations, "SVDs of basis matrices"),
      BindStat("max_constraint_violation", &S::max_constraint_violation, "over accepted steps"),
      BindStat("max_dynamics_residual", &S::max_dynamics_residual, "over accepted steps"),
      BindStat("max_kkt_residual", &S::max_kkt_residual, "over accepted steps"),
      BindStat("min_basis_sigma", &S::min_basis_sigma, "over accepted steps (inf: none)"),
      BindStat("min_rho", &S::min_rho, "smallest rho used (inf: none)"),
      BindStat("min_step", &S::min_step, "smallest step taken (inf: none)"),
      BindStat("cpu_seconds", &S::cpu_seconds, "thread CPU time"),
  };
  return MakeEntry<O, AlphaDaiResult>(
      spec, options, stats, SimulateAlphaDai,
      [](const Scene&, const AlphaDaiResult& result, SimulationResult* out) {
        out->num_steps = result.stats.num_steps;
        out->num_iterations = result.stats.num_sqp_iterations;
        out->final_inputs = result.final_inputs;
        out->record_columns = {"t",
                               "h",
                               "h_rule",
                               "rho",
                               "tries",
                               "sqp_iterations",
                               "constraint_violation",
                               "dynamics_residual",
                               "kkt_residual",
                               "num_active",
                               "num_active_input_bounds",
                               "basis_sigma_min",
                               "basis_condition",
                               "acceleration_norm"};
        for (const AlphaDaiStep& step : result.steps) {
          out->records.push_back(
              {step.t, step.h, step.h_rule, step.rho, static_cast<double>(step.tries),
               static_cast<double>(step.sqp_iterations), step.constraint_violation,
               step.dynamics_residual, step.kkt_residual, static_cast<double>(step.num_active),
               static_cast<double>(step.num_active_input_bounds), step.basis_sigma_min,
               step.basis_condition, step.acceleration_norm});
        }
      });
}

}  // namespace moreau::internal
