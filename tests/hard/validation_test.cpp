// Input-validation matrix (issue 9): every public entry point gets wrong dimensions, NaN and
// infinite values, empty scenes, infeasible initial states, inconsistent hysteresis memory,
// zero or negative step sizes and horizons, and out-of-range options; each is refused with
// std::invalid_argument whose message names the problem (checked by substring). Numerical
// trouble that appears only during a run ends with a status, time and reason.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "moreau/integrators/alpha_dai.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/integrators/radau_tableau.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Expects `call` to throw std::invalid_argument whose message contains `fragment`.
void ExpectRefused(const std::function<void()>& call, const std::string& fragment,
                   const std::string& context) {
  try {
    call();
    ADD_FAILURE() << context << ": no exception, expected one containing '" << fragment << "'";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos)
        << context << ": expected '" << fragment << "' in: " << error.what();
  } catch (const std::exception& error) {
    ADD_FAILURE() << context << ": wrong exception type: " << error.what();
  }
}

// Every simulate entry point that accepts the scene's effects, with default options.
using Simulator = std::function<void(const Scene&)>;
struct Entry {
  std::string name;
  Simulator run;
};
std::vector<Entry> DcsSimulators() {
  return {{"fesd", [](const Scene& s) { SimulateFesd(s, FesdOptions{}); }},
          {"timestepping", [](const Scene& s) { SimulateTimeStepping(s, {}); }},
          {"ida", [](const Scene& s) { SimulateIda(s, IdaOptions{}); }}};
}
std::vector<Entry> AllSimulators() {
  std::vector<Entry> all = DcsSimulators();
  all.push_back({"radau", [](const Scene& s) { SimulateRadau(s, RadauOptions{}); }});
  all.push_back({"alpha", [](const Scene& s) { SimulateAlphaDai(s, AlphaDaiOptions{}); }});
  all.push_back({"lowering", [](const Scene& s) { LoweredSystem lowered(s); }});
  return all;
}

// Scene defects every entry point must refuse (ValidateScene is the common gate).
struct Defect {
  std::string what;
  std::function<void(Scene*)> apply;
  std::string fragment;
};
std::vector<Defect> SceneDefects() {
  return {
      {"empty scene", [](Scene* s) { *s = Scene{}; }, "scene name must not be empty"},
      {"no states",
       [](Scene* s) {
         s->state_names.clear();
         s->initial_state.resize(0);
       },
       "a scene needs at least one state"},
      {"x0 too short", [](Scene* s) { s->initial_state.resize(1); },
       "initial state has 1 entries, expected 2"},
      {"x0 NaN", [](Scene* s) { s->initial_state[0] = kNaN; }, "initial state x0.x1 is not finite"},
      {"x0 Inf", [](Scene* s) { s->initial_state[1] = kInf; }, "initial state x0.x2 is not finite"},
      {"parameter NaN", [](Scene* s) { s->parameters[0].value = kNaN; },
       "parameter 'omega' is not finite"},
      {"parameter -Inf", [](Scene* s) { s->parameters[0].value = -kInf; },
       "parameter 'omega' is not finite"},
      {"zero horizon", [](Scene* s) { s->final_time = s->initial_time; },
       "horizon must be positive"},
      {"negative horizon", [](Scene* s) { s->final_time = -1.0; }, "horizon must be positive"},
      {"infinite horizon", [](Scene* s) { s->final_time = kInf; }, "final time tf is not finite"},
      {"NaN initial time", [](Scene* s) { s->initial_time = kNaN; }, "initial time is not finite"},
      {"dynamics with the wrong size",
       [](Scene* s) {
         s->dynamics = MakeSmoothFunction(
             "f3", 3, [](const auto&, const auto&, const auto&, const auto&, auto&) {});
       },
       "dynamics f ('f3') must have 2 outputs, got 3"},
      {"dynamics reading x[5]",
       [](Scene* s) {
         s->dynamics = MakeSmoothFunction(
             "reader", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
               out[0] = x[5];
             });
       },
       "function 'reader' reads x[5]"},
      {"dynamics NaN at x0",
       [](Scene* s) {
         s->dynamics = MakeSmoothFunction(
             "nan_f", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
               using std::sqrt;
               out[0] = sqrt(-1.0 - x[0] * x[0]);
             });
       },
       "dynamics f ('nan_f') is not finite at the initial state"},
      {"duplicate state names", [](Scene* s) { s->state_names[1] = s->state_names[0]; },
       "duplicate name 'x1'"},
  };
}

// The grazing scene (2 states, a moving set, parameters omega and floor) is the base.
TEST(ValidationMatrix, SceneDefectsAreRefusedByEveryEntryPoint) {
  for (const Defect& defect : SceneDefects()) {
    Scene scene = MakeScene("hard_grazing");
    defect.apply(&scene);
    ExpectRefused([&] { ValidateScene(scene); }, defect.fragment, "ValidateScene: " + defect.what);
    for (const Entry& entry : AllSimulators()) {
      // Radau and alpha refuse the moving set itself; the defect must still be named first
      // or the effect refused, never a crash.
      try {
        entry.run(scene);
        ADD_FAILURE() << entry.name << " accepted: " << defect.what;
      } catch (const std::invalid_argument& error) {
        const std::string message = error.what();
        const bool named = message.find(defect.fragment) != std::string::npos;
        const bool effect_refused = message.find("moving set 'floor'") != std::string::npos;
        EXPECT_TRUE(named || effect_refused)
            << entry.name << ", " << defect.what << ": unexpected message: " << message;
      }
    }
  }
}

// Moving-set, switching and path-constraint defects (wrong dimensions, NaN).
TEST(ValidationMatrix, EffectDefectsNameTheEffect) {
  {
    Scene scene = MakeScene("hard_simultaneous");
    std::get<MovingSet>(scene.effects[0]).constraint_names = {"c1"};
    ExpectRefused([&] { ValidateScene(scene); },
                  "constraints ('hard_simultaneous.c') must have 1 outputs, got 2",
                  "constraint count mismatch");
  }
  {
    Scene scene = MakeScene("hard_simultaneous");
    std::get<MovingSet>(scene.effects[0]).projection_basis = Matrix::Identity(3, 1);
    ExpectRefused([&] { ValidateScene(scene); }, "projection basis E must have 2 rows, got 3",
                  "projection basis rows");
    std::get<MovingSet>(scene.effects[0]).projection_basis = Matrix{{2.0}, {0.0}};
    ExpectRefused([&] { ValidateScene(scene); }, "orthonormal columns", "projection basis norm");
    std::get<MovingSet>(scene.effects[0]).projection_basis = Matrix{{kNaN}, {0.0}};
    ExpectRefused([&] { ValidateScene(scene); }, "projection basis E is not finite",
                  "projection basis NaN");
  }
  {
    Scene scene = MakeScene("hard_zeno");
    std::get<SwitchingSurfaces>(scene.effects[0]).modes.pop_back();
    ExpectRefused([&] { ValidateScene(scene); }, "needs 4 modes (one per sign pattern), got 3",
                  "mode count");
  }
  {
    Scene scene = MakeScene("hard_index3");
    std::get<PathConstraints>(scene.effects[0]).state_lower = Vector::Zero(3);
    ExpectRefused([&] { ValidateScene(scene); }, "state bounds need 0 or 2 entries, got 3",
                  "state bound size");
    std::get<PathConstraints>(scene.effects[0]).state_lower = Vector{{kNaN, 0.0}};
    ExpectRefused([&] { ValidateScene(scene); }, "state bound is NaN", "state bound NaN");
  }
  {
    Scene scene = MakeScene("hard_index3");
    scene.inputs[0].initial_guess = kInf;
    ExpectRefused([&] { ValidateScene(scene); }, "algebraic input 'u' initial guess is not finite",
                  "algebraic guess Inf");
    scene = MakeScene("hard_index3");
    scene.inputs[0].lower = 1.0;
    scene.inputs[0].upper = -1.0;
    ExpectRefused([&] { ValidateScene(scene); }, "algebraic input 'u' has invalid bounds",
                  "algebraic bounds reversed");
    scene = MakeScene("hard_index3");
    scene.inputs[0].signal.values = {kNaN};
    ExpectRefused([&] { ValidateScene(scene); }, "has a non-finite value", "signal NaN");
  }
}

// x0 outside C(t0). FESD is left out: on main it projects an infeasible x0 onto C(t0) when
// LoweringOptions::require_feasible_initial_state is false (a pending change).
TEST(ValidationMatrix, InfeasibleInitialStateIsRefused) {
  Scene scene = MakeScene("hard_simultaneous");
  scene.initial_state[1] = -0.5;
  const std::string fragment = "infeasible initial state: constraint 'c2' of moving set 'walls'";
  ExpectRefused([&] { SimulateTimeStepping(scene, {}); }, fragment, "timestepping");
  ExpectRefused([&] { SimulateIda(scene, IdaOptions{}); }, fragment, "ida");
  ExpectRefused([&] { ValidateScene(scene); }, fragment, "ValidateScene");

  // alpha: x0 outside the state bounds, and path constraints no algebraic input satisfies.
  Scene dai = MakeScene("hard_index3");
  dai.initial_state[0] = -0.5;  // phi = A sin 0 - x1 = 0.5 > 0 whatever u is
  ExpectRefused([&] { SimulateAlphaDai(dai, AlphaDaiOptions{}); }, "floor", "alpha phi(x0) > 0");
  dai = MakeScene("hard_index3");
  std::get<PathConstraints>(dai.effects[0]).state_lower = Vector{{0.5, -kInf}};
  ExpectRefused([&] { SimulateAlphaDai(dai, AlphaDaiOptions{}); }, "x1", "alpha state bound");
}

// Hysteresis memory: values other than 0/1 are refused; a memory inconsistent with the input
// (w0 = B while psi < 0) is re-initialized by a relay switch at t0 (documented behaviour).
TEST(ValidationMatrix, HysteresisMemory) {
  Scene scene = MakeScene("H1");
  std::get<HysteresisRelay>(scene.effects[0]).initial_memory = 2;
  ExpectRefused([&] { ValidateScene(scene); }, "initial memory must be 0 (mode A) or 1 (mode B)",
                "memory 2");
  ExpectRefused([&] { SimulateFesd(scene, FesdOptions{}); }, "initial memory must be 0", "fesd");
  ExpectRefused([&] { SimulateIda(scene, IdaOptions{}); }, "initial memory must be 0", "ida");
  scene = MakeScene("H1");
  auto& relay = std::get<HysteresisRelay>(scene.effects[0]);
  std::swap(scene.parameters[static_cast<std::size_t>(relay.lower_threshold)].value,
            scene.parameters[static_cast<std::size_t>(relay.upper_threshold)].value);
  ExpectRefused([&] { ValidateScene(scene); }, "upper threshold must exceed the lower one",
                "thresholds reversed");
  scene = MakeScene("H1");
  std::get<HysteresisRelay>(scene.effects[0]).auxiliary_gain = 0.0;
  ExpectRefused([&] { ValidateScene(scene); }, "auxiliary gain must be positive", "gain 0");

  // Inconsistent memory: heater off (w = 1) although x0 = 15 is below x_on = 18.
  scene = MakeScene("H1");
  scene.final_time = 1.0;
  std::get<HysteresisRelay>(scene.effects[0]).initial_memory = 1;
  const FesdResult fesd = SimulateFesd(scene, FesdOptions{});
  ASSERT_EQ(fesd.status, FesdStatus::kSuccess) << fesd.message;
  ASSERT_EQ(fesd.relays.size(), 1u);
  ASSERT_FALSE(fesd.relays[0].jump_times.empty());
  EXPECT_EQ(fesd.relays[0].jump_times[0], 0.0);
  EXPECT_EQ(fesd.relays[0].ValueAt(0.5), 0);  // heater back on
  const IdaResult ida = SimulateIda(scene, IdaOptions{});
  ASSERT_EQ(ida.status, IdaStatus::kSuccess) << ida.message;
  ASSERT_EQ(ida.relays.size(), 1u);
  EXPECT_EQ(ida.relays[0].ValueAt(0.5), 0);
  // Both follow x' = -0.2 x + 5 from t0: x(1) = 25 - 10 e^{-0.2}.
  constexpr double kAccuracy = 1e-6;  // default tolerances of both integrators
  EXPECT_NEAR(fesd.final_state[0], 25.0 - 10.0 * std::exp(-0.2), kAccuracy);
  EXPECT_NEAR(ida.final_state[0], 25.0 - 10.0 * std::exp(-0.2), kAccuracy);
}

// Options out of range, zero/negative/NaN/Inf step sizes: Validate() and the Simulate entry
// points name the option.
TEST(ValidationMatrix, OptionsOutOfRange) {
  const Scene scene = MakeScene("hard_grazing");
  for (double h : {0.0, -0.1, kNaN, kInf}) {
    const std::string context = "h = " + std::to_string(h);
    // FESD and Radau: step_size 0 in the structs means error-controlled steps (the default;
    // Simulate refuses a given h = 0, CliValidationMatrix checks that).
    FesdOptions fesd;
    fesd.step_size = h;
    if (h != 0.0) {
      ExpectRefused([&] { SimulateFesd(scene, fesd); }, "step size", "fesd " + context);
    }
    TimeSteppingOptions ts;
    ts.step_size = h;
    ExpectRefused([&] { SimulateTimeStepping(scene, ts); }, "step size h must be positive",
                  "timestepping " + context);
    RadauOptions radau;
    radau.step_size = h;
    if (h != 0.0) ExpectRefused([&] { radau.Validate(); }, "step size", "radau " + context);
    AlphaDaiOptions alpha;
    alpha.step_size = h;
    // 0 means error-controlled steps.
    if (h != 0.0) ExpectRefused([&] { alpha.Validate(); }, "step_size", "alpha " + context);
    IdaOptions ida;
    ida.max_step = h;
    if (h == 0.0) continue;  // 0 means no limit
    ExpectRefused([&] { ida.Validate(); }, "max step", "ida " + context);
  }
  auto fesd = [](auto change, const std::string& fragment) {
    FesdOptions options;
    change(options);
    ExpectRefused([&] { options.Validate(); }, fragment, "fesd: " + fragment);
  };
  fesd([](FesdOptions& o) { o.stages = 0; }, "stages must be in [1, 7], got 0");
  fesd([](FesdOptions& o) { o.stages = 8; }, "stages must be in [1, 7], got 8");
  fesd([](FesdOptions& o) { o.finite_elements = 0; }, "finite elements per step must be >= 1");
  fesd([](FesdOptions& o) { o.event_tolerance = -1.0; }, "event tolerance");
  fesd([](FesdOptions& o) { o.event_tolerance = kNaN; }, "event tolerance");
  fesd([](FesdOptions& o) { o.min_element_fraction = 0.6; }, "min element fraction");
  fesd([](FesdOptions& o) { o.max_event_retries = 0; }, "max event retries must be >= 1");
  fesd([](FesdOptions& o) { o.newton.tolerance = 0.0; }, "Newton tolerance must be positive");
  fesd([](FesdOptions& o) { o.newton.max_iterations = 0; }, "max Newton iterations");

  IdaOptions ida;
  ida.relative_tolerance = 0.0;
  ExpectRefused([&] { ida.Validate(); }, "relative tolerance must be positive", "ida rtol");
  ida = IdaOptions{};
  ida.absolute_tolerance = kNaN;
  ExpectRefused([&] { ida.Validate(); }, "absolute tolerance", "ida atol");
  ida = IdaOptions{};
  ida.max_events = 0;
  ExpectRefused([&] { ida.Validate(); }, "max events must be positive", "ida max_events");
  ida = IdaOptions{};
  ida.output_times = {kNaN};
  ExpectRefused([&] { ida.Validate(); }, "output times must be finite", "ida output times");

  AlphaDaiOptions alpha;
  alpha.rho = 1.0;
  ExpectRefused([&] { alpha.Validate(); }, "rho", "alpha rho 1");
  alpha = AlphaDaiOptions{};
  alpha.rank_tolerance = 0.0;
  ExpectRefused([&] { alpha.Validate(); }, "rank_tolerance", "alpha rank tolerance");
  alpha = AlphaDaiOptions{};
  alpha.max_retries = -1;
  ExpectRefused([&] { alpha.Validate(); }, "max_retries (MAXTRY) must be >= 0", "alpha retries");
  alpha = AlphaDaiOptions{};
  alpha.error_tolerance = -1.0;
  ExpectRefused([&] { alpha.Validate(); }, "error_tolerance", "alpha errtol");

  RadauOptions radau;
  radau.stages = 9;
  ExpectRefused([&] { radau.Validate(); }, "Radau stages must be in [1, 7]", "radau stages");
  radau = RadauOptions{};
  radau.adaptive = true;
  radau.relative_tolerance = -1.0;
  ExpectRefused([&] { radau.Validate(); }, "relative tolerance", "radau rtol");

  ExpectRefused([] { RadauIIA(0); }, "stages", "RadauIIA(0)");
  ExpectRefused([] { AlphaCoefficients::FromRho(-0.1); }, "rho", "FromRho");
  ExpectRefused([] { ParseSwitchingForm("nope"); }, "nope", "ParseSwitchingForm");
  ExpectRefused([] { ParseAlphaDaiObjective("nope"); }, "unknown alpha-method objective 'nope'",
                "ParseAlphaDaiObjective");
}

// More fixed steps than any run can store, or a step below the resolution of t: refused up
// front instead of exhausting memory or producing zero-length steps.
TEST(ValidationMatrix, UnresolvableFixedStepGrids) {
  Scene scene = MakeScene("hard_grazing");
  scene.final_time = 1e12;
  TimeSteppingOptions ts;
  ts.step_size = 1e-3;
  ExpectRefused([&] { SimulateTimeStepping(scene, ts); }, "fixed steps", "too many steps");
  FesdOptions fesd;
  fesd.step_size = 1e-3;
  ExpectRefused([&] { SimulateFesd(scene, fesd); }, "fixed steps", "too many steps (fesd)");
  ExpectRefused([] { FixedStepGrid(1e8, 1e8 + 1.0, 1e-9); }, "fixed steps", "grid size");
  ExpectRefused([] { FixedStepGrid(1e10, 1e10 + 1e-5, 1e-7); }, "resolution",
                "step below resolution");
}

// Wrong dimensions at the lower-level entry points.
TEST(ValidationMatrix, WrongDimensions) {
  const Scene scene = MakeScene("hard_grazing");
  LoweredSystem lowered(scene);
  ExpectRefused([&] { lowered.SetParameters(Vector::Zero(5)); },
                "expected 2 parameter values, got 5", "SetParameters");
  ExpectRefused([&] { lowered.SetInputs(Vector::Zero(1)); }, "expected 0 input values, got 1",
                "SetInputs");
  FesdOptions fesd;
  fesd.initial_state = Vector::Zero(7);
  ExpectRefused([&] { SimulateFesd(scene, fesd); }, "FESD initial lowered state needs", "fesd y0");
  fesd.initial_state = Vector{{kNaN, 0.0, 0.0}};
  ExpectRefused([&] { SimulateFesd(scene, fesd); }, "finite", "fesd y0 NaN");
  ExpectRefused([] { MakeScene("nope"); }, "unknown scene 'nope'; available scenes:", "MakeScene");
  Scene copy = scene;
  ExpectRefused([&] { SetSceneValue(&copy, "nope", 1.0); }, "has no value named 'nope'",
                "SetSceneValue name");
  ExpectRefused([&] { SetSceneValue(&copy, "omega", kNaN); }, "must be finite",
                "SetSceneValue NaN");
}

// Effects an integrator cannot handle are refused by name.
TEST(ValidationMatrix, UnsupportedEffectsAreNamed) {
  ExpectRefused([] { SimulateRadau(MakeScene("hard_grazing"), RadauOptions{}); },
                "moving set 'floor'", "radau");
  ExpectRefused([] { SimulateAlphaDai(MakeScene("hard_zeno"), AlphaDaiOptions{}); },
                "switching surfaces 'twisting'", "alpha");
  ExpectRefused([] { SimulateTimeStepping(MakeScene("H1"), {}); }, "hysteresis relay 'thermostat'",
                "timestepping");
  for (const Entry& entry : DcsSimulators()) {
    ExpectRefused([&] { entry.run(MakeScene("hard_index3")); }, "path constraints 'floor'",
                  entry.name);
  }
}

// A function that turns NaN during the run (after the validated initial point) ends the run
// with a numerical status carrying the time, never with NaN in the result or a crash. The
// function is -1 (smooth, with zero derivative) up to t = 0.5 and NaN after it.
TEST(ValidationMatrix, NaNDuringTheRunIsAStatus) {
  Scene scene = MakeScene("hard_fast_wall");
  scene.dynamics = MakeSmoothFunction(
      "nan_after_half", 1, [](const auto&, const auto&, const auto& t, const auto&, auto& out) {
        using std::sqrt;
        out[0] = -1.0 + 0.0 * sqrt(0.5 - t);
      });
  const FesdResult fesd = SimulateFesd(scene, FesdOptions{});
  EXPECT_NE(fesd.status, FesdStatus::kSuccess);
  EXPECT_NE(fesd.message.find("t = "), std::string::npos) << fesd.message;
  EXPECT_TRUE(fesd.final_state.allFinite()) << fesd.message;
  EXPECT_LE(fesd.final_time, 0.5);
  const TimeSteppingResult ts = SimulateTimeStepping(scene, {});
  EXPECT_NE(ts.status, TimeSteppingStatus::kSuccess);
  EXPECT_NE(ts.message.find("t = "), std::string::npos) << ts.message;
  EXPECT_TRUE(ts.final_state.allFinite()) << ts.message;
  EXPECT_LE(ts.final_time, 0.5);
  const IdaResult ida = SimulateIda(scene, IdaOptions{});
  EXPECT_NE(ida.status, IdaStatus::kSuccess);
  EXPECT_TRUE(ida.final_state.allFinite()) << ida.message;
  EXPECT_LE(ida.final_time, 0.5 + 1e-9);
  EXPECT_FALSE(ida.message.empty());

  Scene smooth = MakeScene("hopf");
  smooth.dynamics = MakeSmoothFunction(
      "nan_after_half", 2, [](const auto&, const auto&, const auto& t, const auto&, auto& out) {
        using std::sqrt;
        out[0] = -1.0 + 0.0 * sqrt(0.5 - t);
      });
  const RadauResult radau = SimulateRadau(smooth, RadauOptions{});
  EXPECT_NE(radau.status, RadauStatus::kSuccess);
  EXPECT_TRUE(radau.final_state.allFinite()) << radau.message;
  EXPECT_NE(radau.message.find("t = "), std::string::npos) << radau.message;
}

}  // namespace
}  // namespace moreau
