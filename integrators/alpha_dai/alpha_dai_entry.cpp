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
      BindReal("h", &O::step_size,
               "fixed step h > 0 (the paper's h_max with errtol); not given: error-controlled "
               "steps (step doubling); with adaptive, rtol or atol the initial step"),
      BindBool("adaptive", &O::adaptive,
               "error-controlled steps even with h given (on whenever h is not given)"),
      BindReal("rtol", &O::relative_tolerance,
               "relative tolerance of the error-controlled steps, > 0 (with h: sets adaptive)"),
      BindReal("atol", &O::absolute_tolerance,
               "absolute tolerance of the error-controlled steps, > 0; 0: rtol times each "
               "state's largest magnitude so far (with h: sets adaptive)"),
      BindReal("h0", &O::initial_step_size,
               "initial step of the error-controlled steps, > 0 (0: automatic)"),
      BindReal("h_min", &O::min_step_size, "smallest error-controlled step, > 0"),
      BindReal("h_max", &O::max_step_size, "largest error-controlled step, >= 0 (0: no bound)"),
      BindReal("errtol", &O::error_tolerance,
               "ERRTOL > 0 of the paper's step-size rule with a fixed step h (inf: fixed steps "
               "h)"),
      BindBool("estimate_error", &O::estimate_error,
               "fixed steps: estimate the error of every step by step doubling (error_estimate, "
               "a warning far above rtol)"),
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
      BindStat("num_rejected_steps", &S::num_rejected_steps,
               "error-controlled steps rejected (error test or event rule)"),
      BindStat("num_event_rejections", &S::num_event_rejections,
               "steps rejected because the working set changed in a step longer than rtol "
               "(tf - t0)"),
      BindStat("num_failed_steps", &S::num_failed_steps,
               "error-controlled steps whose SQP failed, retried shorter"),
      BindStat("error_estimate", &S::error_estimate,
               "accumulated local error estimates relative to the solution's scale (-1: not "
               "estimated)"),
      BindStat("num_unestimated_steps", &S::num_unestimated_steps,
               "fixed steps whose error could not be estimated"),
      BindStat("num_inside_crossings", &S::num_inside_crossings,
               "steps in which a path constraint was found above tol between the step's ends "
               "(error control: retried ending on the crossing)"),
      BindStat("num_unresolved_crossings", &S::num_unresolved_crossings,
               "steps accepted although a path constraint may exceed tol between their ends "
               "(a warning names the first)"),
      BindStat("num_bound_evaluations", &S::num_bound_evaluations,
               "interval evaluations of the path constraints over steps"),
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
      },
      // Without h error-controlled steps, with h fixed ones (see AdjustStepControl).
      AdjustStepControl<O>);
}

}  // namespace moreau::internal
