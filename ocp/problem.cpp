// Validation of optimal control problems and the scene the transcription integrates.

#include <cmath>

#include "internal.hpp"
#include "moreau/core/error.hpp"
#include "moreau/integrators/radau_tableau.hpp"

namespace moreau {

std::string ToString(OcpTranscription transcription) {
  switch (transcription) {
    case OcpTranscription::kMultipleShooting:
      return "multiple_shooting";
    case OcpTranscription::kSingleShooting:
      return "single_shooting";
    case OcpTranscription::kCollocation:
      return "collocation";
  }
  return "?";
}

OcpTranscription ParseOcpTranscription(const std::string& name) {
  for (OcpTranscription t : {OcpTranscription::kMultipleShooting, OcpTranscription::kSingleShooting,
                             OcpTranscription::kCollocation}) {
    if (ToString(t) == name) return t;
  }
  ThrowInvalidArgument("unknown transcription '", name,
                       "'; expected multiple_shooting, single_shooting or collocation");
}

std::string ToString(OcpStatus status) {
  switch (status) {
    case OcpStatus::kSolved:
      return "solved";
    case OcpStatus::kSolvedToAcceptable:
      return "solved_to_acceptable_level";
    case OcpStatus::kInfeasible:
      return "infeasible";
    case OcpStatus::kMaxIterations:
      return "max_iterations";
    case OcpStatus::kSimulationFailure:
      return "simulation_failure";
    case OcpStatus::kSolverFailure:
      return "solver_failure";
    case OcpStatus::kNotVerified:
      return "not_verified";
  }
  return "?";
}

std::string ToString(OcpIntegrator integrator) {
  return integrator == OcpIntegrator::kFesd ? "fesd" : "timestepping";
}

OcpIntegrator ParseOcpIntegrator(const std::string& name) {
  if (name == "fesd") return OcpIntegrator::kFesd;
  if (name == "timestepping") return OcpIntegrator::kTimeStepping;
  ThrowInvalidArgument("unknown OCP integrator '", name, "' (expected fesd or timestepping)");
}

std::string ToString(OcpHessian hessian) {
  switch (hessian) {
    case OcpHessian::kLimitedMemory:
      return "limited_memory";
    case OcpHessian::kBlockBfgs:
      return "block_bfgs";
    case OcpHessian::kBlockSr1:
      return "block_sr1";
    case OcpHessian::kSecondOrder:
      return "second_order";
  }
  return "?";
}

OcpHessian ParseOcpHessian(const std::string& name) {
  for (OcpHessian h : {OcpHessian::kLimitedMemory, OcpHessian::kBlockBfgs, OcpHessian::kBlockSr1,
                       OcpHessian::kSecondOrder}) {
    if (ToString(h) == name) return h;
  }
  ThrowInvalidArgument("unknown OCP Hessian '", name,
                       "' (expected limited_memory, block_bfgs, block_sr1 or second_order)");
}

void OcpOptions::Validate() const {
  RequireArgument(stages >= 1 && stages <= kMaxRadauStages, "stages must be in [1, ",
                  kMaxRadauStages, "], got ", stages);
  RequireArgument(finite_elements >= 1, "finite elements per interval must be >= 1, got ",
                  finite_elements);
  RequireArgument(std::isfinite(tolerance) && tolerance > 0.0,
                  "NLP tolerance must be positive, got ", tolerance);
  RequireArgument(max_iterations >= 0, "max iterations must be >= 0, got ", max_iterations);
  RequireArgument(print_level >= 0 && print_level <= 12, "print level must be in [0, 12], got ",
                  print_level);
  RequireArgument(lbfgs_memory >= 1, "limited-memory history must be >= 1, got ", lbfgs_memory);
  RequireArgument(bound_relaxation >= 0.0 && bound_relaxation < 1e-3,
                  "bound relaxation must be in [0, 1e-3), got ", bound_relaxation);
  RequireArgument(warm_start.allFinite(), "warm start must be finite");
  RequireArgument(warm_start_multipliers.constraints.allFinite() &&
                      warm_start_multipliers.lower_bounds.allFinite() &&
                      warm_start_multipliers.upper_bounds.allFinite(),
                  "warm-start multipliers must be finite");
  RequireArgument(!warm_start_multipliers.empty() ? warm_start.size() > 0 : true,
                  "warm-start multipliers need a warm start (the primal point)");
  for (std::size_t i = 0; i < mesh_continuation.size(); ++i) {
    RequireArgument(
        mesh_continuation[i] >= 1 && (i == 0 || mesh_continuation[i] > mesh_continuation[i - 1]),
        "mesh continuation: interval counts must be >= 1 and increasing, got ",
        mesh_continuation[i], " at position ", i + 1);
  }
  // The refinement is the collocation transcription's (shooting ignores it, as the other
  // collocation options).
  RequireArgument(transcription != OcpTranscription::kCollocation ||
                      collocation_refinement_stages == 0 ||
                      (collocation_refinement_stages > stages &&
                       collocation_refinement_stages <= kMaxRadauStages),
                  "collocation refinement stages must be 0 (no refinement) or in [stages + 1, ",
                  kMaxRadauStages, "] = [", stages + 1, ", ", kMaxRadauStages, "], got ",
                  collocation_refinement_stages);
  RequireArgument(std::isfinite(step_equilibration_weight) && step_equilibration_weight >= 0.0,
                  "step equilibration weight must be >= 0, got ", step_equilibration_weight);
  RequireArgument(std::isfinite(level_tolerance) && level_tolerance > 0.0,
                  "homotopy level tolerance must be positive, got ", level_tolerance);
  for (std::size_t i = 0; i < homotopy.size(); ++i) {
    const OcpHomotopyLevel& level = homotopy[i];
    RequireArgument(std::isfinite(level.smoothing) && level.smoothing >= 0.0 &&
                        std::isfinite(level.relaxation) && level.relaxation >= 0.0 &&
                        std::isfinite(level.complementarity) && level.complementarity >= 0.0,
                    "homotopy level ", i + 1,
                    ": smoothing, relaxation and complementarity relaxation must be >= 0, got ",
                    level.smoothing, ", ", level.relaxation, " and ", level.complementarity);
    RequireArgument(level.smoothing > 0.0 || level.relaxation > 0.0 ||
                        level.complementarity > 0.0 || !level.parameters.empty(),
                    "homotopy level ", i + 1,
                    " neither smooths, relaxes nor changes a parameter (the exact problem is "
                    "always solved last)");
    for (const auto& [name, value] : level.parameters) {
      RequireArgument(std::isfinite(value), "homotopy level ", i + 1, ": parameter '", name,
                      "' must be finite, got ", value);
    }
  }
}

namespace {

void RequireOutputs(const OcpProblem& problem, const SmoothFunction& f, const char* what,
                    int expected) {
  if (f.empty()) return;
  RequireArgument(f.typed() != nullptr, problem.name, ": the ", what,
                  " must differentiate automatically (MakeSmoothFunction)");
  if (expected >= 0) {
    RequireArgument(f.num_outputs() == expected, problem.name, ": the ", what, " needs ", expected,
                    " output, got ", f.num_outputs());
  }
}

}  // namespace

void ValidateOcp(const OcpProblem& problem) {
  RequireArgument(!problem.name.empty(), "an optimal control problem needs a name");
  ValidateScene(problem.scene);
  const Scene& scene = problem.scene;
  RequireArgument(problem.intervals >= 1, problem.name,
                  ": the number of control intervals must be >= 1, got ", problem.intervals);
  RequireArgument(scene.time_scale_input < 0, problem.name,
                  ": the scene must not have its own speed of time; set OcpProblem::speed");
  for (const Effect& effect : scene.effects) {
    RequireArgument(!std::holds_alternative<PathConstraints>(effect), problem.name,
                    ": path constraints of the DAI stepper are not supported by the shooting "
                    "transcription (FESD); use OcpProblem::path_constraints");
  }
  std::vector<bool> seen(static_cast<std::size_t>(scene.num_inputs()), false);
  for (int j : problem.controls) {
    RequireArgument(j >= 0 && j < scene.num_inputs(), problem.name, ": control index ", j,
                    " is not an input (the scene has ", scene.num_inputs(), ")");
    RequireArgument(!seen[static_cast<std::size_t>(j)], problem.name, ": control '",
                    scene.inputs[static_cast<std::size_t>(j)].name, "' is listed twice");
    seen[static_cast<std::size_t>(j)] = true;
    const InputSpec& input = scene.inputs[static_cast<std::size_t>(j)];
    RequireArgument(input.kind == InputSpec::Kind::kControl, problem.name, ": input '", input.name,
                    "' is algebraic, not a control");
    RequireArgument(input.lower <= input.upper, problem.name, ": control '", input.name,
                    "' has bounds [", input.lower, ", ", input.upper, "]");
  }
  if (problem.initial_controls.size() > 0) {
    RequireArgument(
        problem.initial_controls.rows() == problem.intervals &&
            problem.initial_controls.cols() == static_cast<Eigen::Index>(problem.controls.size()),
        problem.name, ": initial controls must be ", problem.intervals, " x ",
        problem.controls.size(), ", got ", problem.initial_controls.rows(), " x ",
        problem.initial_controls.cols());
    RequireArgument(problem.initial_controls.allFinite(), problem.name,
                    ": initial controls must be finite");
  }
  for (const auto& free : problem.free_initial_states) {
    RequireArgument(free.state >= 0 && free.state < scene.num_states(), problem.name,
                    ": free initial state index ", free.state, " is not a state");
    RequireArgument(free.lower <= free.upper, problem.name, ": free initial state '",
                    scene.state_names[static_cast<std::size_t>(free.state)], "' has bounds [",
                    free.lower, ", ", free.upper, "]");
  }
  RequireOutputs(problem, problem.running_cost, "running cost", 1);
  RequireOutputs(problem, problem.terminal_cost, "terminal cost", 1);
  RequireOutputs(problem, problem.terminal_equalities, "terminal equalities", -1);
  RequireOutputs(problem, problem.terminal_inequalities, "terminal inequalities", -1);
  RequireOutputs(problem, problem.path_constraints, "path constraints", -1);
  if (problem.speed.enabled) {
    const auto& s = problem.speed;
    RequireArgument(s.lower > 0.0 && s.lower <= s.initial_guess && s.initial_guess <= s.upper &&
                        std::isfinite(s.upper),
                    problem.name, ": speed of time needs 0 < lower <= guess <= upper < inf, got ",
                    s.lower, " <= ", s.initial_guess, " <= ", s.upper);
  }
}

namespace ocp_internal {

namespace {
// f extended by one zero output (the quadrature state's slot).
SmoothFunction Extend(const SmoothFunction& f) {
  if (f.empty()) return f;
  return MakeStackedFunction(f.name() + "+cost", {f, MakeZeroFunction("cost.zero", 1)});
}
}  // namespace

AugmentedScene Augment(const OcpProblem& problem) {
  AugmentedScene out;
  out.scene = problem.scene;
  Scene& scene = out.scene;
  out.num_states = problem.scene.num_states();
  if (!problem.running_cost.empty()) {
    const int nx = out.num_states;
    out.cost_state = nx;
    scene.state_names.push_back("cost");
    Vector x0(nx + 1);
    x0 << scene.initial_state, 0.0;
    scene.initial_state = x0;
    // q' = L(x, u, t, p): the stacked dynamics (f, L); f = 0 if the scene has none.
    const SmoothFunction f =
        scene.dynamics.empty() ? MakeZeroFunction("f.zero", nx) : scene.dynamics;
    scene.dynamics = MakeStackedFunction("f+cost", {f, problem.running_cost});
    for (Effect& effect : scene.effects) {
      if (auto* switching = std::get_if<SwitchingSurfaces>(&effect)) {
        for (SmoothFunction& mode : switching->modes) mode = Extend(mode);
      } else if (auto* relay = std::get_if<HysteresisRelay>(&effect)) {
        relay->mode_a = Extend(relay->mode_a);
        relay->mode_b = Extend(relay->mode_b);
      } else if (auto* complementarity = std::get_if<Complementarity>(&effect)) {
        // B gains a zero row for q (row-major: m more outputs at the end).
        const int m = static_cast<int>(complementarity->pair_names.size());
        complementarity->input_matrix =
            MakeStackedFunction(complementarity->input_matrix.name() + "+cost",
                                {complementarity->input_matrix, MakeZeroFunction("cost.zero", m)});
      } else if (auto* set = std::get_if<MovingSet>(&effect)) {
        // The constraints do not depend on q, so E = I leaves it alone; an explicit basis
        // gets a zero row for it.
        if (set->projection_basis.size() > 0) {
          Matrix basis = Matrix::Zero(nx + 1, set->projection_basis.cols());
          basis.topRows(nx) = set->projection_basis;
          set->projection_basis = basis;
        }
      }
    }
  }
  out.decisions = problem.controls;
  if (problem.speed.enabled) {
    InputSpec speed;
    speed.name = "speed";
    speed.signal.values = {problem.speed.initial_guess};
    speed.lower = problem.speed.lower;
    speed.upper = problem.speed.upper;
    speed.description = "speed of time (free final time)";
    scene.inputs.push_back(speed);
    out.speed_input = scene.num_inputs() - 1;
    scene.time_scale_input = out.speed_input;
    out.decisions.push_back(out.speed_input);
  }
  // Decision inputs are set per interval; drop their breakpoints here.
  for (int j : out.decisions) {
    PiecewiseConstantSignal& signal = scene.inputs[static_cast<std::size_t>(j)].signal;
    signal = PiecewiseConstantSignal{{}, {signal.values.front()}};
  }
  ValidateScene(scene);
  return out;
}

}  // namespace ocp_internal
}  // namespace moreau
