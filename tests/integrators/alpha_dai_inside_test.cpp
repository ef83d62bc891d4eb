// Path constraints between the ends of the alpha stepper's steps (docs/alpha-method.md,
// "Constraints between step ends"): a thin bump in a floor that a long smooth step jumps over
// (before the search, the default run reported success with y = 0, phi = 0.1 at the bump),
// fixed steps over it (a warning), D2's obs1 (seen at its closed-form contact), and no false
// alarms on the other DAI scenes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "moreau/integrators/alpha_dai.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// The bump: y >= H exp(-((x - c)/w)^2) - H/2 with x' = 1, y' = u (u algebraic, user input 0),
// x(0) = y(0) = 0, tf = 2. The floor reaches above y = 0 only for |x - c| < w sqrt(ln 2)
// (0.083 wide); the default run's smooth steps grow fivefold to 1.25 and one spans it.
constexpr double kHeight = 0.2, kCentre = 0.6, kWidth = 0.05, kHorizon = 2.0;

Scene BumpScene() {
  Scene scene;
  scene.name = "bump";
  scene.state_names = {"x", "y"};
  scene.initial_state = Vector::Zero(2);
  scene.final_time = kHorizon;
  InputSpec input;
  input.name = "u";
  input.kind = InputSpec::Kind::kAlgebraic;
  scene.inputs.push_back(input);
  scene.dynamics = MakeSmoothFunction(
      "bump.f", 2, [](const auto&, const auto& u, const auto&, const auto&, auto& out) {
        out[0] = 1.0;
        out[1] = u[0];
      });
  PathConstraints bump;
  bump.name = "bump";
  bump.constraint_names = {"floor"};
  bump.constraints = MakeSmoothFunction(
      "bump.phi", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        using std::exp;
        const auto z = (x[0] - kCentre) / kWidth;
        out[0] = kHeight * exp(-(z * z)) - 0.5 * kHeight - x[1];
      });
  scene.effects.push_back(bump);
  return scene;
}

// Samples per recorded step of the fine check.
constexpr int kFineSamples = 64;

// The largest phi_k over the recorded steps of `result` in which row k is inactive at both
// ends (what the search covers; an active row is held at zero at the step ends, and between
// them its algebraic inputs are first-order values, so its extension is not the solution's
// shape), sampled kFineSamples times per step on the cubic Hermite interpolant of x (slopes f
// from the scene's dynamics at the recorded points) and the linear one of the algebraic inputs
// (all inputs of these scenes are algebraic).
double FinePhiMaximum(const Scene& scene, const AlphaDaiResult& result, int k) {
  const Trajectory& tr = result.trajectory;
  EXPECT_EQ(result.steps.size() + 1, tr.size());
  auto active_at = [&](std::size_t n) {  // row k in the working set at trajectory point n
    if (n == 0) return false;
    const std::vector<int>& active = result.steps[n - 1].active;
    return std::find(active.begin(), active.end(), k) != active.end();
  };
  const SmoothFunction& phi = std::get<PathConstraints>(scene.effects.front()).constraints;
  const Vector p = scene.ParameterValues();
  double worst = -std::numeric_limits<double>::infinity();
  Vector f0, f1, value;
  for (std::size_t n = 0; n + 1 < tr.size(); ++n) {
    if (active_at(n) || active_at(n + 1)) continue;
    const double h = tr.t[n + 1] - tr.t[n];
    scene.dynamics.Evaluate(tr.x[n], tr.algebraic[n], tr.t[n], p, &f0);
    scene.dynamics.Evaluate(tr.x[n + 1], tr.algebraic[n + 1], tr.t[n + 1], p, &f1);
    for (int m = 0; m <= kFineSamples; ++m) {
      const double s = static_cast<double>(m) / kFineSamples;
      const double h00 = (1.0 + 2.0 * s) * (1.0 - s) * (1.0 - s), h10 = s * (1.0 - s) * (1.0 - s);
      const double h01 = s * s * (3.0 - 2.0 * s), h11 = s * s * (s - 1.0);
      const Vector x = h00 * tr.x[n] + h * h10 * f0 + h01 * tr.x[n + 1] + h * h11 * f1;
      const Vector u = (1.0 - s) * tr.algebraic[n] + s * tr.algebraic[n + 1];
      phi.Evaluate(x, u, tr.t[n] + s * h, p, &value);
      worst = std::max(worst, value[k]);
    }
  }
  return worst;
}

// What the fine check allows: the constraint tolerance plus what the default tolerances
// resolve in phi, |dphi/dx| rtol |x| (the search's threshold): for the bump |dphi/dx| <= H
// sqrt(2/e) / w = 3.4 and |x| <= 2, so 7e-6, rounded up. The violation stepped over before the
// search was 0.1.
constexpr double kBumpFineCheck = 1e-5;
// y(T) = H/2: the floor's peak, which y keeps after the bump (u = w = 0 once the floor falls
// away); the index-2 arc's error at rtol 1e-6 (the run's estimate ~1e-12 per unit step is
// below it by far).
constexpr double kBumpFinal = 1e-6;

TEST(AlphaDaiInsideTest, DefaultRunSeesAThinBumpALongStepWouldJump) {
  const Scene scene = BumpScene();
  const AlphaDaiResult result = SimulateAlphaDai(scene, AlphaDaiOptions{});
  ASSERT_EQ(result.status, AlphaDaiStatus::kSuccess) << result.message;
  EXPECT_GE(result.stats.num_inside_crossings, 1);
  EXPECT_EQ(result.stats.num_unresolved_crossings, 0);
  EXPECT_TRUE(result.warnings.empty()) << result.warnings.front();
  EXPECT_NEAR(result.final_state[1], 0.5 * kHeight, kBumpFinal);
  EXPECT_LE(FinePhiMaximum(scene, result, 0), kBumpFineCheck);
  EXPECT_LE(result.stats.max_constraint_violation, AlphaDaiOptions{}.constraint_tolerance);
  // The floor entered at its closed-form time c - w sqrt(ln 2) (x = t), to the event
  // resolution rtol (tf - t0) of the error control.
  const double entry = kCentre - kWidth * std::sqrt(std::log(2.0));
  const double resolution = AlphaDaiOptions{}.relative_tolerance * kHorizon;
  ASSERT_FALSE(result.events.empty());
  EXPECT_EQ(result.events.front().what, "bump.floor");
  EXPECT_NEAR(result.events.front().t, entry, resolution);
}

TEST(AlphaDaiInsideTest, FixedStepsOverTheBumpWarnAndShortStepsDoNot) {
  const Scene scene = BumpScene();
  AlphaDaiOptions options;
  options.step_size = 0.5;  // the step [0.5, 1] spans the bump; both of its ends are clear
  const AlphaDaiResult coarse = SimulateAlphaDai(scene, options);
  ASSERT_EQ(coarse.status, AlphaDaiStatus::kSuccess) << coarse.message;
  EXPECT_GE(coarse.stats.num_inside_crossings, 1);
  EXPECT_GE(coarse.stats.num_unresolved_crossings, 1);
  ASSERT_FALSE(coarse.warnings.empty());
  EXPECT_NE(coarse.warnings.back().find("bump.floor"), std::string::npos) << coarse.warnings.back();
  // The first time is where the extension (exact here: x = t, y = 0) enters the bump, its
  // closed form c - w sqrt(ln 2) = 0.55837226..., bisected to 2^-40 of the step.
  EXPECT_NE(coarse.warnings.back().find("t = 0.558372"), std::string::npos)
      << coarse.warnings.back();
  // Steps of 0.01 see the bump at their ends (the floor is active there): nothing to warn.
  options.step_size = 0.01;
  const AlphaDaiResult fine = SimulateAlphaDai(scene, options);
  ASSERT_EQ(fine.status, AlphaDaiStatus::kSuccess) << fine.message;
  EXPECT_EQ(fine.stats.num_unresolved_crossings, 0);
}

// D2 with defaults: the robot drives along y = 0 at V = 1, and obs1 (centre (3, 0.73), reach
// r_v + r = 0.75) reaches 0.02 into the lane for |x - 3| < sqrt(0.75^2 - 0.73^2) = 0.172.
// Before the search a step from t = 2.18 to 3.28 jumped it. Now the constraint enters at the
// contact x = 3 - 0.172 (x = t to 1e-9: V = 1 - 1e-9), where the robot meets it at the rate
// 0.23 m/s, which no bounded input cancels (index 3: docs/accuracy.md), and the run ends there
// with a status; along the recorded steps no obstacle is entered.
// What the fine check allows: TOL plus the tolerances' resolution |dphi/dx| rtol |x| (|dphi/dx|
// = 1, |x| <= 3: 3e-6), rounded up; obs1 reached 0.02 into the lane.
constexpr double kD2FineCheck = 1e-5;

TEST(AlphaDaiInsideTest, D2SeesObs1AtItsContact) {
  Scene scene = MakeScene("D2");
  scene.final_time = 4.0;
  const AlphaDaiResult result = SimulateAlphaDai(scene, AlphaDaiOptions{});
  const double contact = 3.0 - std::sqrt(0.75 * 0.75 - 0.73 * 0.73);
  // The event resolution rtol (tf - t0) of this horizon.
  const double resolution = AlphaDaiOptions{}.relative_tolerance * scene.final_time;
  const auto entered = std::find_if(result.events.begin(), result.events.end(),
                                    [](const Event& e) { return e.what == "D2.obs1"; });
  ASSERT_NE(entered, result.events.end()) << ToString(result.status) << ": " << result.message;
  EXPECT_EQ(entered->kind, EventKind::kEnter);
  EXPECT_NEAR(entered->t, contact, resolution);
  if (result.status != AlphaDaiStatus::kSuccess) {
    EXPECT_FALSE(result.message.empty());
  }
  for (int k = 0; k < 3; ++k) EXPECT_LE(FinePhiMaximum(scene, result, k), kD2FineCheck) << k;
}

// No false alarms: the other DAI scenes with defaults (D3's heat flux, which stays within the
// bounds' resolution of zero for a while after it lets go, is checked in
// AlphaDaiErrorControlTest.D3HeatFluxArcMatchesThePhases, which runs it anyway).
TEST(AlphaDaiInsideTest, OtherDaiScenesDoNotWarn) {
  for (const char* name : {"dai_index2", "hard_index3"}) {
    const AlphaDaiResult result = SimulateAlphaDai(MakeScene(name), AlphaDaiOptions{});
    EXPECT_EQ(result.status, AlphaDaiStatus::kSuccess) << name << ": " << result.message;
    EXPECT_EQ(result.stats.num_unresolved_crossings, 0) << name;
    EXPECT_EQ(result.stats.num_inside_crossings, 0) << name;
    EXPECT_TRUE(result.warnings.empty()) << name;
  }
}

}  // namespace
}  // namespace moreau
