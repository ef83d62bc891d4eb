// The smooth Radau IIA integrator as Simulate() sees it (integrators/common/integrator_entry.hpp).
#include "../common/integrator_entry.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/linalg/linear_solver.hpp"

namespace moreau::internal {

IntegratorEntry RadauEntry() {
  using O = RadauOptions;
  IntegratorSpec spec;
  spec.name = "radau";
  spec.title = "the smooth Radau IIA integrator";
  spec.description = "smooth Radau IIA (fixed step or adaptive); scenes without effects";
  spec.step_unit = "step";
  spec.iteration_unit = "Newton";
  std::vector<OptionBinding<O>> options = {
      BindInteger("stages", &O::stages, "Radau IIA stages s in 1..7 (order 2s - 1)"),
      BindReal("h", &O::step_size,
               "fixed step > 0; not given: error-controlled steps; with adaptive, rtol or atol "
               "the initial step"),
      BindBool("adaptive", &O::adaptive,
               "error-controlled steps even with h given (on whenever h is not given)"),
      BindReal("rtol", &O::relative_tolerance,
               "relative local-error tolerance, > 0 (with h: sets adaptive)"),
      BindReal("atol", &O::absolute_tolerance,
               "absolute local-error tolerance, > 0; 0: rtol times each state's largest "
               "magnitude so far (with h: sets adaptive)"),
      BindReal("h0", &O::initial_step_size,
               "initial step of the error-controlled steps, > 0 (0: automatic)"),
      BindReal("h_min", &O::min_step_size, "smallest error-controlled step, > 0"),
      BindReal("h_max", &O::max_step_size, "largest error-controlled step, > 0"),
      BindStopTimes(&O::stop_times),
      BindReal("newton_tol", &O::newton_tolerance,
               "Newton tolerance on max |dZ_i| / (1 + |y_i|) (fixed step), > 0"),
      BindInteger("max_newton_iterations", &O::max_newton_iterations,
                  "Newton iterations per step before it fails, >= 1"),
      BindInteger("max_steps", &O::max_steps,
                  "accepted steps before the run stops (a longer fixed grid is refused), >= 1"),
      BindBool("estimate_error", &O::estimate_error,
               "fixed steps: estimate the error of every step (error_estimate, a warning far "
               "above rtol)"),
      BindLinearSolver(&O::linear_solver),
      BindBool("record_trajectory", &O::record_trajectory,
               "record every step (false: initial and final points only)"),
  };
  using S = RadauStats;
  std::vector<StatBinding<S>> stats = {
      BindStat("num_steps", &S::num_steps, "accepted steps"),
      BindStat("num_rejected_steps", &S::num_rejected_steps,
               "error-test and Newton rejections (adaptive)"),
      BindStat("num_newton_iterations", &S::num_newton_iterations, "Newton iterations"),
      BindStat("num_factorizations", &S::num_factorizations, "LU factorizations"),
      BindStat("num_function_evaluations", &S::num_function_evaluations, "evaluations of f"),
      BindStat("num_jacobian_evaluations", &S::num_jacobian_evaluations,
               "evaluations of f with its Jacobian"),
      BindStat("error_estimate", &S::error_estimate,
               "accumulated local error estimates relative to the solution's scale (-1: not "
               "estimated)"),
      BindStat("cpu_seconds", &S::cpu_seconds, "thread CPU time"),
  };
  return MakeEntry<O, RadauResult>(
      spec, options, stats, SimulateRadau,
      [](const Scene&, const RadauResult& result, SimulationResult* out) {
        out->num_steps = result.stats.num_steps;
        out->num_iterations = result.stats.num_newton_iterations;
      },
      // As FESD: without h error-controlled steps, with h fixed ones (AdjustStepControl).
      AdjustStepControl<O>);
}

}  // namespace moreau::internal
