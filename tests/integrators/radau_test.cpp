#include "moreau/integrators/radau.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "../problems/reference_problems.hpp"
#include "moreau/core/convergence.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Errors below this are dominated by round-off accumulated over the steps (a few hundred
// steps times eps times |x| ~ 1); the observed order is measured above it. The Newton
// increment tolerance (1e-12) is not a floor: the final quadratic step leaves an error far
// below the last increment.
constexpr double kRoundOffFloor = 1e-13;
// Observed order must be within this of the theoretical 2s - 1 (issue acceptance).
constexpr double kOrderSlack = 0.3;

struct OrderCase {
  int stages;
  std::vector<double> step_sizes;
};
void PrintTo(const OrderCase& c, std::ostream* out) { *out << "s = " << c.stages; }

std::string Scientific(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.3e", value);
  return buffer;
}

class RadauOrderTest : public ::testing::TestWithParam<OrderCase> {};

TEST_P(RadauOrderTest, FixedStepShowsOrderTwoSMinusOne) {
  const OrderCase& c = GetParam();
  const testing::ReferenceProblem hopf = testing::Hopf();
  const Scene scene = hopf.Make();
  const Vector exact = hopf.FinalState();
  std::vector<double> errors;
  std::string table;
  for (double h : c.step_sizes) {
    RadauOptions options;
    options.stages = c.stages;
    options.step_size = h;
    options.record_trajectory = false;
    const RadauResult result = SimulateRadau(scene, options);
    ASSERT_EQ(result.status, RadauStatus::kSuccess) << result.message;
    errors.push_back((result.final_state - exact).lpNorm<Eigen::Infinity>());
    table += "h = " + Scientific(h) + " error = " + Scientific(errors.back()) + "\n";
  }
  const std::vector<double> orders = PairwiseOrders(c.step_sizes, errors);
  int checked = 0;
  for (std::size_t k = 0; k < orders.size(); ++k) {
    if (errors[k + 1] <= kRoundOffFloor) continue;
    ++checked;
    EXPECT_NEAR(orders[k], 2 * c.stages - 1, kOrderSlack) << "pair " << k << "\n" << table;
  }
  EXPECT_GE(checked, 2) << "too few points above the round-off floor\n" << table;
}

INSTANTIATE_TEST_SUITE_P(Stages, RadauOrderTest,
                         ::testing::Values(OrderCase{1, {0.01, 0.005, 0.0025, 0.00125}},
                                           OrderCase{2, {0.04, 0.02, 0.01, 0.005}},
                                           OrderCase{3, {0.1, 0.05, 0.025, 0.0125}},
                                           OrderCase{4, {0.1, 0.05, 0.025, 0.0125}}),
                         [](const auto& test_info) {
                           return "s" + std::to_string(test_info.param.stages);
                         });

TEST(RadauTest, AdaptiveMeetsToleranceOnRobertson) {
  const Scene scene = MakeScene("robertson");
  RadauOptions reference_options;
  reference_options.stages = 5;
  reference_options.adaptive = true;
  reference_options.step_size = 0.0;
  reference_options.relative_tolerance = 1e-13;
  reference_options.absolute_tolerance = 1e-18;
  const RadauResult reference = SimulateRadau(scene, reference_options);
  ASSERT_EQ(reference.status, RadauStatus::kSuccess) << reference.message;
  // Mass conservation y1 + y2 + y3 = 1 is a linear invariant that Radau IIA preserves.
  EXPECT_NEAR(reference.final_state.sum(), 1.0, 1e-13);

  for (int stages : {3, 5}) {
    RadauOptions options;
    options.stages = stages;
    options.adaptive = true;
    options.step_size = 0.0;
    options.relative_tolerance = 1e-6;
    options.absolute_tolerance = 1e-12;
    const RadauResult result = SimulateRadau(scene, options);
    ASSERT_EQ(result.status, RadauStatus::kSuccess) << result.message;
    // Global error within the requested tolerance, per component, up to a factor that
    // accounts for accumulation over the steps (local tolerances bound local errors).
    constexpr double kAccumulation = 10.0;
    for (int i = 0; i < 3; ++i) {
      const double tolerance = options.absolute_tolerance +
                               options.relative_tolerance * std::fabs(reference.final_state[i]);
      EXPECT_LE(std::fabs(result.final_state[i] - reference.final_state[i]),
                kAccumulation * tolerance)
          << "s = " << stages << ", component " << i << ", " << result.stats.Summary();
    }
    EXPECT_LT(result.stats.num_steps, 2000) << "step-size control should take large steps";
  }
}

TEST(RadauTest, DenseAndSparsePathsAgreeOnHeatEquation) {
  Scene scene = MakeScene("heat");
  ASSERT_GE(scene.num_states(), 2000);
  SetSceneValue(&scene, "tf", 2e-3);
  RadauOptions options;
  options.stages = 1;
  options.step_size = 1e-3;
  Vector states[2];
  int index = 0;
  for (LinearSolverKind kind : {LinearSolverKind::kDenseLu, LinearSolverKind::kSparseLu}) {
    options.linear_solver = kind;
    const RadauResult result = SimulateRadau(scene, options);
    ASSERT_EQ(result.status, RadauStatus::kSuccess) << result.message;
    states[index++] = result.final_state;
  }
  // Both paths solve the same linear Newton systems; the results differ by round-off only
  // (pivot orders differ): a few hundred ulps of O(1) values.
  EXPECT_LE((states[0] - states[1]).lpNorm<Eigen::Infinity>(), 1e-13);
}

TEST(RadauTest, HeatEquationMatchesTheExactSemiDiscreteSolution) {
  const Scene scene = MakeScene("heat");
  RadauOptions options;
  options.stages = 3;
  options.step_size = 5e-4;
  options.linear_solver = LinearSolverKind::kSparseLu;
  const RadauResult result = SimulateRadau(scene, options);
  ASSERT_EQ(result.status, RadauStatus::kSuccess) << result.message;
  const int n = scene.num_states();
  const double dx = 1.0 / (n + 1);
  const double lambda = -4.0 / (dx * dx) * std::pow(std::sin(std::numbers::pi * dx / 2), 2);
  const Vector exact = std::exp(lambda * scene.final_time) * scene.initial_state;
  // Fifth order with h |lambda| ~ 5e-3: the error is far below 1e-10 of O(1) values.
  EXPECT_LE((result.final_state - exact).lpNorm<Eigen::Infinity>(), 1e-10);
}

TEST(RadauTest, InvalidOptionsAndEffectsAreRefused) {
  const Scene scene = MakeScene("hopf");
  RadauOptions options;
  options.step_size = -0.1;
  EXPECT_THROW(SimulateRadau(scene, options), std::invalid_argument);
  options.step_size = 0.1;
  options.stages = 9;
  EXPECT_THROW(SimulateRadau(scene, options), std::invalid_argument);
}

TEST(RadauTest, ControlBreakpointsAreRespected) {
  // x' = u with u = 1 on [0, 0.3), -2 afterwards: exact x(1) = 0.3 - 1.4 = -1.1; a step
  // across the breakpoint would smear the jump.
  Scene scene;
  scene.name = "ramp";
  scene.state_names = {"x"};
  scene.initial_state = Vector{{0.0}};
  scene.final_time = 1.0;
  InputSpec u;
  u.name = "u";
  u.signal = {{0.3}, {1.0, -2.0}};
  scene.inputs.push_back(u);
  scene.dynamics = MakeSmoothFunction(
      "ramp.f", 1,
      [](const auto&, const auto& in, const auto&, const auto&, auto& out) { out[0] = in[0]; });
  RadauOptions options;
  options.stages = 2;
  options.step_size = 0.25;
  const RadauResult result = SimulateRadau(scene, options);
  ASSERT_EQ(result.status, RadauStatus::kSuccess);
  EXPECT_NEAR(result.final_state[0], -1.1, 1e-14);
}

}  // namespace
}  // namespace moreau
