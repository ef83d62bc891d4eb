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
               "step size > 0 (with adaptive: the initial step; automatic when not given)"),
      BindBool("adaptive", &O::adaptive, "step-size control by the embedded error estimate"),
      BindReal("rtol", &O::relative_tolerance, "relative local-error tolerance (adaptive), > 0"),
      BindReal("atol", &O::absolute_tolerance, "absolute local-error tolerance (adaptive), > 0"),
      BindReal("h_min", &O::min_step_size, "smallest step of the controller (adaptive), > 0"),
      BindReal("h_max", &O::max_step_size, "largest step of the controller (adaptive), > 0"),
      BindStopTimes(&O::stop_times),
      BindReal("newton_tol", &O::newton_tolerance,
               "Newton tolerance on max |dZ_i| / (1 + |y_i|) (fixed step), > 0"),
      BindInteger("max_newton_iterations", &O::max_newton_iterations,
                  "Newton iterations per step before it fails, >= 1"),
      BindInteger("max_steps", &O::max_steps, "accepted steps before the run stops, >= 1"),
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
      BindStat("cpu_seconds", &S::cpu_seconds, "thread CPU time"),
  };
  return MakeEntry<O, RadauResult>(
      spec, options, stats, SimulateRadau,
      [](const Scene&, const RadauResult& result, SimulationResult* out) {
        out->num_steps = result.stats.num_steps;
        out->num_iterations = result.stats.num_newton_iterations;
      },
      // With adaptive steps and no h given, the controller picks the first step (h = 0);
      // without them the controller's settings would be silently ignored, so they are refused.
      [](const std::map<std::string, SettingValue>& given, O* built) {
        if (built->adaptive && given.count("h") == 0) built->step_size = 0.0;
        for (const char* controller_option : {"rtol", "atol", "h_min", "h_max"}) {
          RequireArgument(built->adaptive || given.count(controller_option) == 0, "option '",
                          controller_option,
                          "' applies to the radau integrator with adaptive steps only (set "
                          "adaptive)");
        }
      });
}

}  // namespace moreau::internal
