// The methods of the report: integrator settings for moreau::Simulate(), the one entry point the
// command line and the Python module use as well. The integrators refuse scenes they cannot
// handle (std::invalid_argument); the report records the refusal instead of guessing
// applicability here.
#include "report.hpp"

namespace moreau::report {
namespace {

// Newton tolerance (scaled residual) of the fixed-step integrators, below their default 1e-12:
// the report measures errors of the discretization down to 1e-12, and the solve must not be
// what limits them. With the default, FESD's switch times (roots of the element-length
// equations) scatter by up to 6e-11 (S4, s = 3 and 4 on h < 0.25), which hides orders 5 and 7
// below 1e-9; at 1e-14 (about 50 ulps of the O(1) scaled residual rows) the scatter drops to
// round-off (1e-13) and the runs take up to 16% more Newton iterations (S4, s = 3).
constexpr double kNewtonTolerance = 1e-14;

// Absolute tolerance relative to rtol (IDA): the scenes' states are of order 1 to 20.
constexpr double kAbsoluteToRelative = 1e-2;

// rho = 0.5 (the default). Least-change objective: the DAI scene's closed form assumes the
// constraint stays active, which is what the least-change solution does (with the reference
// objective u would follow its user input w = 0 and leave the constraint); without algebraic
// inputs (hopf) the objective plays no role.
constexpr double kAlphaRho = 0.5;

// A method that runs `integrator` with `fixed` options and the swept parameter as option
// `swept` ("h" or "rtol"); `derived` adds options that follow the parameter.
Method MakeMethod(const std::string& integrator, std::string label, int stages, OrderTheory theory,
                  SimulationSettings settings, std::string swept, bool tolerance_driven = false) {
  const IntegratorSpec& spec = FindIntegrator(integrator);
  settings.integrator = integrator;
  if (stages > 0) settings.options["stages"] = static_cast<long>(stages);
  Method method;
  method.integrator = integrator;
  method.stages = stages;
  method.label = std::move(label);
  method.theory = theory;
  method.tolerance_driven = tolerance_driven;
  method.step_unit = spec.step_unit;
  method.iteration_unit = spec.iteration_unit;
  method.run = [settings, swept, tolerance_driven](const Scene& scene, double parameter) {
    SimulationSettings run = settings;
    run.options[swept] = parameter;
    if (tolerance_driven) run.options["atol"] = kAbsoluteToRelative * parameter;
    return Simulate(scene, run);
  };
  return method;
}

// Fixed-step settings: Newton to kNewtonTolerance, only the final point recorded.
SimulationSettings FixedStep() {
  SimulationSettings settings;
  settings.options = {{"newton_tol", kNewtonTolerance}, {"record_trajectory", false}};
  return settings;
}

}  // namespace

std::vector<Method> Methods() {
  std::vector<Method> methods;
  for (int s = 1; s <= 4; ++s) {
    methods.push_back(MakeMethod("fesd", "FESD s=" + std::to_string(s), s, OrderTheory::kRadau,
                                 FixedStep(), "h"));
  }
  // Adaptive FESD (issue 16), swept over rtol like IDA; the Newton tolerance stays at its
  // default (the error estimate and the switch times are meant for the tolerances users give).
  for (int s = 3; s <= 4; ++s) {
    SimulationSettings adaptive;
    adaptive.options = {{"adaptive", true}, {"record_trajectory", false}};
    methods.push_back(MakeMethod("fesd", "FESD adaptive s=" + std::to_string(s), s,
                                 OrderTheory::kNone, adaptive, "rtol", true));
  }
  for (int s = 1; s <= 3; ++s) {
    methods.push_back(MakeMethod("timestepping", "time-stepping s=" + std::to_string(s), s,
                                 OrderTheory::kFirstOrderAcrossSwitches, FixedStep(), "h"));
  }
  for (int s = 1; s <= 4; ++s) {
    methods.push_back(MakeMethod("radau", "Radau IIA s=" + std::to_string(s), s,
                                 OrderTheory::kRadau, FixedStep(), "h"));
  }
  SimulationSettings ida;
  ida.options = {{"record_steps", false}};
  methods.push_back(MakeMethod("ida", "IDA", 0, OrderTheory::kNone, ida, "rtol", true));
  SimulationSettings alpha;
  alpha.options = {
      {"rho", kAlphaRho}, {"objective", std::string("least-change")}, {"record_trajectory", false}};
  methods.push_back(MakeMethod("alpha", "alpha rho=0.5", 0, OrderTheory::kSecondOrder, alpha, "h"));
  return methods;
}

}  // namespace moreau::report
