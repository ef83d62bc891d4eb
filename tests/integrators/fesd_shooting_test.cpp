// What a shooting code needs from FESD: the speed of time (free final times), starting from a
// full lowered state (relay memories and the clock included) and the derivatives of the final
// lowered state with respect to it.
#include <gtest/gtest.h>

#include <cmath>

#include "../problems/reference_problems.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Adds a control input "speed" with value s and makes it the speed of time.
Scene WithSpeedOfTime(Scene scene, double s) {
  InputSpec speed;
  speed.name = "speed";
  speed.signal.values = {s};
  scene.inputs.push_back(speed);
  scene.time_scale_input = scene.num_inputs() - 1;
  return scene;
}

TEST(FesdShootingTest, SpeedOfTimeStretchesTheDiscretizationExactly) {
  // F1 at speed 2 over tau in [0, T/2] with steps h is F1 over [0, T] with steps 2h: the same
  // discrete equations up to the factor 2 in every rate, hence the same result up to round-off.
  const Scene f1 = MakeScene("F1");
  Scene fast = WithSpeedOfTime(f1, 2.0);
  fast.final_time = f1.final_time / 2;
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.0245;
  const FesdResult scaled = SimulateFesd(fast, options);
  options.step_size = 0.049;
  const FesdResult plain = SimulateFesd(f1, options);
  ASSERT_EQ(scaled.status, FesdStatus::kSuccess) << scaled.message;
  ASSERT_EQ(plain.status, FesdStatus::kSuccess) << plain.message;
  constexpr double kRoundOff = 1e-12;
  EXPECT_LE((scaled.final_state - plain.final_state).lpNorm<Eigen::Infinity>(), kRoundOff);
  EXPECT_NEAR(scaled.final_time, f1.final_time, kRoundOff);  // the clock is physical time
  ASSERT_EQ(scaled.events.size(), plain.events.size());
  EXPECT_NEAR(scaled.events[0].t, plain.events[0].t, kRoundOff);
}

TEST(FesdShootingTest, SpeedOfTimeWithRelaysKeepsPhysicalSwitchTimes) {
  // H1 at speed 2: the horizon is numerical time and physical time is the clock; the physical
  // switch times are those of the thermostat.
  Scene scene = WithSpeedOfTime(MakeScene("H1"), 2.0);
  scene.final_time = 6.0;
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.05;
  const FesdResult result = SimulateFesd(scene, options);
  ASSERT_EQ(result.status, FesdStatus::kSuccess) << result.message;
  const auto exact = testing::H1().Switches(result.final_time);
  std::vector<double> switches;
  for (const Event& e : result.events) {
    if (e.kind == EventKind::kRelaySwitch) switches.push_back(e.t);
  }
  ASSERT_EQ(switches.size(), exact.size());
  for (std::size_t k = 0; k < exact.size(); ++k) EXPECT_NEAR(switches[k], exact[k].t, 1e-8);
  // Numerical time is either frozen or runs at speed 2 (this horizon ends inside the jump
  // that starts at the fifth switch); each completed jump lasts 1/(a s) = 0.5.
  EXPECT_NEAR(result.final_time, 2.0 * (scene.final_time - result.stats.frozen_time), 1e-10);
  EXPECT_GT(result.stats.frozen_time, 0.5 * (static_cast<double>(exact.size()) - 1) - 1e-10);
  EXPECT_LT(result.stats.frozen_time, 0.5 * static_cast<double>(exact.size()));
}

// Central differences of the FESD map with respect to the lowered initial state (step 1e-6;
// the map is smooth where its element structure is fixed).
Matrix FiniteDifferenceLowered(const Scene& scene, FesdOptions options, const Vector& y0) {
  options.sensitivities = false;
  constexpr double kStep = 1e-6;
  Matrix d(y0.size(), y0.size());
  for (Eigen::Index j = 0; j < y0.size(); ++j) {
    FesdOptions plus = options, minus = options;
    plus.initial_state = y0;
    minus.initial_state = y0;
    plus.initial_state[j] += kStep;
    minus.initial_state[j] -= kStep;
    const FesdResult a = SimulateFesd(scene, plus), b = SimulateFesd(scene, minus);
    EXPECT_EQ(a.status, FesdStatus::kSuccess) << a.message;
    EXPECT_EQ(b.status, FesdStatus::kSuccess) << b.message;
    d.col(j) = (a.final_lowered_state - b.final_lowered_state) / (2 * kStep);
  }
  return d;
}

TEST(FesdShootingTest, LoweredStateSensitivitiesIncludeMemoryAndClock) {
  // A shooting interval of the time-optimal turbo car: speed of time 1.3, numerical horizon
  // [0, 2], starting inside a jump of the turbo (w = 0.4 travelling to B at v = 15) and with
  // the clock at 4.2. The node derivatives d y(T) / d y0 cover x, w and the clock.
  Scene scene = WithSpeedOfTime(MakeScene("H2"), 1.3);
  scene.final_time = 2.0;
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.1;
  options.initial_state = Vector{{37.5, 15.0, 0.4, 4.2}};  // q, v, turbo.w, clock
  options.sensitivities = true;
  const FesdResult result = SimulateFesd(scene, options);
  ASSERT_EQ(result.status, FesdStatus::kSuccess) << result.message;
  ASSERT_EQ(result.sensitivities.lowered.rows(), 4);
  ASSERT_EQ(result.sensitivities.lowered.cols(), 4 + scene.num_parameters() + 2);
  // The jump finishes first (no relay_switch event: it started before t0), then the car
  // accelerates with the turbo.
  EXPECT_NEAR(result.final_lowered_state[2], 1.0, 1e-12);
  const Matrix fd = FiniteDifferenceLowered(scene, options, options.initial_state);
  const Matrix exact = result.sensitivities.lowered.leftCols(4);
  constexpr double kAgreement = 1e-6;  // central differences of an O(10) map, step 1e-6
  EXPECT_LE((exact - fd).lpNorm<Eigen::Infinity>(),
            kAgreement * (1.0 + fd.lpNorm<Eigen::Infinity>()))
      << "exact\n"
      << exact << "\nfinite differences\n"
      << fd;
  // The memory's position within the jump moves the end of the frozen interval, hence how
  // much numerical time is left at speed 1.3: d clock(T) / d w0 = -1.3 / (a s) * ... != 0.
  EXPECT_GT(std::fabs(exact(3, 2)), 0.1);
}

TEST(FesdShootingTest, StartOnAMovingBoundaryTakesTheOutwardDerivative) {
  // The wave-rider S4 pushed by its boundary: the state at t = 1 (contact from t = 0.094 to
  // 1.449 with the scene's u = 2) lies on the boundary (a multiple-shooting node of a trajectory
  // riding the set). The map from there is not differentiable (inward starts are free for a moment,
  // outward ones are projected); FESD returns the outward one-sided derivative, the limit of the
  // derivatives of infeasible starts (docs/ocp.md).
  Scene scene = MakeScene("S4");
  scene.final_time = 1.0;
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.25;
  const FesdResult approach = SimulateFesd(scene, options);
  ASSERT_EQ(approach.status, FesdStatus::kSuccess) << approach.message;
  ASSERT_FALSE(approach.events.empty());
  ASSERT_EQ(approach.events.back().kind, EventKind::kEnter) << "must end in contact";
  const Vector y0 = approach.final_lowered_state;  // x1, x2, clock
  EXPECT_NEAR(y0[0] + std::cos(y0[1] - y0[2]), 0.0, 1e-12);

  scene.initial_time = 1.0;
  scene.final_time = 2.0;
  options.step_size = 1.0;
  options.finite_elements = 3;
  options.sensitivities = true;
  options.initial_state = y0;
  const FesdResult on_boundary = SimulateFesd(scene, options);
  ASSERT_EQ(on_boundary.status, FesdStatus::kSuccess) << on_boundary.message;
  // Outward: x1 decreases (c = x1 + cos(x2 - t) decreases with it).
  constexpr double kOffset = 1e-9;
  options.initial_state[0] -= kOffset;
  const FesdResult outside = SimulateFesd(scene, options);
  ASSERT_EQ(outside.status, FesdStatus::kSuccess) << outside.message;
  const Matrix d_boundary = on_boundary.sensitivities.lowered.leftCols(3);
  const Matrix d_outside = outside.sensitivities.lowered.leftCols(3);
  // The derivative is continuous from outside: the offset changes it by O(kOffset).
  constexpr double kContinuity = 1e-6;
  EXPECT_LE((d_boundary - d_outside).lpNorm<Eigen::Infinity>(), kContinuity)
      << "on the boundary\n"
      << d_boundary << "\nfrom outside\n"
      << d_outside;
  // And it is the backward (outward) difference quotient of the map in x1.
  options.sensitivities = false;
  options.initial_state = y0;
  FesdOptions minus = options;
  constexpr double kStep = 1e-7;
  minus.initial_state[0] -= kStep;
  const Vector quotient = (SimulateFesd(scene, options).final_lowered_state -
                           SimulateFesd(scene, minus).final_lowered_state) /
                          kStep;
  // One-sided quotient: truncation O(kStep) times the map's curvature, noise 1e-14 / kStep.
  constexpr double kQuotientTolerance = 1e-5;
  EXPECT_LE((quotient - d_boundary.col(0)).lpNorm<Eigen::Infinity>(), kQuotientTolerance)
      << quotient.transpose() << "\nvs " << d_boundary.col(0).transpose();
}

// A start just inside the boundary is free for a moment and is caught after a vanishing
// element. Counted as an element of the step, that element changes the step's discretization:
// the map jumps by the change of the discretization error. With
// keep_elements_after_early_switch the rest of the step keeps its elements and the map is
// continuous there (multiple shooting's nodes lie on active boundaries; docs/ocp.md).
TEST(FesdShootingTest, StartJustInsideAMovingBoundaryIsContinuousWithKeptElements) {
  Scene scene = MakeScene("S4");
  scene.final_time = 1.0;
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.25;
  const FesdResult approach = SimulateFesd(scene, options);
  ASSERT_EQ(approach.status, FesdStatus::kSuccess) << approach.message;
  ASSERT_EQ(approach.events.back().kind, EventKind::kEnter) << "must end in contact";
  const Vector y0 = approach.final_lowered_state;
  scene.initial_time = 1.0;
  scene.final_time = 2.0;
  options.step_size = 1.0;
  options.finite_elements = 3;
  constexpr double kInward = 1e-9;  // x1 up: c = x1 + cos(x2 - t) > 0, a free start
  auto end_state = [&](bool keep, double offset) {
    FesdOptions run = options;
    run.keep_elements_after_early_switch = keep;
    run.initial_state = y0;
    run.initial_state[0] += offset;
    const FesdResult result = SimulateFesd(scene, run);
    EXPECT_EQ(result.status, FesdStatus::kSuccess) << result.message;
    return Vector(result.final_lowered_state);
  };
  const double kept = (end_state(true, kInward) - end_state(true, 0.0)).lpNorm<Eigen::Infinity>();
  const double counted =
      (end_state(false, kInward) - end_state(false, 0.0)).lpNorm<Eigen::Infinity>();
  std::printf("end-state change for an inward start of %g: %.3e kept, %.3e counted\n", kInward,
              kept, counted);
  // Continuous: the change is the derivative (O(1)) times the offset, plus Newton noise.
  constexpr double kContinuous = 1e3 * kInward;
  EXPECT_LE(kept, kContinuous);
  // The default counts the vanishing element: a jump far above the offset.
  EXPECT_GT(counted, kContinuous);
}

TEST(FesdShootingTest, InitialLoweredStateIsValidated) {
  FesdOptions options;
  options.initial_state = Vector{{1.0, 2.0}};  // H1 needs (x, w, clock)
  try {
    SimulateFesd(MakeScene("H1"), options);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("needs 3 entries"), std::string::npos) << error.what();
  }
  options.initial_state = Vector{{15.0, std::nan(""), 0.0}};
  EXPECT_THROW(SimulateFesd(MakeScene("H1"), options), std::invalid_argument);
  // Other integrators refuse a speed of time by name.
  Scene scene = WithSpeedOfTime(MakeScene("S1"), 2.0);
  Scene bad = scene;
  bad.inputs.back().signal.values = {-1.0};
  EXPECT_THROW(SimulateFesd(bad, {}), std::invalid_argument);
}

}  // namespace
}  // namespace moreau
