// Example optimal control problems (include/moreau/ocp/catalog.hpp, docs/ocp.md).
#include <cmath>

#include "moreau/core/error.hpp"
#include "moreau/model/projection.hpp"
#include "moreau/ocp/catalog.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// min over x0 of int_0^2 x^2 dt + (x(2) - 5/3)^2 with x' in 2 - sign(x) (Stewart and
// Anitescu): the optimum x0* = (9 - sqrt(417))/8 lies before the switch at -x0/3, so the
// cost depends on the switch time (docs/ocp.md derives the closed form).
OcpProblem StewartAnitescu() {
  OcpProblem problem;
  problem.name = "stewart_anitescu";
  problem.description =
      "min over x0 of int_0^2 x^2 dt + (x(2) - 5/3)^2, x' in 2 - sign(x): x0* = (9 - sqrt "
      "417)/8";
  problem.scene = MakeScene("F4");
  problem.scene.initial_state[0] = -1.0;  // initial guess of x0
  problem.intervals = 4;
  problem.free_initial_states = {{0, -5.0, 5.0}};
  problem.running_cost = MakeSmoothFunction(
      "stewart_anitescu.L", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0] * x[0];
      });
  problem.terminal_cost =
      MakeSmoothFunction("stewart_anitescu.Phi", 1,
                         [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
                           const auto d = x[0] - 5.0 / 3.0;
                           out[0] = d * d;
                         });
  return problem;
}

// The wave-rider (sweeping paper, Sec. VI-A): min int u^2 dt, |u| <= 1, x(T) = (1, 4), the
// moving boundary x1 + cos(x2 - t) >= 0 being the only way to move x1.
OcpProblem WaveRider() {
  OcpProblem problem;
  problem.name = "wave_rider";
  problem.description =
      "min int u^2 dt, |u| <= 1, x(T) = (1, 4): ride the moving boundary x1 + cos(x2 - t) >= 0";
  problem.scene = MakeScene("S4");
  // The paper's x(0) = (0, 2) lies outside C(0) (cos 2 < 0): the sweeping process starts with
  // the jump onto C(0), the projection of (0, 2), which is the initial state used here. The
  // paper does not state T; T = 8 leaves time for one push of the wave.
  Scene& scene = problem.scene;
  const MovingSetProjection jump =
      ProjectOntoMovingSets(scene, Vector{{0.0, 2.0}}, scene.initial_time,
                            scene.InputValues(scene.initial_time), scene.ParameterValues(), false);
  RequireArgument(jump.converged, "wave_rider: ", jump.message);
  scene.initial_state = jump.x;
  scene.final_time = 8.0;
  InputSpec& u = problem.scene.inputs[0];
  u.lower = -1.0;
  u.upper = 1.0;
  u.signal.values = {0.5};
  problem.controls = {0};
  problem.intervals = 10;
  problem.running_cost = MakeSmoothFunction(
      "wave_rider.L", 1, [](const auto&, const auto& u_, const auto&, const auto&, auto& out) {
        out[0] = u_[0] * u_[0];
      });
  problem.terminal_equalities = MakeSmoothFunction(
      "wave_rider.g", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0] - 1.0;
        out[1] = x[1] - 4.0;
      });
  return problem;
}

// The moving doorway (sweeping paper, Sec. VI-B): the pusher (x3, x4) pushes the slider (x1,
// x2) up through the doorway between two moving discs, with the cost as printed in the paper,
// int |u|^2 dt + 1000 |(x2, x3) - (1, 7)|^2 (the slider's height to 1, past the doorway at
// y = 0; the pusher's abscissa to 7).
OcpProblem Doorway() {
  OcpProblem problem;
  problem.name = "doorway";
  problem.description =
      "push the slider (x1, x2) up through the moving doorway: min int |u|^2 dt + 1000 |(x2, "
      "x3) - (1, 7)|^2, |u_i| <= 5 (cost as printed in the paper)";
  problem.scene = MakeScene("S5");
  for (InputSpec& u : problem.scene.inputs) u.signal.values = {0.0};
  problem.controls = {0, 1};
  problem.intervals = 20;
  // The slider moves only when pushed, so u = 0 is a stationary point (no contact, no
  // gradient). The initial guess is a pushing plan on the exact dynamics, produced by a
  // feedback rule evaluated at every interval start: the pusher goes round and below the
  // slider, pushes it up at speed 3 while staying under it (the doorway's walls steer the
  // slider sideways), and once the slider is at height 1 retreats to (7, -8.8). It takes the
  // slider through the doorway (final height 1.44, cost 359).
  const double plan[20][2] = {{0.833, 0.0},    {0.0, -5.0},     {-4.167, 3.0},   {1.92, 0.0},
                              {0.0, -1.705},   {-4.167, 3.833}, {-1.993, 2.339}, {0.117, 2.998},
                              {1.861, 2.432},  {1.637, 2.57},   {1.351, 2.714},  {1.049, 2.831},
                              {-0.258, 2.99},  {-0.321, 2.984}, {-0.738, -5.0},  {-0.123, -5.0},
                              {0.451, -3.167}, {5.0, 0.0},      {5.0, 0.0},      {2.857, 0.0}};
  problem.initial_controls.resize(problem.intervals, 2);
  for (int k = 0; k < problem.intervals; ++k) {
    problem.initial_controls.row(k) << plan[k][0], plan[k][1];
  }
  problem.running_cost = MakeSmoothFunction(
      "doorway.L", 1, [](const auto&, const auto& u, const auto&, const auto&, auto& out) {
        out[0] = u[0] * u[0] + u[1] * u[1];
      });
  problem.terminal_cost = MakeSmoothFunction(
      "doorway.Phi", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = 1000.0 * ((x[1] - 1.0) * (x[1] - 1.0) + (x[2] - 7.0) * (x[2] - 7.0));
      });
  return problem;
}

// The turbo car (hysteresis paper, Sec. V): from rest at 0 to q = 150 at rest in minimum time,
// |u| <= 5, |v| <= 25, the turbo tripling the acceleration with hysteresis (on at v = 15, off
// at v = 10). Free final time by a speed of time on a numerical horizon of 5.
OcpProblem TurboCar() {
  OcpProblem problem;
  problem.name = "turbo_car";
  problem.description =
      "time-optimal turbo car with hysteresis: q(T) = 150, v(T) = 0, |u| <= 5, |v| <= 25 "
      "(continuous-time optimum 152/15)";
  problem.scene = MakeScene("H2");
  problem.scene.final_time = 5.0;  // numerical time
  InputSpec& u = problem.scene.inputs[0];
  u.signal = PiecewiseConstantSignal{{}, {0.0}};
  u.lower = -5.0;
  u.upper = 5.0;
  problem.controls = {0};
  problem.intervals = 10;
  problem.speed.enabled = true;
  problem.speed.lower = 0.1;
  problem.speed.upper = 10.0;
  problem.speed.initial_guess = 2.0;
  problem.terminal_cost = MakeSmoothFunction(
      "turbo_car.T", 1,
      [](const auto&, const auto&, const auto& t, const auto&, auto& out) { out[0] = t; });
  problem.terminal_equalities = MakeSmoothFunction(
      "turbo_car.g", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0] - 150.0;
        out[1] = x[1];
      });
  problem.path_constraints = MakeSmoothFunction(
      "turbo_car.v_max", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[1] - 25.0;
        out[1] = -x[1] - 25.0;
      });
  return problem;
}

OcpOptions Defaults() { return OcpOptions(); }

// Many short intervals (N > 10): mesh continuation from the catalog's N = 10 through 25, 50
// and 100 (docs/ocp.md, "Scaling in N"); without it the turbo car at N = 200 does not converge
// and the wave-rider ends at IPOPT's acceptable level. N = 10 itself is solved directly.
const std::vector<int> kMeshContinuation = {10, 25, 50, 100};

OcpOptions TurboCarOptions() {
  OcpOptions options;
  options.mesh_continuation = kMeshContinuation;
  return options;
}

// The wave-rider's x1(T) = 1 is degenerate (docs/ocp.md): relaxed to |x1(T) - 1| <= eps and
// |x2(T) - 4| <= eps first, eps = 1e-2 and 1e-4, then exact. Block BFGS: the same optimum
// from every start to 1e-10 and far fewer iterations at large N (docs/ocp.md).
OcpOptions WaveRiderOptions() {
  OcpOptions options;
  options.homotopy = {{0.0, 1e-2, {}}, {0.0, 1e-4, {}}};
  options.hessian = OcpHessian::kBlockBfgs;
  options.mesh_continuation = kMeshContinuation;
  return options;
}

// The doorway (docs/ocp.md, "Doorway"): multiple shooting has kinks of order one at the nodes
// of a push and cycles; the collocation transcription (the FESD equations as constraints,
// complementarity relaxed to sigma = 1e-3, then 1e-5, then exact on the pieces of the last
// relaxed solution) solves it, with the exact second-order Hessian. The pushing plan's FESD
// trajectory satisfies complementarity exactly, so the first level starts at a small sigma
// (from sigma = 1 the relaxed walls let the slider tunnel and the levels drift to worse local
// optima). A unit step-equilibration weight keeps element lengths near equal where nothing
// switches, so that the exact level's equal-length conditions start nearly satisfied. After
// the exact level (and its element minima) the refinement to s = 5 stages: the s = 3
// collocation error where contacts begin left the NLP's x(T) 2.15e-6 from the re-simulation of
// its controls; s = 4 leaves 5.7e-8 (IDA: a graze at t = 6.85 it resolves as a short contact)
// and 1.2e-9 (FESD) in 10 more iterations, s = 5 5.6e-11 and 5.2e-11 in 9.
OcpOptions DoorwayOptions() {
  OcpOptions options;
  options.transcription = OcpTranscription::kCollocation;
  options.hessian = OcpHessian::kSecondOrder;
  OcpHomotopyLevel coarse, fine;
  coarse.complementarity = 1e-3;
  fine.complementarity = 1e-5;
  options.homotopy = {coarse, fine};
  options.step_equilibration_weight = 1.0;
  options.collocation_refinement_stages = 5;
  return options;
}

}  // namespace

const std::vector<OcpDefinition>& OcpCatalog() {
  static const std::vector<OcpDefinition> catalog = {
      {"stewart_anitescu", "min over x0 through a Filippov switch (closed-form optimum)",
       StewartAnitescu, Defaults},
      {"wave_rider", "steer x(T) = (1, 4) by riding a moving boundary (sweeping)", WaveRider,
       WaveRiderOptions},
      {"doorway", "push a slider through a moving doorway (sweeping, 5 constraints)", Doorway,
       DoorwayOptions},
      {"turbo_car", "time-optimal car with a hysteresis turbo (time-freezing)", TurboCar,
       TurboCarOptions},
  };
  return catalog;
}

namespace {
const OcpDefinition& FindOcp(const std::string& name) {
  std::string available;
  for (const OcpDefinition& definition : OcpCatalog()) {
    if (definition.name == name) return definition;
    available += (available.empty() ? "" : ", ") + definition.name;
  }
  ThrowInvalidArgument("unknown optimal control problem '", name, "'; available: ", available);
}
}  // namespace

OcpProblem MakeOcpProblem(const std::string& name) { return FindOcp(name).make(); }

OcpOptions MakeOcpOptions(const std::string& name) { return FindOcp(name).options(); }

}  // namespace moreau
