// One adapter per integrator: options from (stages, parameter), result to RunOutput. The
// integrators refuse scenes they cannot handle (std::invalid_argument); the report records
// the refusal instead of guessing applicability here.
#include "moreau/integrators/alpha_dai.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "report.hpp"

namespace moreau::report {
namespace {

// Fields every integrator result has under the same names (Radau IIA has no events).
template <class Result>
RunOutput Common(const Result& result, bool success) {
  RunOutput out;
  out.success = success;
  out.status = ToString(result.status);
  out.message = result.message;
  out.final_time = result.final_time;
  out.final_state = result.final_state;
  if constexpr (requires { result.events; }) out.events = result.events;
  return out;
}

// Newton tolerance (scaled residual) of the fixed-step integrators, below their default 1e-12:
// the report measures errors of the discretization down to 1e-12, and the solve must not be
// what limits them. With the default, FESD's switch times (roots of the element-length
// equations) scatter by up to 6e-11 (S4, s = 3 and 4 on h < 0.25), which hides orders 5 and 7
// below 1e-9; at 1e-14 (about 50 ulps of the O(1) scaled residual rows) the scatter drops to
// round-off (1e-13) and the runs take up to 16% more Newton iterations (S4, s = 3).
constexpr double kNewtonTolerance = 1e-14;

RunOutput RunFesd(const Scene& scene, int stages, double h) {
  FesdOptions options;
  options.stages = stages;
  options.step_size = h;
  options.newton.tolerance = kNewtonTolerance;
  options.record_trajectory = false;
  const FesdResult result = SimulateFesd(scene, options);
  RunOutput out = Common(result, result.status == FesdStatus::kSuccess);
  out.steps = result.stats.num_elements;
  out.newton_iterations = result.stats.num_newton_iterations;
  return out;
}

RunOutput RunTimeStepping(const Scene& scene, int stages, double h) {
  TimeSteppingOptions options;
  options.stages = stages;
  options.step_size = h;
  options.newton.tolerance = kNewtonTolerance;
  options.record_trajectory = false;
  const TimeSteppingResult result = SimulateTimeStepping(scene, options);
  RunOutput out = Common(result, result.status == TimeSteppingStatus::kSuccess);
  out.steps = result.stats.num_steps;
  out.newton_iterations = result.stats.num_newton_iterations;
  return out;
}

// Absolute tolerance relative to rtol: the scenes' states are of order 1 to 20.
constexpr double kAbsoluteToRelative = 1e-2;

RunOutput RunIda(const Scene& scene, double rtol) {
  IdaOptions options;
  options.relative_tolerance = rtol;
  options.absolute_tolerance = kAbsoluteToRelative * rtol;
  options.record_steps = false;
  const IdaResult result = SimulateIda(scene, options);
  RunOutput out = Common(result, result.status == IdaStatus::kSuccess);
  out.steps = result.stats.num_steps;
  out.newton_iterations = result.stats.num_nonlinear_iterations;
  return out;
}

RunOutput RunRadau(const Scene& scene, int stages, double h) {
  RadauOptions options;
  options.stages = stages;
  options.step_size = h;
  options.newton_tolerance = kNewtonTolerance;
  options.record_trajectory = false;
  const RadauResult result = SimulateRadau(scene, options);
  RunOutput out = Common(result, result.status == RadauStatus::kSuccess);
  out.steps = result.stats.num_steps;
  out.newton_iterations = result.stats.num_newton_iterations;
  return out;
}

// rho = 0.5 (the default). Least-change objective: the DAI scene's closed form assumes the
// constraint stays active, which is what the least-change solution does (with the reference
// objective u would follow its user input w = 0 and leave the constraint); without algebraic
// inputs (hopf) the objective plays no role.
constexpr double kAlphaRho = 0.5;

RunOutput RunAlpha(const Scene& scene, double h) {
  AlphaDaiOptions options;
  options.rho = kAlphaRho;
  options.max_step_size = h;
  options.objective = AlphaDaiObjective::kLeastChange;
  options.record_trajectory = false;
  const AlphaDaiResult result = SimulateAlphaDai(scene, options);
  RunOutput out = Common(result, result.status == AlphaDaiStatus::kSuccess);
  out.final_algebraic_inputs = result.final_inputs;
  out.steps = result.stats.num_steps;
  out.newton_iterations = result.stats.num_sqp_iterations;
  return out;
}

Method StageMethod(const std::string& integrator, const std::string& name, int stages,
                   OrderTheory theory, RunOutput (*run)(const Scene&, int, double)) {
  Method method;
  method.integrator = integrator;
  method.stages = stages;
  method.label = name + " s=" + std::to_string(stages);
  method.theory = theory;
  method.step_unit = "step";
  method.iteration_unit = "Newton";
  method.run = [run, stages](const Scene& scene, double h) { return run(scene, stages, h); };
  return method;
}

}  // namespace

std::vector<Method> Methods() {
  std::vector<Method> methods;
  for (int s = 1; s <= 4; ++s) {
    Method m = StageMethod("fesd", "FESD", s, OrderTheory::kRadau, RunFesd);
    m.step_unit = "element";
    methods.push_back(m);
  }
  for (int s = 1; s <= 3; ++s) {
    methods.push_back(StageMethod("timestepping", "time-stepping", s,
                                  OrderTheory::kFirstOrderAcrossSwitches, RunTimeStepping));
  }
  for (int s = 1; s <= 4; ++s) {
    methods.push_back(StageMethod("radau", "Radau IIA", s, OrderTheory::kRadau, RunRadau));
  }
  Method ida;
  ida.integrator = "ida";
  ida.label = "IDA";
  ida.tolerance_driven = true;
  ida.theory = OrderTheory::kNone;
  ida.step_unit = "step";
  ida.iteration_unit = "nonlinear";
  ida.run = RunIda;
  methods.push_back(ida);
  Method alpha;
  alpha.integrator = "alpha";
  alpha.label = "alpha rho=0.5";
  alpha.theory = OrderTheory::kSecondOrder;
  alpha.step_unit = "step";
  alpha.iteration_unit = "SQP";
  alpha.run = RunAlpha;
  methods.push_back(alpha);
  return methods;
}

}  // namespace moreau::report
