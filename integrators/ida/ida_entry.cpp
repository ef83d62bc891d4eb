// SUNDIALS IDA (the reference) as Simulate() sees it (integrators/common/integrator_entry.hpp).
#include "../common/integrator_entry.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/linalg/linear_solver.hpp"

namespace moreau::internal {

IntegratorEntry IdaEntry() {
  using O = IdaOptions;
  IntegratorSpec spec;
  spec.name = "ida";
  spec.title = "the IDA integrator";
  spec.description = "SUNDIALS IDA (adaptive BDF) between located events; the reference integrator";
  spec.supported_effects = {"moving set", "switching surfaces", "hysteresis relay",
                            "complementarity system"};
  spec.step_unit = "step";
  spec.iteration_unit = "nonlinear";
  std::vector<OptionBinding<O>> options = {
      BindReal("rtol", &O::relative_tolerance, "relative tolerance of IDA's local error test"),
      BindReal("atol", &O::absolute_tolerance, "absolute tolerance of IDA's local error test"),
      BindReal("newton_convergence_factor", &O::newton_convergence_factor,
               "IDA's Newton stops below this fraction of the local tolerance, in (0, 1]"),
      BindReal("drift_rate", &O::drift_rate,
               "Baumgarte rate kappa >= 0 (1/time) of the drift control (0: off)"),
      BindSwitching(&O::switching_form),
      BindLinearSolver(&O::linear_solver),
      BindReal("event_tol", &O::event_tolerance,
               "free sides within this of zero are decided at events, > 0"),
      BindInteger("max_steps", &O::max_steps, "internal steps over the run, > 0"),
      BindInteger("max_events", &O::max_events, "events over the run (Zeno guard), > 0"),
      BindReal("max_step", &O::max_step, "largest internal step (0: no limit)"),
      BindStopTimes(&O::stop_times),
      BindBool("record_steps", &O::record_steps,
               "record every internal step (false: events, breakpoints, output times)"),
      BindRealList("output_times", &O::output_times, "extra trajectory points in (t0, tf]"),
  };
  using S = IdaStats;
  std::vector<StatBinding<S>> stats = {
      BindStat("num_steps", &S::num_steps, "internal steps"),
      BindStat("num_phases", &S::num_phases, "(re)starts of IDA: events and breakpoints"),
      BindStat("num_events", &S::num_events, "located events"),
      BindStat("num_residual_evaluations", &S::num_residual_evaluations, "residual evaluations"),
      BindStat("num_jacobian_evaluations", &S::num_jacobian_evaluations, "Jacobian evaluations"),
      BindStat("num_symbolic_analyses", &S::num_symbolic_analyses,
               "KLU symbolic analyses (Jacobian pattern changes)"),
      BindStat("num_nonlinear_iterations", &S::num_nonlinear_iterations, "Newton iterations"),
      BindStat("num_error_test_failures", &S::num_error_test_failures, "error-test failures"),
      BindStat("max_drift", &S::max_drift, "largest position-level drift before projection"),
      BindStat("num_unresolved_crossings", &S::num_unresolved_crossings,
               "steps whose root-function bounds admit a zero the search did not resolve"),
      BindStat("cpu_seconds", &S::cpu_seconds, "thread CPU time"),
  };
  return MakeEntry<O, IdaResult>(spec, options, stats, SimulateIda,
                                 [](const Scene&, const IdaResult& result, SimulationResult* out) {
                                   out->num_steps = result.stats.num_steps;
                                   out->num_iterations = result.stats.num_nonlinear_iterations;
                                   out->relays = result.relays;
                                 });
}

}  // namespace moreau::internal
