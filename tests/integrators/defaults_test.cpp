// Right by default (docs/accuracy.md): with no step given FESD and Radau control their error,
// atol follows rtol, the first step follows the model's time scale; fixed-step runs estimate
// their error and warn; runaways stop with a named status; output times and tf are exact.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "../problems/reference_problems.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// The error of an error-controlled run stays within this factor of rtol relative to the
// solution's scale (the proportionality the adaptive tests assert for FESD).
constexpr double kProportionality = 10.0;

SimulationResult RunWith(const Scene& scene, const std::string& integrator,
                         std::map<std::string, SettingValue> options = {}) {
  return Simulate(scene, SimulationSettings{integrator, std::move(options)});
}

double HopfError(const SimulationResult& result) {
  const testing::ReferenceProblem hopf = testing::Hopf();
  return (result.final_state - hopf.solution(result.final_time)).lpNorm<Eigen::Infinity>();
}

TEST(RightByDefault, NoStepMeansErrorControl) {
  EXPECT_TRUE(FesdOptions{}.ErrorControlled());
  EXPECT_TRUE(RadauOptions{}.ErrorControlled());
  FesdOptions fixed;
  fixed.step_size = 0.1;
  EXPECT_FALSE(fixed.ErrorControlled());
  // A given h keeps its fixed steps (shooting codes), unchanged: the F1 grid of H = 0.1.
  const SimulationResult result = RunWith(MakeScene("hopf"), "radau", {{"h", 0.1}});
  ASSERT_TRUE(result.success) << result.message;
  EXPECT_EQ(result.num_steps, 20);
  // An explicit h = 0 is a bad step, not "choose for me".
  EXPECT_THROW(RunWith(MakeScene("hopf"), "radau", {{"h", 0.0}}), std::invalid_argument);
}

// atol scales with rtol (per state, rtol times its scale): at rtol = 1e-10 the error follows
// rtol instead of stalling at a fixed atol = 1e-8 (23 rtol before).
TEST(RightByDefault, AbsoluteToleranceFollowsTheRelativeOne) {
  const Scene hopf = MakeScene("hopf");
  for (double rtol : {1e-6, 1e-8, 1e-10}) {
    const SimulationResult radau = RunWith(hopf, "radau", {{"rtol", rtol}});
    ASSERT_TRUE(radau.success) << radau.message;
    EXPECT_LE(HopfError(radau), kProportionality * rtol) << "radau rtol " << rtol;
  }
}

// The starting step (Hairer, Norsett & Wanner) scales with the model's time scale: the same
// decay in milliseconds starts with a step 1000 times shorter.
TEST(RightByDefault, InitialStepFollowsTheTimeScale) {
  auto first_step = [](double tau) {
    const Scene scene = ParseScene(
        "name = \"decay\"\nstates = [\"x\", \"y\"]\nx0 = [1.0, 2.0]\ntf = \"5*tau\"\n"
        "dynamics = [\"-x/tau\", \"y*(1 - y)/tau\"]\n[[parameters]]\nname = \"tau\"\nvalue = " +
            std::to_string(tau) + "\n",
        "decay.toml");
    const SimulationResult result = RunWith(scene, "radau");
    EXPECT_TRUE(result.success) << result.message;
    return result.trajectory.t[1] - result.trajectory.t[0];
  };
  const double ratio = first_step(1e-3) / first_step(1.0);
  // 1e-3 up to what is not scale-free in a run (the Newton iterates' stopping test, the
  // accepted step after a rejection): within 10%.
  constexpr double kScaleFree = 0.1;
  EXPECT_NEAR(ratio, 1e-3, kScaleFree * 1e-3);
}

// A fixed-step run estimates its own error and warns far above the tolerance.
TEST(RightByDefault, FixedStepsEstimateTheirErrorAndWarn) {
  const Scene hopf = MakeScene("hopf");
  const SimulationResult coarse = RunWith(hopf, "radau", {{"h", 0.5}, {"stages", 1L}});
  ASSERT_TRUE(coarse.success) << coarse.message;
  ASSERT_TRUE(coarse.error_estimate.has_value());
  // The estimate sums local errors of order s + 1 = 2 for a method of order 1: it is of the
  // size of the true error, not orders below it.
  const double error = HopfError(coarse);
  EXPECT_GT(*coarse.error_estimate, 0.1 * error) << "true error " << error;
  EXPECT_GT(*coarse.error_estimate, kErrorWarningFactor * kDefaultRelativeTolerance);
  ASSERT_EQ(coarse.warnings.size(), 1u);
  EXPECT_NE(coarse.warnings[0].find("estimated error of this fixed-step run"), std::string::npos)
      << coarse.warnings[0];

  // The embedded estimate has local order s + 1 = 4 while the solution has order 5: an upper
  // estimate (docs/accuracy.md), below the warning from h = 0.002 (8e-5 at h = 0.01).
  const SimulationResult fine = RunWith(hopf, "radau", {{"h", 0.002}});
  ASSERT_TRUE(fine.success) << fine.message;
  ASSERT_TRUE(fine.error_estimate.has_value());
  EXPECT_LE(*fine.error_estimate, kErrorWarningFactor * kDefaultRelativeTolerance);
  EXPECT_TRUE(fine.warnings.empty());

  // FESD's fixed steps too (F1 with H = 0.5: the comparison solve of every step).
  const SimulationResult fesd = RunWith(MakeScene("F1"), "fesd", {{"h", 0.5}, {"stages", 1L}});
  ASSERT_TRUE(fesd.success) << fesd.message;
  ASSERT_TRUE(fesd.error_estimate.has_value());
  EXPECT_FALSE(fesd.warnings.empty());
  EXPECT_GT(fesd.Stat("error_estimate"), kErrorWarningFactor * kDefaultRelativeTolerance);
}

// A fixed grid with more steps than max_steps is refused before any work.
TEST(RightByDefault, TooLongFixedGridsAreRefusedUpFront) {
  const Scene f2c = MakeScene("F2c");
  for (const char* integrator : {"fesd", "timestepping", "radau"}) {
    Scene scene = integrator == std::string("radau") ? MakeScene("hopf") : f2c;
    SetSceneValue(&scene, "tf", 1e300);
    try {
      RunWith(scene, integrator, {{"h", 1e5}});
      ADD_FAILURE() << integrator << ": not refused";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find("more than max_steps"), std::string::npos)
          << integrator << ": " << error.what();
    }
  }
}

// A model whose sqrt argument turns negative at t = 0.1276: every integrator stops there at
// once with a status naming the function, its output and the time (IDA took 10^7 steps and
// wrote 1.5 GB before).
TEST(RightByDefault, NonFiniteModelValuesAreNamed) {
  const Scene scene = ParseScene(
      "name = \"cliff\"\nstates = [\"x\", \"y\"]\nx0 = [0.0, 1.0]\ntf = 1.0\n"
      "dynamics = [\"sqrt(0.1276 - t)\", \"-y\"]\n",
      "cliff.toml");
  constexpr double kCliff = 0.1276;
  for (const char* integrator : {"radau", "fesd", "ida"}) {
    const SimulationResult result = RunWith(scene, integrator);
    SCOPED_TRACE(integrator);
    EXPECT_FALSE(result.success);
    EXPECT_TRUE(result.status == "non_finite" || result.status == "step_size_too_small")
        << result.status << ": " << result.message;
    EXPECT_NE(result.message.find("the dynamics f"), std::string::npos) << result.message;
    EXPECT_NE(result.message.find("output 'x'"), std::string::npos) << result.message;
    EXPECT_NEAR(result.final_time, kCliff, 1e-6) << result.message;
    EXPECT_LT(result.trajectory.size(), 10'000u);
  }
}

// The times asked for, exactly: IDA's output_times give t0, those times and tf only; fixed
// steps end at tf exactly (not 9.9999999999997158 or 10.000000000000028).
TEST(RightByDefault, OutputTimesAndTheFinalTimeAreExact) {
  const Scene s3 = MakeScene("S3");
  const SimulationResult ida =
      RunWith(s3, "ida", {{"output_times", std::vector<double>{0.5, 1.0}}});
  ASSERT_TRUE(ida.success) << ida.message;
  EXPECT_EQ(ida.trajectory.t, (std::vector<double>{0.0, 0.5, 1.0, s3.final_time}));

  Scene long_f1 = MakeScene("F1");
  SetSceneValue(&long_f1, "tf", 10.0);
  for (const auto& [integrator, h] : {std::pair{"fesd", 0.1}, {"timestepping", 0.1}}) {
    const SimulationResult result = RunWith(long_f1, integrator, {{"h", h}});
    ASSERT_TRUE(result.success) << integrator << ": " << result.message;
    EXPECT_EQ(result.final_time, 10.0) << integrator;
    EXPECT_EQ(result.trajectory.t.back(), 10.0) << integrator;
  }
  Scene long_hopf = MakeScene("hopf");
  SetSceneValue(&long_hopf, "tf", 10.0);
  const SimulationResult radau = RunWith(long_hopf, "radau", {{"h", 0.1}});
  ASSERT_TRUE(radau.success) << radau.message;
  EXPECT_EQ(radau.final_time, 10.0);
  EXPECT_EQ(radau.trajectory.t.back(), 10.0);
}

// Near-miss option names get the closest valid one; an option of another integrator says so.
TEST(RightByDefault, UnknownOptionsSuggestTheClosest) {
  const Scene s3 = MakeScene("S3");
  auto message = [&](const std::string& integrator, const std::string& name) {
    try {
      RunWith(s3, integrator, {{name, 3L}});
    } catch (const std::invalid_argument& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("fesd", "stage")
                .find("unknown option 'stage' for integrator 'fesd'; did "
                      "you mean 'stages'?"),
            std::string::npos);
  EXPECT_NE(message("ida", "h").find("option 'h' does not apply to integrator 'ida'"),
            std::string::npos);
}

}  // namespace
}  // namespace moreau
