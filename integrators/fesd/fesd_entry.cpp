// FESD Radau IIA as Simulate() sees it (integrators/common/integrator_entry.hpp).
#include <algorithm>

#include "../common/integrator_entry.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/linalg/linear_solver.hpp"

namespace moreau::internal {

IntegratorEntry FesdEntry() {
  using O = FesdOptions;
  IntegratorSpec spec;
  spec.name = "fesd";
  spec.title = "the FESD integrator";
  spec.description = "FESD Radau IIA: switches on element boundaries, order 2s-1 across switches";
  spec.supported_effects = {"moving set", "switching surfaces", "hysteresis relay",
                            "complementarity system"};
  spec.supports_time_scale = true;
  spec.step_unit = "element";
  spec.iteration_unit = "Newton";
  std::vector<OptionBinding<O>> options = {
      BindInteger("stages", &O::stages, "Radau IIA stages s in 1..7 (order 2s - 1)"),
      BindReal("h", &O::step_size,
               "fixed integration step H > 0 (control interval; numerical time with relays); "
               "not given: error-controlled steps; with adaptive, rtol or atol the initial step"),
      BindBool("adaptive", &O::adaptive,
               "error-controlled steps even with h given (on whenever h is not given)"),
      BindReal("rtol", &O::relative_tolerance,
               "relative tolerance of the error-controlled steps, > 0 (with h: sets adaptive)"),
      BindReal("atol", &O::absolute_tolerance,
               "absolute tolerance of the error-controlled steps, > 0; 0: rtol times each "
               "state's largest magnitude so far (with h: sets adaptive)"),
      BindReal("h0", &O::initial_step_size,
               "initial step of the error-controlled steps, > 0 (0: automatic)"),
      BindReal("h_min", &O::min_step_size, "smallest error-controlled step and failure retry, > 0"),
      BindReal("h_max", &O::max_step_size, "largest error-controlled step, >= 0 (0: no bound)"),
      BindInteger("max_steps", &O::max_steps,
                  "most steps: a longer fixed grid is refused, an error-controlled run stops "
                  "with max_steps_reached, >= 1"),
      BindBool("estimate_error", &O::estimate_error,
               "fixed steps: estimate the error of every step (error_estimate, a warning far "
               "above rtol)"),
      BindStopTimes(&O::stop_times),
      BindReal("output_dt", &O::output_step,
               "dense output every output_dt from t0 (collocation polynomials), >= 0"),
      BindRealList("output_times", &O::output_times,
                   "dense output at these times in [t0, tf] (collocation polynomials)"),
      BindRealList("step_sequence", &O::step_sequence,
                   "replay an adaptive run's accepted steps (its step_sequence) without error "
                   "control"),
      BindInteger("fe", &O::finite_elements, "nominal finite elements per step N_fe >= 1"),
      BindSwitching(&O::switching_form),
      BindReal("event_tol", &O::event_tolerance,
               "free sides within this of zero are decided by the velocity-level problem, > 0"),
      BindReal("min_element_fraction", &O::min_element_fraction,
               "remainders shorter than this fraction of H / N_fe merge into the next step, "
               "in (0, 0.5]"),
      BindInteger("max_event_retries", &O::max_event_retries, "re-solves per switch, >= 1"),
      BindBool("project_initial_state", &O::project_initial_state,
               "an initial state outside the moving sets is projected onto them (shooting "
               "nodes), not refused"),
      BindBool("keep_elements_after_early_switch", &O::keep_elements_after_early_switch,
               "a switch right after a step's start does not use up an element (shooting)"),
      BindBool("sensitivities", &O::sensitivities,
               "dx(T)/dx(0), dx(T)/dp, dx(T)/du through switches (IFT on every group)"),
      BindBool("reduce_smooth_elements", &O::reduce_smooth_elements,
               "elements whose statuses leave a smooth field (one Stewart mode, no active "
               "constraint) solved as Radau IIA steps of it, then checked on the full system"),
      BindBool("record_stages", &O::record_stages, "record every collocation stage point"),
      BindBool("record_trajectory", &O::record_trajectory,
               "record element ends (false: initial and final points only)"),
  };
  // Directional and adjoint sensitivities, listed after `sensitivities`.
  const auto adjoint = BindDirectionalAndAdjoint<O>(
      "times in (t0, tf] whose states the sensitivities also cover (element ends of the run: "
      "multiples of h from a control breakpoint)");
  options.insert(std::find_if(options.begin(), options.end(),
                              [](const auto& b) { return b.spec.name == "sensitivities"; }) +
                     1,
                 adjoint.begin(), adjoint.end());
  for (auto& binding : BindConstraintFilter(&O::constraint_filter, &O::filter_safety)) {
    options.push_back(binding);
  }
  options.push_back(BindThreads(&O::threads));
  for (auto& binding : BindNewton(&O::newton)) options.push_back(binding);
  using S = FesdStats;
  std::vector<StatBinding<S>> stats = {
      BindStat("num_steps", &S::num_steps, "integration steps"),
      BindStat("num_elements", &S::num_elements, "finite elements"),
      BindStat("num_switches", &S::num_switches, "element boundaries with a switch"),
      BindStat("num_groups", &S::num_groups, "group solves with the event equation"),
      BindStat("num_event_retries", &S::num_event_retries, "re-solves at switches"),
      BindStat("num_rejected_steps", &S::num_rejected_steps,
               "adaptive steps rejected by the error test"),
      BindStat("num_failed_steps", &S::num_failed_steps,
               "adaptive steps whose solves failed, retried shorter"),
      BindStat("num_newton_iterations", &S::num_newton_iterations, "Newton iterations"),
      BindStat("num_factorizations", &S::num_factorizations, "LU factorizations"),
      BindStat("max_cross_complementarity", &S::max_cross_complementarity,
               "max over elements of the cross-complementarity certificate"),
      BindStat("max_complementarity", &S::max_complementarity,
               "max over elements and stages of |min(a, b)|"),
      BindStat("min_element_length", &S::min_element_length, "shortest element"),
      BindStat("frozen_time", &S::frozen_time, "numerical time with physical time frozen (relays)"),
      BindStat("num_filter_rechecks", &S::num_filter_rechecks,
               "steps solved again: a constraint left out by the filter was not positive"),
      BindStat("num_reduced_elements", &S::num_reduced_elements,
               "elements solved as a Radau IIA step of a smooth field"),
      BindStat("num_inside_crossings", &S::num_inside_crossings,
               "crossings of free sides found between an element's nodes"),
      BindStat("num_unresolved_crossings", &S::num_unresolved_crossings,
               "elements whose indicator bounds admit a crossing the search did not resolve"),
      BindStat("num_bound_evaluations", &S::num_bound_evaluations,
               "interval evaluations of the event indicators"),
      BindStat("max_working_pairs", &S::max_working_pairs,
               "most complementarity pairs in an element system (near-active filter)"),
      BindStat("error_estimate", &S::error_estimate,
               "accumulated local error estimates relative to the solution's scale (-1: not "
               "estimated)"),
      BindStat("num_unestimated_steps", &S::num_unestimated_steps,
               "fixed steps whose error could not be estimated"),
  };
  for (auto& binding : BindAdjointStats<S>()) stats.push_back(binding);
  stats.push_back(BindStat("cpu_seconds", &S::cpu_seconds, "thread CPU time"));
  return MakeEntry<O, FesdResult>(
      spec, options, stats, SimulateFesd,
      [](const Scene& scene, const FesdResult& result, SimulationResult* out) {
        out->num_steps = result.stats.num_elements;
        out->num_iterations = result.stats.num_newton_iterations;
        out->stage_trajectory = result.stage_trajectory;
        out->numerical_trajectory = result.numerical_trajectory;
        out->relays = result.relays;
        out->record_columns = {"t_start",         "physical_start",  "length",
                               "frozen",          "ends_at_switch",  "newton_iterations",
                               "newton_residual", "complementarity", "cross_complementarity"};
        for (const FesdElement& e : result.elements) {
          out->records.push_back({e.t_start, e.physical_start, e.length, e.frozen ? 1.0 : 0.0,
                                  e.ends_at_switch ? 1.0 : 0.0,
                                  static_cast<double>(e.newton_iterations), e.newton_residual,
                                  e.complementarity, e.cross_complementarity});
        }
        out->step_sequence = result.step_sequence;
        for (const Vector& y : result.sample_states) {
          out->sample_states.push_back(y.head(scene.num_states()));
        }
        if (result.adjoint)
          out->adjoint = std::make_shared<KeptAdjointSweep<FesdAdjoint>>(result.adjoint);
        const FesdSensitivities& given = result.sensitivities;
        if (given.lowered.size() == 0 && given.directional.size() == 0 &&
            given.adjoint.size() == 0) {
          return;
        }
        SimulationSensitivities s;
        s.initial_state = given.initial_state;
        s.parameters = given.parameters;
        s.inputs = given.inputs;
        s.segment_starts = given.segment_starts;
        s.directional = given.directional;
        s.sample_directional = given.sample_directional;
        s.adjoint = given.adjoint;
        out->sensitivities = s;
      },
      // Without h error-controlled steps, with h fixed ones (see AdjustStepControl).
      AdjustStepControl<O>,
      // Lowered once, run many times (Simulator, Python's moreau.Integrator).
      [](const Scene& scene, const O& built) {
        auto integrator = std::make_shared<FesdIntegrator>(scene, built);
        return std::function<FesdResult(const Scene&, const ProgressCallback&)>(
            [integrator](const Scene& values, const ProgressCallback& progress) {
              return integrator->Simulate(values, progress);
            });
      });
}

}  // namespace moreau::internal
