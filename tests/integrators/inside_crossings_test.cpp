// Switches inside a step (docs/fesd-formulation.md, section 11): a pulse of a switching function
// narrower than the steps, a disc that brushes a point between two steps. Each integrator
// either resolves them (FESD fixed and adaptive, IDA) or says that it does not (time-stepping,
// and any run whose indicator bounds stay undecided): never x(T) = 0 and `success` alone.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene_file.hpp"

namespace moreau {
namespace {

// x' = 1 only while the Gaussian pulse exp(-((t - 2)/w)^2) exceeds 1/2, i.e. for
// |t - 2| < w sqrt(ln 2): x(T) = 2 w sqrt(ln 2) for T > 2 + w sqrt(ln 2) (x(0) = 0).
Scene PulseScene(double w) {
  Scene scene = ParseScene(R"(
name = "pulse"
states = ["x"]
x0 = [0.0]
tf = 4.0
dynamics = ["0"]

[[parameters]]
name = "w"
value = 0.05

[[effects]]
kind = "switching"
name = "pulse"
surfaces = ["exp(-((t - 2)/w)^2) - 0.5"]
below = [["0"]]
above = [["1"]]
)");
  SetSceneValue(&scene, "w", w);
  return scene;
}
double PulseExact(double w) { return 2.0 * w * std::sqrt(std::log(2.0)); }

// A point at rest at the origin and a disc of radius R whose centre moves at unit speed along
// x2 = -R/2 (from x1 = -1 at t = 0): a sweeping process (the point moves only while the disc
// pushes it, along the disc's normal). With phi the angle of the point on the disc's circle
// (from the direction of motion), the contact starts at sin(phi0) = 1/2 (phi0 = pi/6, the
// point at x1 - c1 = R cos(phi0)), and the point, pushed with the normal component cos(phi) of
// the unit velocity, slides along the circle with R phi' = sin(phi) until phi = pi/2, where the
// push ends: it takes R ln cot(phi0 / 2) = R ln(2 + sqrt 3), over which the centre moves as far.
// Final point: x1 = -R cos(phi0) + R ln(2 + sqrt 3) = R (ln(2 + sqrt 3) - sqrt(3)/2),
// x2 = -R/2 + R = R/2; for R = 0.01: (0.0045093249, 0.005).
Scene BrushScene(double radius) {
  Scene scene = ParseScene(R"(
name = "brush"
states = ["x1", "x2"]
x0 = [0.0, 0.0]
tf = 2.0
dynamics = ["0", "0"]

[[parameters]]
name = "R"
value = 0.01

[[effects]]
kind = "moving_set"
name = "disc"
constraints = ["(x1 - (t - 1))^2 + (x2 + R/2)^2 - R^2"]
)");
  SetSceneValue(&scene, "R", radius);
  return scene;
}
Vector BrushExact(double radius) {
  return Vector{{radius * (std::log(2.0 + std::sqrt(3.0)) - std::sqrt(3.0) / 2.0), radius / 2.0}};
}

// Adaptive runs meet their tolerance on x(T) within this factor (the bound asserted by the
// adaptive tests, fesd_adaptive_test.cpp: error per unit step adds up to about rtol).
constexpr double kToleranceFactor = 10.0;
// Fixed steps that contain the whole pulse: both switch times are located by the event equation
// to the Newton tolerance, and x' = 1 in between is exact for the collocation.
constexpr double kLocated = 1e-10;

TEST(InsideCrossingsTest, GaussianPulseWithAdaptiveFesd) {
  for (double w : {0.05, 0.1}) {
    for (auto [rtol, atol] : {std::pair{1e-6, 1e-8}, std::pair{1e-10, 1e-12}}) {
      const SimulationResult r =
          Simulate(PulseScene(w), {"fesd", {{"rtol", rtol}, {"atol", atol}}});
      ASSERT_TRUE(r.success) << r.message;
      EXPECT_NEAR(r.final_state[0], PulseExact(w), kToleranceFactor * rtol)
          << "w = " << w << ", rtol = " << rtol;
      EXPECT_EQ(r.events.size(), 2u) << "w = " << w << ", rtol = " << rtol;
      EXPECT_TRUE(r.warnings.empty());
    }
  }
}

TEST(InsideCrossingsTest, GaussianPulseWithIda) {
  // IDA's default tolerances (rtol 1e-8): the pulse of w = 0.01 is found on the interpolant of
  // a step that flies over it (x' = 0 before: the steps grow without bound).
  const double w = 0.01;
  const SimulationResult r = Simulate(PulseScene(w), {"ida", {}});
  ASSERT_TRUE(r.success) << r.message;
  EXPECT_NEAR(r.final_state[0], PulseExact(w), kToleranceFactor * 1e-8);
  EXPECT_EQ(r.events.size(), 2u);
}

TEST(InsideCrossingsTest, FixedStepsThatContainTheWholePulseResolveIt) {
  // One step of H = 4 (two elements of 2) and steps of 1 and 2, s = 2 and 3: the pulse lies
  // between the nodes of an element; the crossing search finds it and the step ends on it.
  const double w = 0.05;
  for (auto [h, stages] : {std::pair{4.0, 3L}, std::pair{1.0, 3L}, std::pair{2.0, 2L}}) {
    const SimulationResult r = Simulate(PulseScene(w), {"fesd", {{"h", h}, {"stages", stages}}});
    ASSERT_TRUE(r.success) << r.message;
    EXPECT_NEAR(r.final_state[0], PulseExact(w), kLocated) << "h = " << h;
    EXPECT_EQ(r.events.size(), 2u) << "h = " << h;
  }
  const SimulationResult one = Simulate(PulseScene(w), {"fesd", {{"h", 4.0}}});
  EXPECT_GT(one.Stat("num_inside_crossings"), 0.0);
}

TEST(InsideCrossingsTest, TimeSteppingWarnsOfAPulseInsideAStep) {
  // Steps of 0.3 with s = 1: the pulse (1.958 .. 2.042) lies inside the step from 1.8 to 2.1
  // and no stage sees it. Time-stepping has no switch detection: x(T) = 0, with a warning.
  const SimulationResult r = Simulate(PulseScene(0.05), {"timestepping", {{"h", 0.3}}});
  ASSERT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.final_state[0], 0.0);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("t = 1.8"), std::string::npos) << r.warnings[0];
  EXPECT_EQ(r.Stat("num_inside_crossings"), 1.0);
  // A step boundary inside the pulse (tstops) lets it see the pulse: no warning.
  const SimulationResult stopped =
      Simulate(PulseScene(0.05), {"timestepping", {{"h", 0.3}, {"tstops", 2.0}}});
  EXPECT_TRUE(stopped.warnings.empty());
  EXPECT_GT(stopped.final_state[0], 0.0);
}

TEST(InsideCrossingsTest, DiscBrushingAPointWithAdaptiveFesd) {
  const double radius = 0.01;
  const Vector exact = BrushExact(radius);
  for (double rtol : {1e-6, 1e-8, 1e-10}) {
    const SimulationResult r = Simulate(BrushScene(radius), {"fesd", {{"rtol", rtol}}});
    ASSERT_TRUE(r.success) << r.message;
    EXPECT_LE((r.final_state - exact).lpNorm<Eigen::Infinity>(), kToleranceFactor * rtol)
        << "rtol = " << rtol << ": x(T) = " << r.final_state.transpose();
    EXPECT_TRUE(r.warnings.empty());
  }
  const SimulationResult ida = Simulate(BrushScene(radius), {"ida", {}});
  ASSERT_TRUE(ida.success) << ida.message;
  EXPECT_LE((ida.final_state - exact).lpNorm<Eigen::Infinity>(), kToleranceFactor * 1e-8);
}

// A trajectory point at t (up to the round-off of the integrated clock).
bool HasPoint(const SimulationResult& r, double t) {
  for (double point : r.trajectory.t) {
    if (std::fabs(point - t) <= 1e-12) return true;
  }
  return false;
}

TEST(InsideCrossingsTest, StopTimesAreDeclaredForEveryIntegratorThatSteps) {
  // tstops is one option of the IntegratorSpec declarations (command line and Python get it):
  // the steps end there. 2.0537 lies on none of the default grids.
  constexpr double kStop = 2.0537;
  for (const char* integrator : {"fesd", "ida", "timestepping"}) {
    const SimulationResult r = Simulate(PulseScene(0.05), {integrator, {{"tstops", kStop}}});
    ASSERT_TRUE(r.success) << integrator << ": " << r.message;
    EXPECT_TRUE(HasPoint(r, kStop)) << integrator;
    const SimulationResult plain = Simulate(PulseScene(0.05), {integrator, {}});
    EXPECT_FALSE(HasPoint(plain, kStop)) << integrator;
  }
  const Scene smooth =
      ParseScene("name = \"decay\"\nstates = [\"x\"]\nx0 = [1.0]\ntf = 1.0\ndynamics = [\"-x\"]\n");
  EXPECT_TRUE(HasPoint(Simulate(smooth, {"radau", {{"tstops", 0.3}, {"h", 0.25}}}), 0.3));
  EXPECT_THROW(Simulate(smooth, {"radau", {{"tstops", std::vector<double>{NAN}}}}),
               std::invalid_argument);
}

TEST(InsideCrossingsTest, BoundsThatCannotDecideGiveAWarning) {
  // A switching function whose interval evaluation overestimates (1e8 (sin t - sin t) is
  // zero, but its enclosure over an interval of width d is about 1e8 d wide) and whose true
  // minimum, 1e-6 at t = 2.3 (on no step's node), is a graze far above the event tolerance
  // (1e-9): the bounds admit a crossing down to 2^-30 of a step (1e8 2^-30 > 1e-6 for steps
  // above 1e-5) that the samples never confirm. Fixed steps warn; adaptive steps halve six
  // times, then go on and warn. Neither reports a switch, and neither is silent.
  const Scene scene = ParseScene(R"toml(
name = "graze"
states = ["x"]
x0 = [0.0]
tf = 4.0
dynamics = ["0"]

[[effects]]
kind = "switching"
name = "graze"
surfaces = ["(t - 2.3)^2 + 1e-6 + 1e8*(sin(t) - sin(t))"]
below = [["1"]]
above = [["0"]]
)toml");
  for (const SimulationSettings& settings :
       {SimulationSettings{"fesd", {{"h", 1.0}}}, SimulationSettings{"fesd", {{"rtol", 1e-6}}}}) {
    const SimulationResult r = Simulate(scene, settings);
    ASSERT_TRUE(r.success) << r.message;
    EXPECT_EQ(r.final_state[0], 0.0);
    EXPECT_TRUE(r.events.empty());
    ASSERT_EQ(r.warnings.size(), 1u) << settings.options.begin()->first;
    EXPECT_NE(r.warnings[0].find("tstops"), std::string::npos) << r.warnings[0];
    EXPECT_GT(r.Stat("num_unresolved_crossings"), 0.0);
  }
}

}  // namespace
}  // namespace moreau
