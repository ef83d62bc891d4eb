#include "moreau/integrators/fesd.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "../problems/reference_problems.hpp"
#include "moreau/core/convergence.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/integrators/timestepping.hpp"

namespace moreau {
namespace {

using testing::ReferenceProblem;

// Acceptance: cross complementarity at most 1e-10 on every element of every run.
constexpr double kCrossComplementarity = 1e-10;
// Errors below this are round-off (hundreds of elements, Newton tolerance 1e-12 with one
// forced correction): the observed order is measured above it.
constexpr double kRoundOffFloor = 1e-12;

// Checks the certificates of every element, and that every element shorter than the
// documented minimum (FesdOptions::min_element_fraction of a nominal element) either ends on a
// switch or follows one (the piece between a switch and a step that may not be merged).
void ExpectCertificates(const FesdResult& result, const FesdOptions& options,
                        const std::string& label) {
  ASSERT_EQ(result.status, FesdStatus::kSuccess) << label << ": " << result.message;
  const double minimum = options.min_element_fraction * options.step_size / options.finite_elements;
  for (std::size_t e = 0; e < result.elements.size(); ++e) {
    const FesdElement& element = result.elements[e];
    EXPECT_LE(element.cross_complementarity, kCrossComplementarity)
        << label << ": element " << e << " at t = " << element.t_start;
    EXPECT_LE(element.complementarity, kCrossComplementarity) << label << ": element " << e;
    const bool switch_needs_it =
        element.ends_at_switch || (e > 0 && result.elements[e - 1].ends_at_switch);
    if (!switch_needs_it) {
      EXPECT_GE(element.length, minimum)
          << label << ": element " << e << " at t = " << element.t_start;
    }
  }
}

// Distance from each exact switch time to the closest reported event.
double SwitchTimeError(const ReferenceProblem& problem, const std::vector<Event>& events) {
  double worst = 0.0;
  for (double t : problem.switch_times) {
    double closest = std::numeric_limits<double>::infinity();
    for (const Event& event : events) closest = std::min(closest, std::fabs(event.t - t));
    worst = std::max(worst, closest);
  }
  return worst;
}

std::string Table(const std::vector<double>& h, const std::vector<double>& e) {
  std::string table;
  char line[96];
  for (std::size_t k = 0; k < h.size(); ++k) {
    std::snprintf(line, sizeof line, "h = %.4e  error = %.4e\n", h[k], e[k]);
    table += line;
  }
  return table;
}

struct F1Case {
  int stages;
  int first_steps;  // h = 1 / (m + 1/4), m = first_steps * 2^k: the switch at a fixed fraction
  int grids;
};
void PrintTo(const F1Case& c, std::ostream* out) { *out << "s = " << c.stages; }

class FesdF1OrderTest : public ::testing::TestWithParam<F1Case> {};

// Acceptance: on F1 the error at T shows order 2s - 1 (within 0.3) for s = 1..4 until the
// 1e-12 floor, the switch at t = 1 is located to 1e-10, and on the same grid the standard
// time-stepping shows order about 1. The step sizes put the switch at the same fraction of a
// step on every grid, so that the element configuration around the switch does not change
// with h (it changes the error constant, not the order).
TEST_P(FesdF1OrderTest, OrderTwoSMinusOneBesideTimeSteppingOrderOne) {
  const F1Case& c = GetParam();
  const ReferenceProblem problem = testing::F1();
  const Scene scene = problem.Make();
  std::vector<double> steps, errors, switch_errors, ts_errors;
  for (int k = 0; k < c.grids; ++k) {
    FesdOptions options;
    options.stages = c.stages;
    options.step_size = 1.0 / (c.first_steps * (1 << k) + 0.25);
    options.record_trajectory = false;
    const FesdResult result = SimulateFesd(scene, options);
    ExpectCertificates(result, options, "F1 s = " + std::to_string(c.stages));
    steps.push_back(options.step_size);
    errors.push_back((result.final_state - problem.FinalState()).lpNorm<Eigen::Infinity>());
    switch_errors.push_back(SwitchTimeError(problem, result.events));
    TimeSteppingOptions baseline;
    baseline.stages = c.stages;
    baseline.step_size = options.step_size;
    baseline.record_trajectory = false;
    const TimeSteppingResult stepped = SimulateTimeStepping(scene, baseline);
    ASSERT_EQ(stepped.status, TimeSteppingStatus::kSuccess) << stepped.message;
    ts_errors.push_back((stepped.final_state - problem.FinalState()).lpNorm<Eigen::Infinity>());
  }
  const std::vector<double> orders = PairwiseOrders(steps, errors);
  int checked = 0;
  for (std::size_t k = 0; k < orders.size(); ++k) {
    if (errors[k + 1] <= kRoundOffFloor) continue;
    ++checked;
    EXPECT_NEAR(orders[k], 2 * c.stages - 1, 0.3) << "FESD\n" << Table(steps, errors);
  }
  EXPECT_GE(checked, 2) << Table(steps, errors);
  if (c.stages >= 3) {
    EXPECT_LE(switch_errors.back(), 1e-10) << "switch time\n" << Table(steps, switch_errors);
  }
  // Time-stepping on the same grids: order about 1 in the asymptotic range (last 3 grids).
  const std::vector<double> tail_h(steps.end() - 3, steps.end());
  const std::vector<double> tail_e(ts_errors.end() - 3, ts_errors.end());
  const OrderFit fit = FitOrder(tail_h, tail_e, 0.0);
  EXPECT_GE(fit.order, 0.8) << "time-stepping\n" << Table(steps, ts_errors);
  EXPECT_LE(fit.order, 1.3) << "time-stepping\n" << Table(steps, ts_errors);
  if (c.stages >= 2) {
    EXPECT_LT(errors.back(), 1e-3 * ts_errors.back()) << "FESD should be far more accurate";
  }
}

INSTANTIATE_TEST_SUITE_P(Stages, FesdF1OrderTest,
                         ::testing::Values(F1Case{1, 128, 5}, F1Case{2, 8, 5}, F1Case{3, 16, 5},
                                           F1Case{4, 8, 5}),
                         [](const auto& test_info) {
                           return "s" + std::to_string(test_info.param.stages);
                         });

TEST(FesdTest, S1SwitchAndFinalStateExact) {
  const ReferenceProblem problem = testing::S1();
  FesdOptions options;
  options.stages = 2;
  options.step_size = 0.1;
  const FesdResult result = SimulateFesd(problem.Make(), options);
  ExpectCertificates(result, options, "S1");
  ASSERT_EQ(result.events.size(), 1u);
  EXPECT_EQ(result.events[0].kind, EventKind::kEnter);
  EXPECT_NEAR(result.events[0].t, 1.0, 1e-12);
  EXPECT_NEAR(result.final_state[0], problem.FinalState()[0], 1e-12);
}

TEST(FesdTest, S2PlayOperatorSwitchTimesAndFinalState) {
  const ReferenceProblem problem = testing::S2();
  FesdOptions options;
  options.stages = 2;
  options.step_size = 0.1;
  const FesdResult result = SimulateFesd(problem.Make(), options);
  ExpectCertificates(result, options, "S2");
  // Every switch up to T = 4 pi (the last one, the lower bound arriving, exactly at T).
  ASSERT_EQ(result.events.size(), problem.switch_times.size());
  for (std::size_t k = 0; k < problem.switch_times.size(); ++k) {
    EXPECT_NEAR(result.events[k].t, problem.switch_times[k], 1e-9) << "switch " << k;
    EXPECT_EQ(result.events[k].kind, k % 2 == 0 ? EventKind::kEnter : EventKind::kLeave)
        << "switch " << k;
  }
  EXPECT_LE((result.final_state - problem.FinalState()).lpNorm<Eigen::Infinity>(), 1e-8);
}

TEST(FesdTest, S3ContactLeavingAndFinalState) {
  const ReferenceProblem problem = testing::S3();
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.05;
  const FesdResult result = SimulateFesd(problem.Make(), options);
  ExpectCertificates(result, options, "S3");
  ASSERT_EQ(result.events.size(), 2u);
  EXPECT_EQ(result.events[0].kind, EventKind::kEnter);
  EXPECT_EQ(result.events[1].kind, EventKind::kLeave);
  EXPECT_NEAR(result.events[0].t, problem.switch_times[0], 1e-9);
  EXPECT_NEAR(result.events[1].t, problem.switch_times[1], 1e-9);
  EXPECT_LE((result.final_state - problem.FinalState()).lpNorm<Eigen::Infinity>(), 1e-9);
  // The state never leaves C = {x2 >= -1} (to the Newton tolerance).
  for (const Vector& x : result.trajectory.x) EXPECT_GE(x[1] + 1.0, -1e-12);
}

// S4 with its fixed control: contact, sliding along the moving boundary, leaving, against the
// derived closed form (tests/problems/reference_problems.hpp).
TEST(FesdTest, S4ContactAndLeavingMatchClosedForm) {
  const ReferenceProblem problem = testing::S4();
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.05;
  const FesdResult result = SimulateFesd(problem.Make(), options);
  ExpectCertificates(result, options, "S4");
  ASSERT_EQ(result.events.size(), 2u);
  EXPECT_EQ(result.events[0].kind, EventKind::kEnter);
  EXPECT_EQ(result.events[1].kind, EventKind::kLeave);
  // Measured: switch times to 9e-16 and 4e-12, states to 1e-11; the tolerance of S3 above.
  EXPECT_NEAR(result.events[0].t, problem.switch_times[0], 1e-9);
  EXPECT_NEAR(result.events[1].t, problem.switch_times[1], 1e-9);
  EXPECT_LE((result.final_state - problem.FinalState()).lpNorm<Eigen::Infinity>(), 1e-9);
  // On the boundary between the switches, x1 = -cos(x2 - t) (the closed form's phase).
  for (std::size_t k = 0; k < result.trajectory.size(); ++k) {
    const double t = result.trajectory.t[k];
    if (t <= problem.switch_times[0] || t >= problem.switch_times[1]) continue;
    EXPECT_LE((result.trajectory.x[k] - problem.solution(t)).lpNorm<Eigen::Infinity>(), 1e-9)
        << "t = " << t;
  }
}

struct SwitchingCase {
  ReferenceProblem problem;
  SwitchingForm form;
};
void PrintTo(const SwitchingCase& c, std::ostream* out) {
  *out << c.problem.scene << " " << ToString(c.form);
}

class FesdSwitchingTest : public ::testing::TestWithParam<SwitchingCase> {};

// Acceptance: F2 (a)-(c) and F3: switch and sliding times within 1e-10.
TEST_P(FesdSwitchingTest, SwitchAndSlidingTimes) {
  const SwitchingCase& c = GetParam();
  for (int stages : {1, 2, 3}) {
    FesdOptions options;
    options.stages = stages;
    options.step_size = 0.1;
    options.switching_form = c.form;
    const FesdResult result = SimulateFesd(c.problem.Make(), options);
    const std::string label = c.problem.scene + " s = " + std::to_string(stages);
    ExpectCertificates(result, options, label);
    ASSERT_EQ(result.events.size(), c.problem.switch_times.size()) << label;
    EXPECT_LE(SwitchTimeError(c.problem, result.events), 1e-10) << label;
    // The smooth phases are polynomials of degree <= 2 (exact for s >= 2); implicit Euler
    // (s = 1) is exact only for the piecewise-linear ones.
    if (stages >= 2 || c.problem.scene != "F2c") {
      EXPECT_LE((result.final_state - c.problem.FinalState()).lpNorm<Eigen::Infinity>(), 1e-10)
          << label;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(ReferenceProblems, FesdSwitchingTest,
                         ::testing::Values(SwitchingCase{testing::F2a(), SwitchingForm::kStewart},
                                           SwitchingCase{testing::F2b(), SwitchingForm::kStewart},
                                           SwitchingCase{testing::F2c(), SwitchingForm::kStewart},
                                           SwitchingCase{testing::F3(), SwitchingForm::kStewart},
                                           SwitchingCase{testing::F4(), SwitchingForm::kStewart},
                                           SwitchingCase{testing::F2a(), SwitchingForm::kHeaviside},
                                           SwitchingCase{testing::F2b(), SwitchingForm::kHeaviside},
                                           SwitchingCase{testing::F2c(), SwitchingForm::kHeaviside},
                                           SwitchingCase{testing::F3(), SwitchingForm::kHeaviside},
                                           SwitchingCase{testing::F4(), SwitchingForm::kHeaviside}),
                         [](const auto& test_info) {
                           return test_info.param.problem.scene + "_" +
                                  ToString(test_info.param.form);
                         });

// Acceptance: F2 (d) has a documented outcome, never a failure: the surface is repulsive, the
// continuation is not unique, and the slow solution (x' = 0, staying on the surface) is taken
// and reported as an ambiguous event.
TEST(FesdTest, F2dSpontaneousSwitchHasDocumentedOutcome) {
  for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
    FesdOptions options;
    options.switching_form = form;
    const FesdResult result = SimulateFesd(MakeScene("F2d"), options);
    ExpectCertificates(result, options, "F2d");
    ASSERT_EQ(result.events.size(), 1u);
    EXPECT_EQ(result.events[0].kind, EventKind::kAmbiguous);
    EXPECT_EQ(result.events[0].t, 0.0);
    EXPECT_NE(result.events[0].detail.find("slow"), std::string::npos) << result.events[0].detail;
    EXPECT_EQ(result.final_state[0], 0.0);
  }
}

// Sensitivities of the whole simulation against central differences (relative 1e-6). The step
// sizes keep the switches away from step boundaries: where a switch crosses one, the element
// structure changes and the discrete map jumps by about the discretization error, so finite
// differences there measure that jump, not a derivative.
void ExpectSensitivities(const std::string& scene_name, int stages, double h) {
  const Scene scene = MakeScene(scene_name);
  FesdOptions options;
  options.stages = stages;
  options.step_size = h;
  options.sensitivities = true;
  const FesdResult result = SimulateFesd(scene, options);
  ExpectCertificates(result, options, scene_name);
  ASSERT_FALSE(result.events.empty()) << "the test needs a switch";
  FesdOptions plain = options;
  plain.sensitivities = false;
  constexpr double kStep = 1e-6;      // central differences: O(kStep^2) truncation
  constexpr double kRelative = 1e-6;  // acceptance
  auto check = [&](const Vector& derivative, Scene plus, Scene minus, const std::string& what) {
    const Vector fd =
        (SimulateFesd(plus, plain).final_state - SimulateFesd(minus, plain).final_state) /
        (2 * kStep);
    for (Eigen::Index i = 0; i < fd.size(); ++i) {
      EXPECT_NEAR(derivative[i], fd[i], kRelative * std::max(1.0, std::fabs(fd[i])))
          << scene_name << " " << what << " component " << i;
    }
  };
  for (int j = 0; j < scene.num_states(); ++j) {
    Scene plus = scene, minus = scene;
    plus.initial_state[j] += kStep;
    minus.initial_state[j] -= kStep;
    check(result.sensitivities.initial_state.col(j), plus, minus, "dx/dx0_" + std::to_string(j));
  }
  for (int j = 0; j < scene.num_parameters(); ++j) {
    Scene plus = scene, minus = scene;
    plus.parameters[static_cast<std::size_t>(j)].value += kStep;
    minus.parameters[static_cast<std::size_t>(j)].value -= kStep;
    check(result.sensitivities.parameters.col(j), plus, minus,
          "dx/d" + scene.parameters[static_cast<std::size_t>(j)].name);
  }
}

TEST(FesdSensitivityTest, AgreeWithFiniteDifferencesAcrossSwitchesF1) {
  ExpectSensitivities("F1", 3, 0.049);
}

TEST(FesdSensitivityTest, AgreeWithFiniteDifferencesAcrossSwitchesS3) {
  ExpectSensitivities("S3", 3, 0.05);
}

TEST(FesdSensitivityTest, InputSensitivitiesOfTheWaveRider) {
  // dx(T)/du for the constant control of S4 (one segment), against central differences.
  const Scene scene = MakeScene("S4");
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.05;
  options.sensitivities = true;
  const FesdResult result = SimulateFesd(scene, options);
  ExpectCertificates(result, options, "S4");
  ASSERT_EQ(result.sensitivities.inputs.cols(), 1);
  constexpr double kStep = 1e-6;
  Scene plus = scene, minus = scene;
  plus.inputs[0].signal.values[0] += kStep;
  minus.inputs[0].signal.values[0] -= kStep;
  FesdOptions plain = options;
  plain.sensitivities = false;
  const Vector fd =
      (SimulateFesd(plus, plain).final_state - SimulateFesd(minus, plain).final_state) /
      (2 * kStep);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(result.sensitivities.inputs(i, 0), fd[i], 1e-6 * std::max(1.0, std::fabs(fd[i])));
  }
}

// Acceptance: the standard time-stepping's derivative is wrong across a switch. Its discrete
// map is smooth between grid-crossing events of the switch, so its derivative is measured by
// central differences with a step small enough to stay on one piece; it misses the dependence
// of the switch time on x(0) and differs from the exact derivative (which FESD converges to).
TEST(FesdSensitivityTest, TimeSteppingDerivativeIsWrongAcrossTheSwitch) {
  const Scene scene = MakeScene("F1");
  FesdOptions options;
  options.stages = 3;
  options.step_size = 0.049;
  options.sensitivities = true;
  const double exact = SimulateFesd(scene, options).sensitivities.initial_state(0, 0);
  // FESD at two resolutions agrees (converged derivative).
  options.step_size = 0.0245;
  EXPECT_NEAR(SimulateFesd(scene, options).sensitivities.initial_state(0, 0), exact,
              1e-4 * std::fabs(exact));
  TimeSteppingOptions baseline;
  baseline.stages = 3;
  baseline.step_size = 0.0245;
  constexpr double kStep = 1e-9;
  Scene plus = scene, minus = scene;
  plus.initial_state[0] += kStep;
  minus.initial_state[0] -= kStep;
  const double stepped = (SimulateTimeStepping(plus, baseline).final_state[0] -
                          SimulateTimeStepping(minus, baseline).final_state[0]) /
                         (2 * kStep);
  EXPECT_GT(std::fabs(stepped - exact), 0.1 * std::fabs(exact))
      << "time-stepping derivative " << stepped << ", exact " << exact;
}

// A switch exactly on a step boundary is found at the step end, not by an event equation; the
// saltation matrix must still carry the dependence of its time on the data. F2a (x' = below
// for x < 0, above for x > 0, both plus slope * t; x0 = -1) switches at t_s = 0.5 = 5 h, and
// Radau IIA is exact for its polynomial pieces, so the derivatives are exact:
// x(T) = int_{t_s}^T (above + slope t) dt with t_s = -x0/below at slope = 0.
TEST(FesdSensitivityTest, SwitchOnAStepBoundaryUsesTheSaltationMatrix) {
  const Scene scene = MakeScene("F2a");
  FesdOptions options;
  options.stages = 2;
  options.step_size = 0.1;
  options.sensitivities = true;
  const FesdResult result = SimulateFesd(scene, options);
  ASSERT_EQ(result.status, FesdStatus::kSuccess) << result.message;
  ASSERT_EQ(result.events.size(), 1u);
  ASSERT_EQ(result.events[0].t, 0.5);  // on the boundary of the fifth step
  const double below = 2.0, above = 0.2, x0 = -1.0, tf = 1.5, ts = 0.5;
  constexpr double kExact = 1e-12;  // polynomial pieces: round-off only
  EXPECT_NEAR(result.sensitivities.initial_state(0, 0), above / below, kExact);
  // Parameters (below, above, slope).
  EXPECT_NEAR(result.sensitivities.parameters(0, 0), -above * x0 / (below * below), kExact);
  EXPECT_NEAR(result.sensitivities.parameters(0, 1), tf - ts, kExact);
  EXPECT_NEAR(result.sensitivities.parameters(0, 2),
              (tf * tf - ts * ts) / 2 + above * ts * ts / (2 * below), kExact);
}

TEST(FesdTest, WithoutEffectsFesdIsRadauIIA) {
  // No pairs: every element is a Radau IIA step; N_fe = 1 reproduces the smooth integrator.
  const Scene scene = MakeScene("hopf");
  FesdOptions fesd;
  fesd.stages = 3;
  fesd.step_size = 0.02;
  fesd.finite_elements = 1;
  RadauOptions radau;
  radau.stages = 3;
  radau.step_size = 0.02;
  const FesdResult a = SimulateFesd(scene, fesd);
  const RadauResult b = SimulateRadau(scene, radau);
  ASSERT_EQ(a.status, FesdStatus::kSuccess);
  // Same discretization; the Newton stopping rules differ (scaled residual 1e-12 with one
  // forced correction, against increments 1e-12), which over 100 steps leaves ~1e-11.
  EXPECT_LE((a.final_state - b.final_state).lpNorm<Eigen::Infinity>(), 1e-10);
  EXPECT_EQ(a.stats.num_elements, b.stats.num_steps);
}

// Smooth elements (FesdOptions::reduce_smooth_elements) are Radau IIA steps of the field the
// statuses leave (one Stewart mode; no active constraint), checked on the full element system: the
// run is the full solve's run up to the Newton tolerance (1e-12 on the scaled residual, where the
// full solve stops too) and round-off. Observed: <= 1e-15 on states and switch times; a tenth of
// the tolerance holds with margin and would catch any element that solved another system.
constexpr double kReducedAgreement = 1e-13;

// Runs `scene` with smooth elements off and on (the other options from `options`) and checks
// what every comparison of the two requires: certificates of both runs, reduced elements in
// the second only, the same events (kinds, times within kReducedAgreement) and elements.
std::pair<FesdResult, FesdResult> RunFullAndReduced(const Scene& scene, FesdOptions options,
                                                    const std::string& label) {
  FesdOptions full = options;
  full.reduce_smooth_elements = false;
  FesdOptions reduced = options;
  reduced.reduce_smooth_elements = true;
  FesdResult a = SimulateFesd(scene, full);
  FesdResult b = SimulateFesd(scene, reduced);
  ExpectCertificates(a, full, label + " (full)");
  ExpectCertificates(b, reduced, label + " (reduced)");
  EXPECT_EQ(a.stats.num_reduced_elements, 0) << label;
  EXPECT_GT(b.stats.num_reduced_elements, 0) << label;
  EXPECT_EQ(a.events.size(), b.events.size()) << label;
  for (std::size_t k = 0; k < std::min(a.events.size(), b.events.size()); ++k) {
    EXPECT_EQ(a.events[k].kind, b.events[k].kind) << label << " event " << k;
    EXPECT_NEAR(a.events[k].t, b.events[k].t, kReducedAgreement) << label << " event " << k;
  }
  EXPECT_EQ(a.elements.size(), b.elements.size()) << label;
  return {std::move(a), std::move(b)};
}

TEST(FesdTest, SmoothElementsAgreeWithTheFullSolve) {
  // F1 crosses the circle; F2b enters a sliding mode (two active modes: not reduced) and F2c
  // leaves one; F3 slides to the origin. S1-S4: moving sets, free before the first contact
  // and after leaving, not reduced while in contact.
  for (const char* name : {"F1", "F2a", "F2b", "F2c", "F3", "S1", "S2", "S3", "S4"}) {
    for (int stages : {1, 2, 3}) {
      FesdOptions options;
      options.stages = stages;
      options.step_size = 0.1;
      const std::string label = std::string(name) + " s = " + std::to_string(stages);
      // Every element before the first switch is in one mode, or free, and reduces.
      const auto [a, b] = RunFullAndReduced(MakeScene(name), options, label);
      ASSERT_EQ(a.trajectory.size(), b.trajectory.size()) << label;
      for (std::size_t k = 0; k < a.trajectory.size(); ++k) {
        EXPECT_LE((a.trajectory.x[k] - b.trajectory.x[k]).lpNorm<Eigen::Infinity>(),
                  kReducedAgreement)
            << label << " t = " << a.trajectory.t[k];
      }
      EXPECT_LE((a.final_state - b.final_state).lpNorm<Eigen::Infinity>(), kReducedAgreement)
          << label;
    }
  }
}

// Hysteresis relays (time-freezing): an element in which every relay is in one region or slides
// on a memory boundary is a Radau IIA step of the lowered field with theta held at its constant
// values (1, or 1/2 on the two sides of the boundary). H1: one relay; H3: two, each freezing the
// other while it jumps. Groups that end on a switch are reduced too (the element length is the
// root of the switching indicator, driven to round-off). Both runs with the Newton tolerance
// 1e-14: at the default 1e-12 the full group solve stops at a residual of 2.6e-13 (H1, s = 2),
// which moves the first switch by 4.5e-13. Same agreement as above relative to 1 + |y| (the
// Newton tolerance is relative to it; the temperatures reach 20, where round-off alone gives
// 1.2e-13).
TEST(FesdTest, SmoothElementsOfRelaysAgreeWithTheFullSolve) {
  constexpr double kConvergedTolerance = 1e-14;
  for (const char* name : {"H1", "H3"}) {
    for (int stages : {1, 2, 3}) {
      FesdOptions options;
      options.stages = stages;
      options.step_size = 0.1;
      options.newton.tolerance = kConvergedTolerance;
      const std::string label = std::string(name) + " s = " + std::to_string(stages);
      const auto [a, b] = RunFullAndReduced(MakeScene(name), options, label);
      ASSERT_EQ(a.numerical_trajectory.size(), b.numerical_trajectory.size()) << label;
      double size = 0.0;
      for (const Vector& y : a.numerical_trajectory.x) {
        size = std::max(size, y.lpNorm<Eigen::Infinity>());
      }
      const double agreement = kReducedAgreement * (1.0 + size);
      for (std::size_t k = 0; k < a.numerical_trajectory.size(); ++k) {
        EXPECT_LE(
            (a.numerical_trajectory.x[k] - b.numerical_trajectory.x[k]).lpNorm<Eigen::Infinity>(),
            agreement)
            << label << " tau = " << a.numerical_trajectory.t[k];
      }
      EXPECT_LE((a.final_state - b.final_state).lpNorm<Eigen::Infinity>(), agreement) << label;
    }
  }
}

// With sensitivities, a smooth element's transfer comes from the factorization at the reduced
// solution: the same derivatives as the full solve's.
TEST(FesdSensitivityTest, SmoothElementsGiveTheFullSolvesDerivatives) {
  const Scene scene = MakeScene("F1");
  FesdOptions full;
  full.stages = 2;
  full.step_size = 0.1;
  full.sensitivities = true;
  full.reduce_smooth_elements = false;
  FesdOptions reduced = full;
  reduced.reduce_smooth_elements = true;
  const FesdResult a = SimulateFesd(scene, full);
  const FesdResult b = SimulateFesd(scene, reduced);
  ASSERT_EQ(a.status, FesdStatus::kSuccess) << a.message;
  ASSERT_EQ(b.status, FesdStatus::kSuccess) << b.message;
  EXPECT_GT(b.stats.num_reduced_elements, 0);
  // Derivatives up to ~57 (dx/domega over the run): 1e-13 relative to that (observed 6e-14).
  const double scale = std::max(1.0, a.sensitivities.lowered.lpNorm<Eigen::Infinity>());
  EXPECT_LE((a.sensitivities.lowered - b.sensitivities.lowered).lpNorm<Eigen::Infinity>(),
            kReducedAgreement * scale);
}

TEST(FesdTest, RefusesUnsupportedEffectsAndBadOptions) {
  Scene scene = testing::S1().Make();
  PathConstraints dai;
  dai.name = "limits";
  scene.effects.push_back(dai);
  try {
    SimulateFesd(scene, {});
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("path constraints 'limits'"), std::string::npos)
        << error.what();
  }
  FesdOptions options;
  options.finite_elements = 0;
  EXPECT_THROW(SimulateFesd(testing::S1().Make(), options), std::invalid_argument);
  options = {};
  options.min_element_fraction = 0.9;
  EXPECT_THROW(SimulateFesd(testing::S1().Make(), options), std::invalid_argument);
}

}  // namespace
}  // namespace moreau
