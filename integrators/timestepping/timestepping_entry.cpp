// The time-stepping baseline as Simulate() sees it (integrators/common/integrator_entry.hpp).
#include "../common/integrator_entry.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "moreau/linalg/linear_solver.hpp"

namespace moreau::internal {

IntegratorEntry TimeSteppingEntry() {
  using O = TimeSteppingOptions;
  IntegratorSpec spec;
  spec.name = "timestepping";
  spec.title = "the time-stepping integrator";
  spec.description =
      "fixed-step Radau IIA with stage complementarity (first-order baseline, no switch "
      "detection)";
  spec.supported_effects = {"moving set", "switching surfaces", "complementarity system"};
  spec.step_unit = "step";
  spec.iteration_unit = "Newton";
  std::vector<OptionBinding<O>> options = {
      BindInteger("stages", &O::stages, "Radau IIA stages s in 1..7"),
      BindReal("h", &O::step_size, "fixed step > 0"),
      BindStopTimes(&O::stop_times),
      BindSwitching(&O::switching_form),
      BindInteger("max_steps", &O::max_steps, "most steps (a longer grid is refused), >= 1"),
      BindBool("record_trajectory", &O::record_trajectory,
               "record every step (false: initial and final points only)"),
      BindBool("sensitivities", &O::sensitivities,
               "dx(T)/dx(0), dx(T)/dp, dx(T)/du by the IFT on every step (no switch-time terms)"),
  };
  for (auto& binding : BindDirectionalAndAdjoint<O>(
           "times in (t0, tf] whose states the sensitivities also cover (each becomes a step "
           "end, as a stop time)")) {
    options.push_back(binding);
  }
  for (auto& binding : BindConstraintFilter(&O::constraint_filter, &O::filter_safety)) {
    options.push_back(binding);
  }
  options.push_back(BindThreads(&O::threads));
  for (auto& binding : BindNewton(&O::newton)) options.push_back(binding);
  using S = TimeSteppingStats;
  std::vector<StatBinding<S>> stats = {
      BindStat("num_steps", &S::num_steps, "steps"),
      BindStat("num_newton_iterations", &S::num_newton_iterations, "Newton iterations"),
      BindStat("num_factorizations", &S::num_factorizations, "LU factorizations"),
      BindStat("num_backtracks", &S::num_backtracks, "line-search backtracks"),
      BindStat("num_filter_rechecks", &S::num_filter_rechecks,
               "steps solved again: a constraint left out by the filter was not positive"),
      BindStat("max_working_pairs", &S::max_working_pairs,
               "most complementarity pairs in a step system (near-active filter)"),
      BindStat("max_complementarity_residual", &S::max_complementarity_residual,
               "max over steps of max |min(a, b)|"),
      BindStat("max_newton_residual", &S::max_newton_residual,
               "max over steps of ||S Phi||_inf at convergence"),
      BindStat("num_inside_crossings", &S::num_inside_crossings,
               "steps with a free side below zero between their nodes (not resolved: a warning)"),
  };
  for (auto& binding : BindAdjointStats<S>()) stats.push_back(binding);
  stats.push_back(BindStat("cpu_seconds", &S::cpu_seconds, "thread CPU time"));
  return MakeEntry<O, TimeSteppingResult>(
      spec, options, stats, SimulateTimeStepping,
      [](const Scene& scene, const TimeSteppingResult& result, SimulationResult* out) {
        out->num_steps = result.stats.num_steps;
        out->num_iterations = result.stats.num_newton_iterations;
        for (const Vector& y : result.sample_states) {
          out->sample_states.push_back(y.head(scene.num_states()));
        }
        if (result.adjoint_sweep) {
          out->adjoint =
              std::make_shared<KeptAdjointSweep<const TimeSteppingAdjoint>>(result.adjoint_sweep);
        }
        if (result.directional.size() > 0 || result.adjoint.size() > 0) {
          SimulationSensitivities s;
          s.segment_starts = result.segment_starts;
          s.directional = result.directional;
          s.sample_directional = result.sample_directional;
          s.adjoint = result.adjoint;
          out->sensitivities = s;
        }
        if (result.sensitivities.size() == 0) return;
        // Columns of the lowered derivative: y0 (n_y = n_x + clock), p, then u per segment.
        const Eigen::Index nx = scene.num_states(), np = scene.num_parameters();
        const Eigen::Index ny = result.sensitivities.rows();
        const Eigen::Index nu_all = result.sensitivities.cols() - ny - np;
        SimulationSensitivities s;
        s.segment_starts = result.segment_starts;
        s.initial_state = result.sensitivities.topLeftCorner(nx, nx);
        s.parameters = result.sensitivities.block(0, ny, nx, np);
        s.inputs = result.sensitivities.block(0, ny + np, nx, nu_all);
        s.directional = result.directional;
        s.sample_directional = result.sample_directional;
        s.adjoint = result.adjoint;
        out->sensitivities = s;
      });
}

}  // namespace moreau::internal
