#include "run_report.hpp"

#include <cmath>

#include "moreau/core/error.hpp"
#include "moreau/integrators/alpha_dai.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "moreau/linalg/linear_solver.hpp"

namespace moreau::tool {

const std::vector<std::pair<std::string, std::string>>& IntegratorNames() {
  static const std::vector<std::pair<std::string, std::string>> names = {
      {"auto", "radau for scenes without effects, alpha for path constraints, fesd otherwise"},
      {"radau", "smooth Radau IIA (fixed step or --adaptive); scenes without effects"},
      {"timestepping",
       "fixed-step Radau IIA with stage complementarity (first-order baseline, no switch "
       "detection); moving sets, switching surfaces"},
      {"fesd",
       "FESD Radau IIA: switches on element boundaries, order 2s-1 across switches; moving "
       "sets, switching surfaces, hysteresis relays (time-freezing)"},
      {"ida",
       "SUNDIALS IDA (adaptive BDF) between located events, --rtol/--atol; the reference "
       "integrator; moving sets, switching surfaces, hysteresis relays"},
      {"alpha",
       "alpha-method DAI stepper with an active-set SQP per step (order 2 in x, rho "
       "regularization); path constraints, algebraic inputs"},
  };
  return names;
}

namespace {

// Rejects options the user gave explicitly that `integrator` does not use.
void RequireOnly(const RunSettings& settings, const std::set<std::string>& used) {
  for (const std::string& option : settings.given) {
    RequireArgument(used.count(option) > 0, "option --", option, " does not apply to integrator '",
                    settings.integrator, "'");
  }
}

// The fields every integrator's result has: status (success when it equals `success`),
// message, final time and state, trajectory; events where the result has them.
template <class Result, class Status>
void CopyOutcome(const Result& result, Status success, RunReport* report) {
  report->status = ToString(result.status);
  report->success = result.status == success;
  report->message = result.message;
  report->final_time = result.final_time;
  report->final_state = result.final_state;
  report->trajectory = result.trajectory;
  if constexpr (requires { result.events; }) report->events = result.events;
}

RunReport RunRadau(const Scene& scene, const RunSettings& settings,
                   const ProgressCallback& progress) {
  std::set<std::string> used{"stages", "h", "adaptive", "linear-solver"};
  if (settings.adaptive) used.insert({"rtol", "atol"});
  RequireOnly(settings, used);
  RadauOptions options;
  options.stages = settings.stages;
  options.adaptive = settings.adaptive;
  options.step_size = settings.adaptive && !settings.step_size_given ? 0.0 : settings.step_size;
  options.relative_tolerance = settings.relative_tolerance;
  options.absolute_tolerance = settings.absolute_tolerance;
  options.linear_solver = ParseLinearSolverKind(settings.linear_solver);
  const RadauResult result = SimulateRadau(scene, options, progress);

  RunReport report;
  report.options = {{"stages", options.stages},
                    {"order", 2 * options.stages - 1},
                    {"adaptive", options.adaptive},
                    {"step_size", options.step_size},
                    {"linear_solver", settings.linear_solver}};
  if (options.adaptive) {
    report.options["rtol"] = options.relative_tolerance;
    report.options["atol"] = options.absolute_tolerance;
  }
  CopyOutcome(result, RadauStatus::kSuccess, &report);
  const RadauStats& s = result.stats;
  report.stats = {{"num_steps", s.num_steps},
                  {"num_rejected_steps", s.num_rejected_steps},
                  {"num_newton_iterations", s.num_newton_iterations},
                  {"num_factorizations", s.num_factorizations},
                  {"num_function_evaluations", s.num_function_evaluations},
                  {"num_jacobian_evaluations", s.num_jacobian_evaluations},
                  {"cpu_seconds", s.cpu_seconds}};
  report.stats_summary = s.Summary();
  report.num_steps = s.num_steps;
  report.num_newton_iterations = s.num_newton_iterations;
  report.cpu_seconds = s.cpu_seconds;
  return report;
}

RunReport RunTimeStepping(const Scene& scene, const RunSettings& settings,
                          const ProgressCallback& progress) {
  RequireOnly(settings, {"stages", "h", "switching", "linear-solver"});
  TimeSteppingOptions options;
  options.stages = settings.stages_given ? settings.stages : 1;
  options.step_size = settings.step_size;
  options.switching_form = ParseSwitchingForm(settings.switching_form);
  options.newton.linear_solver = ParseLinearSolverKind(settings.linear_solver);
  const TimeSteppingResult result = SimulateTimeStepping(scene, options, progress);

  RunReport report;
  report.options = {{"stages", options.stages},
                    {"step_size", options.step_size},
                    {"switching_form", settings.switching_form},
                    {"newton_tolerance", options.newton.tolerance}};
  CopyOutcome(result, TimeSteppingStatus::kSuccess, &report);
  const TimeSteppingStats& s = result.stats;
  report.stats = {{"num_steps", s.num_steps},
                  {"num_newton_iterations", s.num_newton_iterations},
                  {"num_factorizations", s.num_factorizations},
                  {"num_backtracks", s.num_backtracks},
                  {"max_complementarity_residual", s.max_complementarity_residual},
                  {"max_newton_residual", s.max_newton_residual},
                  {"cpu_seconds", s.cpu_seconds}};
  report.stats_summary = s.Summary();
  report.num_steps = s.num_steps;
  report.num_newton_iterations = s.num_newton_iterations;
  report.cpu_seconds = s.cpu_seconds;
  return report;
}

RunReport RunFesd(const Scene& scene, const RunSettings& settings,
                  const ProgressCallback& progress) {
  RequireOnly(settings, {"stages", "h", "fe", "switching", "linear-solver", "numerical-time"});
  FesdOptions options;
  if (settings.stages_given) options.stages = settings.stages;
  if (settings.step_size_given) options.step_size = settings.step_size;
  options.finite_elements = settings.finite_elements;
  options.switching_form = ParseSwitchingForm(settings.switching_form);
  options.newton.linear_solver = ParseLinearSolverKind(settings.linear_solver);
  options.record_stages = true;
  const FesdResult result = SimulateFesd(scene, options, progress);

  RunReport report;
  report.options = {{"stages", options.stages},
                    {"order", 2 * options.stages - 1},
                    {"step_size", options.step_size},
                    {"finite_elements", options.finite_elements},
                    {"switching_form", settings.switching_form},
                    {"newton_tolerance", options.newton.tolerance}};
  CopyOutcome(result, FesdStatus::kSuccess, &report);
  report.numerical_trajectory = result.numerical_trajectory;
  report.relays = result.relays;
  if (settings.numerical_time) {
    RequireArgument(!result.relays.empty(),
                    "--numerical-time applies to scenes with hysteresis "
                    "relays only (elsewhere numerical and physical time coincide)");
    report.trajectory = result.numerical_trajectory;
    report.numerical_time_axis = true;
  }
  const FesdStats& s = result.stats;
  report.stats = {{"num_steps", s.num_steps},
                  {"num_elements", s.num_elements},
                  {"num_switches", s.num_switches},
                  {"num_groups", s.num_groups},
                  {"num_event_retries", s.num_event_retries},
                  {"num_newton_iterations", s.num_newton_iterations},
                  {"num_factorizations", s.num_factorizations},
                  {"max_cross_complementarity", s.max_cross_complementarity},
                  {"max_complementarity", s.max_complementarity},
                  {"min_element_length", s.min_element_length},
                  {"frozen_time", s.frozen_time},
                  {"cpu_seconds", s.cpu_seconds}};
  report.stats_summary = s.Summary();
  report.num_steps = s.num_steps;
  report.num_newton_iterations = s.num_newton_iterations;
  report.cpu_seconds = s.cpu_seconds;
  report.stage_trajectory = result.stage_trajectory;
  report.element_columns = {"t_start",         "physical_start",  "length",
                            "frozen",          "ends_at_switch",  "newton_iterations",
                            "newton_residual", "complementarity", "cross_complementarity"};
  for (const FesdElement& e : result.elements) {
    report.element_rows.push_back({e.t_start, e.physical_start, e.length, e.frozen ? 1.0 : 0.0,
                                   e.ends_at_switch ? 1.0 : 0.0,
                                   static_cast<double>(e.newton_iterations), e.newton_residual,
                                   e.complementarity, e.cross_complementarity});
  }
  return report;
}

RunReport RunIda(const Scene& scene, const RunSettings& settings,
                 const ProgressCallback& progress) {
  RequireOnly(settings, {"rtol", "atol", "switching", "linear-solver"});
  IdaOptions options;
  if (settings.given.count("rtol") > 0) options.relative_tolerance = settings.relative_tolerance;
  if (settings.given.count("atol") > 0) options.absolute_tolerance = settings.absolute_tolerance;
  options.switching_form = ParseSwitchingForm(settings.switching_form);
  options.linear_solver = ParseLinearSolverKind(settings.linear_solver);
  const IdaResult result = SimulateIda(scene, options, progress);

  RunReport report;
  report.options = {{"rtol", options.relative_tolerance},
                    {"atol", options.absolute_tolerance},
                    {"drift_rate", options.drift_rate},
                    {"switching_form", settings.switching_form},
                    {"linear_solver", settings.linear_solver}};
  CopyOutcome(result, IdaStatus::kSuccess, &report);
  report.relays = result.relays;
  const IdaStats& s = result.stats;
  report.stats = {{"num_steps", s.num_steps},
                  {"num_phases", s.num_phases},
                  {"num_events", s.num_events},
                  {"num_residual_evaluations", s.num_residual_evaluations},
                  {"num_jacobian_evaluations", s.num_jacobian_evaluations},
                  {"num_nonlinear_iterations", s.num_nonlinear_iterations},
                  {"num_error_test_failures", s.num_error_test_failures},
                  {"max_drift", s.max_drift},
                  {"cpu_seconds", s.cpu_seconds}};
  report.stats_summary = s.Summary();
  report.num_steps = s.num_steps;
  report.num_newton_iterations = s.num_nonlinear_iterations;
  report.cpu_seconds = s.cpu_seconds;
  return report;
}

RunReport RunAlpha(const Scene& scene, const RunSettings& settings,
                   const ProgressCallback& progress) {
  RequireOnly(settings, {"h", "rho", "errtol", "rank-tol", "max-retries", "objective"});
  AlphaDaiOptions options;
  if (settings.step_size_given) options.max_step_size = settings.step_size;
  options.rho = settings.rho;
  options.error_tolerance = settings.error_tolerance;
  options.rank_tolerance = settings.rank_tolerance;
  options.max_retries = settings.max_retries;
  options.objective = ParseAlphaDaiObjective(settings.objective);
  const AlphaDaiResult result = SimulateAlphaDai(scene, options, progress);

  RunReport report;
  report.options = {
      {"rho", options.rho},
      {"h_max", options.max_step_size},
      {"errtol", std::isfinite(options.error_tolerance) ? nlohmann::json(options.error_tolerance)
                                                        : nlohmann::json("inf")},
      {"tol", options.constraint_tolerance},
      {"rank_tol", options.rank_tolerance},
      {"max_retries", options.max_retries},
      {"max_sqp_iterations", options.max_sqp_iterations},
      {"objective", ToString(options.objective)}};
  CopyOutcome(result, AlphaDaiStatus::kSuccess, &report);
  const AlphaDaiStats& s = result.stats;
  report.stats = {
      {"num_steps", s.num_steps},
      {"num_tries", s.num_tries},
      {"num_rho_reductions", s.num_rho_reductions},
      {"num_guess_retries", s.num_guess_retries},
      {"num_rank_deficient", s.num_rank_deficient},
      {"num_infeasible", s.num_infeasible},
      {"num_sqp_iterations", s.num_sqp_iterations},
      {"num_qp_iterations", s.num_qp_iterations},
      {"num_elastic_qps", s.num_elastic_qps},
      {"num_jacobian_evaluations", s.num_jacobian_evaluations},
      {"num_function_evaluations", s.num_function_evaluations},
      {"num_basis_factorizations", s.num_basis_factorizations},
      {"max_constraint_violation", s.max_constraint_violation},
      {"max_dynamics_residual", s.max_dynamics_residual},
      {"max_kkt_residual", s.max_kkt_residual},
      {"min_basis_sigma", std::isfinite(s.min_basis_sigma) ? nlohmann::json(s.min_basis_sigma)
                                                           : nlohmann::json(nullptr)},
      {"min_rho", std::isfinite(s.min_rho) ? nlohmann::json(s.min_rho) : nlohmann::json(nullptr)},
      {"cpu_seconds", s.cpu_seconds}};
  report.stats_summary = s.Summary();
  report.num_steps = s.num_steps;
  report.num_newton_iterations = s.num_sqp_iterations;
  report.cpu_seconds = s.cpu_seconds;
  // Per-step certificates (elements.csv): the rows of AlphaDaiStep.
  report.element_columns = {"t",
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
    report.element_rows.push_back(
        {step.t, step.h, step.h_rule, step.rho, static_cast<double>(step.tries),
         static_cast<double>(step.sqp_iterations), step.constraint_violation,
         step.dynamics_residual, step.kkt_residual, static_cast<double>(step.num_active),
         static_cast<double>(step.num_active_input_bounds), step.basis_sigma_min,
         step.basis_condition, step.acceleration_norm});
  }
  return report;
}

}  // namespace

// The integrator `auto` picks for a scene: the smooth one without effects, the alpha-method
// stepper for path constraints (DAI), FESD otherwise.
std::string AutomaticIntegrator(const Scene& scene) {
  if (scene.effects.empty()) return "radau";
  if (scene.Has<PathConstraints>()) return "alpha";
  return "fesd";
}

RunReport RunScene(const Scene& scene, const RunSettings& requested,
                   const ProgressCallback& progress) {
  RunSettings settings = requested;
  if (settings.integrator == "auto") settings.integrator = AutomaticIntegrator(scene);
  RunReport report;
  if (settings.integrator == "radau") {
    report = RunRadau(scene, settings, progress);
  } else if (settings.integrator == "timestepping") {
    report = RunTimeStepping(scene, settings, progress);
  } else if (settings.integrator == "fesd") {
    report = RunFesd(scene, settings, progress);
  } else if (settings.integrator == "ida") {
    report = RunIda(scene, settings, progress);
  } else if (settings.integrator == "alpha") {
    report = RunAlpha(scene, settings, progress);
  } else {
    std::string valid;
    for (const auto& [name, description] : IntegratorNames()) {
      valid += (valid.empty() ? "" : ", ") + name;
    }
    ThrowInvalidArgument("unknown integrator '", settings.integrator, "'; available: ", valid);
  }
  report.scene = scene.name;
  report.integrator = settings.integrator;
  report.state_names = scene.state_names;
  return report;
}

}  // namespace moreau::tool
