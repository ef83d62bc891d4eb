// moreau::Simulate, the one entry point of the command line, the report and Python: it runs
// the integrator itself (results bit-identical to SimulateXxx with the same options), its
// declared options carry the Options structs' defaults, and every refusal of an effect comes
// from the declared support.
#include "moreau/integrators/simulate.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <set>

#include "moreau/integrators/alpha_dai.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

bool BitEqual(const Vector& a, const Vector& b) {
  return a.size() == b.size() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(),
                                       sizeof(double) * static_cast<std::size_t>(a.size())) == 0);
}

template <class Result>
void ExpectSame(const SimulationResult& common, const Result& direct) {
  EXPECT_EQ(common.status, ToString(direct.status));
  EXPECT_EQ(common.message, direct.message);
  EXPECT_EQ(common.final_time, direct.final_time);
  EXPECT_TRUE(BitEqual(common.final_state, direct.final_state));
  ASSERT_EQ(common.trajectory.size(), direct.trajectory.size());
  for (std::size_t k = 0; k < common.trajectory.size(); ++k) {
    EXPECT_EQ(common.trajectory.t[k], direct.trajectory.t[k]);
    EXPECT_TRUE(BitEqual(common.trajectory.x[k], direct.trajectory.x[k]));
  }
  if constexpr (requires { direct.events; }) {
    ASSERT_EQ(common.events.size(), direct.events.size());
    for (std::size_t k = 0; k < common.events.size(); ++k) {
      EXPECT_EQ(common.events[k].t, direct.events[k].t);
      EXPECT_EQ(common.events[k].what, direct.events[k].what);
    }
  }
}

TEST(SimulateTest, RunsEachIntegratorExactlyAsItsOwnFunction) {
  {
    FesdOptions options;
    options.stages = 2;
    options.step_size = 0.05;
    options.finite_elements = 3;
    const SimulationResult common = Simulate(
        MakeScene("S3"), {"fesd", {{"stages", 2L}, {"h", 0.05}, {"fe", std::string("3")}}});
    ExpectSame(common, SimulateFesd(MakeScene("S3"), options));
    EXPECT_EQ(common.Stat("num_elements"),
              SimulateFesd(MakeScene("S3"), options).stats.num_elements);
  }
  {
    TimeSteppingOptions options;
    options.step_size = 0.02;
    ExpectSame(Simulate(MakeScene("F1"), {"timestepping", {{"h", 0.02}}}),
               SimulateTimeStepping(MakeScene("F1"), options));
  }
  {
    IdaOptions options;
    options.relative_tolerance = 1e-9;
    ExpectSame(Simulate(MakeScene("H1"), {"ida", {{"rtol", 1e-9}}}),
               SimulateIda(MakeScene("H1"), options));
  }
  {
    RadauOptions options;
    options.adaptive = true;
    options.step_size = 0.0;  // not given: the controller picks the first step
    ExpectSame(Simulate(MakeScene("hopf"), {"radau", {{"adaptive", true}}}),
               SimulateRadau(MakeScene("hopf"), options));
  }
  {
    AlphaDaiOptions options;
    options.objective = AlphaDaiObjective::kLeastChange;
    ExpectSame(Simulate(MakeScene("D2"), {"alpha", {{"objective", std::string("least-change")}}}),
               SimulateAlphaDai(MakeScene("D2"), options));
  }
}

TEST(SimulateTest, DeclaredDefaultsAreTheOptionsStructDefaults) {
  // A run without options reports every declared option with its default; a few spot checks
  // against the structs (the declarations read them off default-constructed Options).
  const SimulationResult fesd = Simulate(MakeScene("S3"), {"fesd", {}});
  std::map<std::string, SettingValue> used(fesd.options.begin(), fesd.options.end());
  EXPECT_EQ(std::get<long>(used.at("stages")), FesdOptions{}.stages);
  EXPECT_EQ(std::get<double>(used.at("h")), FesdOptions{}.step_size);
  EXPECT_EQ(std::get<double>(used.at("newton_tol")), FesdOptions{}.newton.tolerance);
  EXPECT_EQ(std::get<std::string>(used.at("switching")), "stewart");
  for (const IntegratorSpec& spec : Integrators()) {
    std::set<std::string> names;
    for (const OptionSpec& option : spec.options) {
      EXPECT_TRUE(names.insert(option.name).second) << spec.name << ": " << option.name;
      EXPECT_FALSE(option.meaning.empty()) << spec.name << ": " << option.name;
    }
    std::set<std::string> stats;
    for (const StatSpec& stat : spec.stats) EXPECT_TRUE(stats.insert(stat.name).second);
  }
}

TEST(SimulateTest, RefusalsFollowTheDeclaredSupportOnEveryCatalogScene) {
  for (const SceneDefinition& definition : SceneCatalog()) {
    const Scene scene = definition.make();
    const std::vector<std::string> supporting = IntegratorsSupporting(scene);
    for (const IntegratorSpec& spec : Integrators()) {
      const bool supported =
          std::find(supporting.begin(), supporting.end(), spec.name) != supporting.end();
      if (supported) {
        EXPECT_NO_THROW(RequireSupportedEffects(scene, spec.name)) << definition.name;
        continue;
      }
      try {
        RequireSupportedEffects(scene, spec.name);
        ADD_FAILURE() << definition.name << " with " << spec.name << " was not refused";
      } catch (const std::invalid_argument& error) {
        const std::string message = error.what();
        EXPECT_NE(message.find(spec.title + " does not support"), std::string::npos) << message;
        // Every integrator the message suggests does support the scene.
        for (const std::string& other : supporting) {
          EXPECT_NE(message.find(other), std::string::npos) << message;
        }
      }
    }
    // auto picks a supporting integrator.
    const std::string automatic = AutomaticIntegrator(scene);
    EXPECT_TRUE(std::find(supporting.begin(), supporting.end(), automatic) != supporting.end())
        << definition.name << ": " << automatic;
  }
}

TEST(SimulateTest, BadSettingsAreNamed) {
  const Scene scene = MakeScene("S3");
  auto expect_message = [&scene](const SimulationSettings& settings, const std::string& part) {
    try {
      Simulate(scene, settings);
      ADD_FAILURE() << "no error, expected: " << part;
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(part), std::string::npos) << error.what();
    }
  };
  expect_message({"nope", {}}, "unknown integrator 'nope'; available: auto, radau");
  expect_message({"fesd", {{"rho", 0.5}}}, "option 'rho' does not apply to integrator 'fesd'");
  expect_message({"fesd", {{"stages", 2.5}}},
                 "bad value 2.5 for option 'stages': expected an integer");
  expect_message({"fesd", {{"stages", std::string("x")}}}, "expected an integer");
  expect_message({"fesd", {{"h", true}}}, "bad value true for option 'h': expected a number");
  expect_message({"fesd", {{"switching", std::string("filippov")}}},
                 "expected one of stewart, heaviside");
  expect_message({"fesd", {{"stages", 0L}}}, "stages must be in [1, 7]");
  expect_message({"radau", {}}, "does not support the moving set 'floor'");
  expect_message({"ida", {{"sensitivities", true}}},
                 "option 'sensitivities' does not apply to integrator 'ida'");
}

TEST(SimulateTest, SensitivitiesArriveInTheCommonResult) {
  const Scene scene = MakeScene("F1");
  FesdOptions options;
  options.sensitivities = true;
  const FesdResult direct = SimulateFesd(scene, options);
  const SimulationResult common = Simulate(scene, {"fesd", {{"sensitivities", true}}});
  ASSERT_TRUE(common.sensitivities.has_value());
  EXPECT_EQ(common.sensitivities->initial_state, direct.sensitivities.initial_state);
  EXPECT_EQ(common.sensitivities->parameters, direct.sensitivities.parameters);
  // Time-stepping: the scene-state blocks of the lowered derivative (y = (x, clock)).
  TimeSteppingOptions ts;
  ts.sensitivities = true;
  const TimeSteppingResult ts_direct = SimulateTimeStepping(scene, ts);
  const SimulationResult ts_common = Simulate(scene, {"timestepping", {{"sensitivities", true}}});
  ASSERT_TRUE(ts_common.sensitivities.has_value());
  const Eigen::Index nx = scene.num_states(), ny = ts_direct.sensitivities.rows();
  EXPECT_EQ(ts_common.sensitivities->initial_state, ts_direct.sensitivities.topLeftCorner(nx, nx));
  EXPECT_EQ(ts_common.sensitivities->parameters,
            ts_direct.sensitivities.block(0, ny, nx, scene.num_parameters()));
  EXPECT_FALSE(Simulate(scene, {"fesd", {}}).sensitivities.has_value());
}

}  // namespace
}  // namespace moreau

namespace moreau {
namespace {

// The reusable Simulator (FESD lowered once) gives Simulate's result bit for bit for every
// value set, run after run, including sensitivities; other integrators set up each run anew.
TEST(SimulatorTest, RepeatedRunsEqualFreshSimulations) {
  for (const std::string integrator : {"fesd", "timestepping", "ida"}) {
    const Scene scene = MakeScene("S3");
    std::map<std::string, SettingValue> options;
    if (integrator == "fesd") options = {{"stages", 3L}, {"h", 0.05}, {"sensitivities", true}};
    Simulator simulator(scene, {integrator, options});
    EXPECT_EQ(simulator.integrator(), integrator);
    const std::vector<std::vector<std::pair<std::string, double>>> runs = {
        {}, {{"x0.x1", 0.9}, {"floor", -0.8}}, {}, {{"tf", 3.0}}};
    for (const auto& values : runs) {
      Scene fresh = scene;
      for (const auto& [name, value] : values) SetSceneValue(&fresh, name, value);
      const SimulationResult a = simulator.Run(values);
      const SimulationResult b = Simulate(fresh, {integrator, options});
      ASSERT_TRUE(a.success) << a.message;
      EXPECT_EQ(a.final_time, b.final_time) << integrator;
      EXPECT_TRUE(BitEqual(a.final_state, b.final_state)) << integrator;
      ASSERT_EQ(a.events.size(), b.events.size()) << integrator;
      for (std::size_t k = 0; k < a.events.size(); ++k) EXPECT_EQ(a.events[k].t, b.events[k].t);
      if (integrator == "fesd") {
        ASSERT_TRUE(a.sensitivities && b.sensitivities);
        EXPECT_EQ(a.sensitivities->initial_state, b.sensitivities->initial_state);
        EXPECT_EQ(a.sensitivities->parameters, b.sensitivities->parameters);
      }
    }
  }
}

TEST(SimulatorTest, BadValuesAreNamedPerRun) {
  Simulator simulator(MakeScene("S3"), {"fesd", {}});
  EXPECT_THROW(simulator.Run({{"radius", 1.0}}), std::invalid_argument);
  // x0 below the floor: the run is refused as SimulateFesd would refuse it.
  try {
    simulator.Run({{"x0.x2", -2.0}});
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("infeasible initial state"), std::string::npos)
        << error.what();
  }
  EXPECT_TRUE(simulator.Run().success);  // the scene's own values again
}

}  // namespace
}  // namespace moreau
