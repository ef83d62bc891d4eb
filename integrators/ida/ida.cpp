// Event-driven integration of lowered scenes with SUNDIALS IDA (include/moreau/integrators/ida.hpp,
// docs/ida.md): options, statuses and the entry points; the run itself is IdaRun (ida_run.hpp).

#include "moreau/integrators/ida.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "ida_run.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"

namespace moreau {

IdaOptions IdaOptions::Reference() {
  IdaOptions options;
  options.relative_tolerance = 1e-12;
  options.absolute_tolerance = 1e-14;
  options.newton_convergence_factor = 0.01;
  return options;
}

void IdaOptions::Validate() const {
  RequireArgument(std::isfinite(relative_tolerance) && relative_tolerance > 0.0,
                  "relative tolerance must be positive and finite, got ", relative_tolerance);
  RequireArgument(std::isfinite(absolute_tolerance) && absolute_tolerance > 0.0,
                  "absolute tolerance must be positive and finite, got ", absolute_tolerance);
  RequireArgument(newton_convergence_factor > 0.0 && newton_convergence_factor <= 1.0,
                  "Newton convergence factor must be in (0, 1], got ", newton_convergence_factor);
  RequireArgument(std::isfinite(drift_rate) && drift_rate >= 0.0,
                  "drift rate must be nonnegative and finite, got ", drift_rate);
  RequireArgument(std::isfinite(event_tolerance) && event_tolerance > 0.0,
                  "event tolerance must be positive, got ", event_tolerance);
  RequireArgument(max_steps > 0, "max steps must be positive, got ", max_steps);
  RequireArgument(max_events > 0, "max events must be positive, got ", max_events);
  RequireArgument(std::isfinite(max_step) && max_step >= 0.0,
                  "max step must be nonnegative (0: no limit), got ", max_step);
  for (double t : stop_times) {
    RequireArgument(std::isfinite(t), "stop times (tstops) must be finite, got ", t);
  }
  for (double t : output_times) {
    RequireArgument(std::isfinite(t), "output times must be finite, got ", t);
  }
}

std::string ToString(IdaStatus status) {
  switch (status) {
    case IdaStatus::kSuccess:
      return "success";
    case IdaStatus::kSolverFailure:
      return "solver_failure";
    case IdaStatus::kStatusDecisionFailure:
      return "status_decision_failure";
    case IdaStatus::kTooManySteps:
      return "too_many_steps";
    case IdaStatus::kTooManyEvents:
      return "too_many_events";
    case IdaStatus::kNoProgress:
      return "no_progress";
    case IdaStatus::kStepSizeTooSmall:
      return "step_size_too_small";
    case IdaStatus::kNonFinite:
      return "non_finite";
  }
  return "?";
}

std::string IdaStats::Summary() const {
  std::ostringstream s;
  s << num_steps << " steps, " << num_phases << " phases, " << num_events << " events, "
    << num_residual_evaluations << " residuals, " << num_jacobian_evaluations << " Jacobians";
  if (num_symbolic_analyses > 0) s << " (" << num_symbolic_analyses << " KLU analyses)";
  s << ", max drift " << max_drift << ", " << cpu_seconds << " s";
  return s.str();
}

IdaResult SimulateIda(const Scene& scene, const IdaOptions& options,
                      const ProgressCallback& progress) {
  options.Validate();
  RequireSupportedEffects(scene, "ida");
  internal::IdaRun run(scene, options, progress);
  return run.Run();
}

ReferenceSolution ComputeReference(const Scene& scene, const std::vector<double>& sample_times,
                                   const IdaOptions& options) {
  IdaOptions reference = options;
  reference.output_times = sample_times;
  reference.record_steps = false;
  const IdaResult result = SimulateIda(scene, reference);
  if (result.status != IdaStatus::kSuccess) {
    throw std::runtime_error("reference solution of scene '" + scene.name +
                             "' failed: " + result.message);
  }
  ReferenceSolution solution;
  solution.final_state = result.final_state;
  solution.final_time = result.final_time;
  solution.events = result.events;
  solution.relays = result.relays;
  for (double t : sample_times) {
    // The trajectory holds t0, event points, the output times and tf, in time order.
    const auto& times = result.trajectory.t;
    std::size_t best = 0;
    for (std::size_t k = 1; k < times.size(); ++k) {
      if (std::fabs(times[k] - t) < std::fabs(times[best] - t)) best = k;
    }
    solution.sample_times.push_back(t);
    solution.samples.push_back(result.trajectory.x[best]);
  }
  return solution;
}

}  // namespace moreau
