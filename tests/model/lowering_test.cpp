#include <gtest/gtest.h>

#include <random>

#include "../problems/test_scenes.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Central differences with step 1e-6 have truncation error ~1e-12 |f'''| and round-off
// ~1e-10 |f|; derivatives of O(1)-O(10) functions agree to this relative tolerance.
constexpr double kFiniteDifference = 1e-6;
constexpr double kDerivativeAgreement = 1e-6;

// Checks every derivative block of `system` at (y, z) against central differences.
void CheckDerivatives(LoweredSystem* system, const Vector& y, const Vector& z,
                      const std::string& label) {
  PointEvaluation exact;
  system->Evaluate(y, z, Derivatives::kAll, &exact);
  auto compare = [&](const DerivativeMatrix& stored, const Matrix& numeric,
                     const std::string& what) {
    const Matrix analytic = stored.ToDense();
    ASSERT_EQ(analytic.rows(), numeric.rows()) << label << " " << what;
    ASSERT_EQ(analytic.cols(), numeric.cols()) << label << " " << what;
    const double scale = 1.0 + numeric.lpNorm<Eigen::Infinity>();
    EXPECT_LE((analytic - numeric).lpNorm<Eigen::Infinity>(), kDerivativeAgreement * scale)
        << label << ": " << what << "\nanalytic:\n"
        << analytic << "\nnumeric:\n"
        << numeric;
  };
  // Perturbs one coordinate through `apply` and differentiates F, G, A, B.
  auto numeric = [&](int columns, auto apply) {
    std::array<Matrix, 4> d;
    for (Matrix& m : d) m.resize(0, columns);
    d[0].resize(exact.F.size(), columns);
    d[1].resize(exact.G.size(), columns);
    d[2].resize(exact.A.size(), columns);
    d[3].resize(exact.B.size(), columns);
    for (int j = 0; j < columns; ++j) {
      PointEvaluation plus, minus;
      apply(j, kFiniteDifference, &plus);
      apply(j, -kFiniteDifference, &minus);
      d[0].col(j) = (plus.F - minus.F) / (2 * kFiniteDifference);
      d[1].col(j) = (plus.G - minus.G) / (2 * kFiniteDifference);
      d[2].col(j) = (plus.A - minus.A) / (2 * kFiniteDifference);
      d[3].col(j) = (plus.B - minus.B) / (2 * kFiniteDifference);
    }
    return d;
  };
  const auto dy = numeric(static_cast<int>(y.size()), [&](int j, double e, PointEvaluation* out) {
    Vector yy = y;
    yy[j] += e;
    system->Evaluate(yy, z, Derivatives::kNone, out);
  });
  const auto dz = numeric(static_cast<int>(z.size()), [&](int j, double e, PointEvaluation* out) {
    Vector zz = z;
    zz[j] += e;
    system->Evaluate(y, zz, Derivatives::kNone, out);
  });
  const Vector u = system->inputs(), p = system->parameters();
  const auto du = numeric(static_cast<int>(u.size()), [&](int j, double e, PointEvaluation* out) {
    Vector uu = u;
    uu[j] += e;
    system->SetInputs(uu);
    system->Evaluate(y, z, Derivatives::kNone, out);
    system->SetInputs(u);
  });
  const auto dp = numeric(static_cast<int>(p.size()), [&](int j, double e, PointEvaluation* out) {
    Vector pp = p;
    pp[j] += e;
    system->SetParameters(pp);
    system->Evaluate(y, z, Derivatives::kNone, out);
    system->SetParameters(p);
  });
  compare(exact.F_y, dy[0], "F_y");
  compare(exact.G_y, dy[1], "G_y");
  compare(exact.A_y, dy[2], "A_y");
  compare(exact.B_y, dy[3], "B_y");
  compare(exact.F_z, dz[0], "F_z");
  compare(exact.G_z, dz[1], "G_z");
  compare(exact.A_z, dz[2], "A_z");
  compare(exact.B_z, dz[3], "B_z");
  compare(exact.F_u, du[0], "F_u");
  compare(exact.G_u, du[1], "G_u");
  compare(exact.A_u, du[2], "A_u");
  compare(exact.F_p, dp[0], "F_p");
  compare(exact.G_p, dp[1], "G_p");
  compare(exact.A_p, dp[2], "A_p");
}

class LoweringDerivativeTest
    : public ::testing::TestWithParam<std::pair<std::string, SwitchingForm>> {};

TEST_P(LoweringDerivativeTest, AllBlocksMatchCentralDifferences) {
  const auto& [name, form] = GetParam();
  const Scene scene = name == "two_surfaces"       ? testing::TwoSurfaceScene()
                      : name == "mixed_hysteresis" ? testing::MixedHysteresisScene()
                      : name == "mixed_speed"      ? testing::MixedHysteresisScene(true)
                                                   : MakeScene(name);
  // Both derivative storages: dense AD and sparse AD (docs/sparse-systems.md).
  for (const DerivativeStorage storage : {DerivativeStorage::kDense, DerivativeStorage::kSparse}) {
    LoweringOptions options;
    options.switching_form = form;
    options.storage = storage;
    LoweredSystem system(scene, options);
    std::mt19937 rng(42);
    std::uniform_real_distribution<double> uniform(-0.9, 0.9);
    for (int trial = 0; trial < 3; ++trial) {
      Vector y = system.InitialState();
      for (Eigen::Index i = 0; i < y.size(); ++i) y[i] += uniform(rng);
      Vector z(system.num_algebraic());
      for (Eigen::Index i = 0; i < z.size(); ++i) z[i] = 0.5 + 0.5 * uniform(rng);
      CheckDerivatives(&system, y, z,
                       name + " " + ToString(storage) + " trial " + std::to_string(trial));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    Scenes, LoweringDerivativeTest,
    ::testing::Values(std::pair{std::string("S2"), SwitchingForm::kStewart},
                      std::pair{std::string("S3"), SwitchingForm::kStewart},
                      std::pair{std::string("F1"), SwitchingForm::kStewart},
                      std::pair{std::string("F1"), SwitchingForm::kHeaviside},
                      std::pair{std::string("F2c"), SwitchingForm::kStewart},
                      std::pair{std::string("F2c"), SwitchingForm::kHeaviside},
                      std::pair{std::string("two_surfaces"), SwitchingForm::kStewart},
                      std::pair{std::string("two_surfaces"), SwitchingForm::kHeaviside},
                      std::pair{std::string("H2"), SwitchingForm::kStewart},
                      std::pair{std::string("H3"), SwitchingForm::kStewart},
                      std::pair{std::string("mixed_hysteresis"), SwitchingForm::kStewart},
                      std::pair{std::string("mixed_hysteresis"), SwitchingForm::kHeaviside},
                      std::pair{std::string("mixed_speed"), SwitchingForm::kStewart}),
    [](const auto& test_info) {
      return test_info.param.first + "_" + ToString(test_info.param.second);
    });

TEST(LoweringTest, SizesAreSquarePerStageAndOnlyDeclaredEffectsCost) {
  const LoweredSystem smooth(MakeScene("hopf"));
  EXPECT_EQ(smooth.num_algebraic(), 0);
  EXPECT_EQ(smooth.num_pairs(), 0);
  EXPECT_EQ(smooth.num_states(), 3);  // x, y and the clock
  const LoweredSystem sweeping(MakeScene("S2"));
  EXPECT_EQ(sweeping.num_algebraic(), 2);
  EXPECT_EQ(sweeping.num_pairs(), 2);
  LoweringOptions heaviside;
  heaviside.switching_form = SwitchingForm::kHeaviside;
  const LoweredSystem stewart(testing::TwoSurfaceScene()),
      step(testing::TwoSurfaceScene(), heaviside);
  // Stewart: 4 modes -> theta, lambda (4 each) and mu; plus the disc's lambda.
  EXPECT_EQ(stewart.num_algebraic(), 2 * 4 + 1 + 1);
  EXPECT_EQ(stewart.num_equations(), 4 + 1);
  // Heaviside: 3 unknowns per surface; plus the disc's lambda.
  EXPECT_EQ(step.num_algebraic(), 3 * 2 + 1);
  EXPECT_EQ(step.num_equations(), 2);
  for (const LoweredSystem* s : {&smooth, &sweeping, &stewart, &step}) {
    EXPECT_EQ(s->num_algebraic(), s->num_equations() + s->num_pairs());
  }
}

TEST(LoweringTest, InitialGuessSelectsTheRegion) {
  const LoweredSystem system(MakeScene("F1"));
  // Outside the unit circle: theta = (0, 1), lambda = (2c, 0), mu = -c.
  const Vector z = system.InitialAlgebraicGuess(Vector{{2.0, 0.0, 0.0}});
  EXPECT_EQ(z[0], 0.0);
  EXPECT_EQ(z[1], 1.0);
  EXPECT_DOUBLE_EQ(z[2], 6.0);
  EXPECT_EQ(z[3], 0.0);
  EXPECT_DOUBLE_EQ(z[4], -3.0);
  PointEvaluation e;
  system.Evaluate(Vector{{2.0, 0.0, 0.0}}, z, Derivatives::kNone, &e);
  EXPECT_LE(e.G.lpNorm<Eigen::Infinity>(), 1e-15);
}

TEST(LoweringTest, HysteresisRelaysAddMemoriesAndStewartRegions) {
  const LoweredSystem h3(MakeScene("H3"));
  // y = (xa, xb, thermostat_a.w, thermostat_b.w, clock); 9 unknowns, 5 equations, 4 pairs
  // per relay.
  EXPECT_EQ(h3.num_states(), 5);
  EXPECT_EQ(h3.state_names()[2], "thermostat_a.w");
  EXPECT_EQ(h3.num_algebraic(), 18);
  EXPECT_EQ(h3.num_equations(), 10);
  EXPECT_EQ(h3.num_pairs(), 8);
  EXPECT_TRUE(h3.time_freezing());
  const Vector y0 = h3.InitialState();
  EXPECT_EQ(y0[2], 0.0);  // room a starts with the heater on (w = 0)
  EXPECT_EQ(y0[3], 1.0);  // room b with the heater off
  // At y0 both relays lie on a region boundary (w = 0: R1/R2; w = 1 with psi > 1: R3/R4):
  // the guess splits theta evenly, which is the sliding value, and P = 1.
  const Vector z = h3.InitialAlgebraicGuess(y0);
  EXPECT_EQ(z.segment(0, 4), Vector({{0.5, 0.5, 0.0, 0.0}}).eval());
  EXPECT_EQ(z.segment(9, 4), Vector({{0.0, 0.0, 0.5, 0.5}}).eval());
  PointEvaluation e;
  h3.Evaluate(y0, z, Derivatives::kNone, &e);
  EXPECT_LE(e.G.lpNorm<Eigen::Infinity>(), 1e-15);
  EXPECT_EQ(e.F[4], 1.0);  // clock' = P = 1
  EXPECT_EQ(e.F[2], 0.0);  // memories at rest
  EXPECT_EQ(e.F[3], 0.0);
  // Physical dynamics of room a (heater on): -0.2 * 15 + 5; room b (off): -0.3 * 22.
  EXPECT_DOUBLE_EQ(e.F[0], 2.0);
  EXPECT_DOUBLE_EQ(e.F[1], -6.6);
  // Relay b jumping (theta_to_A = 1): physical time and both rooms freeze.
  Vector frozen = z;
  frozen.segment(9, 4) << 0.0, 1.0, 0.0, 0.0;
  h3.Evaluate(y0, frozen, Derivatives::kNone, &e);
  EXPECT_EQ(e.F[0], 0.0);
  EXPECT_EQ(e.F[1], 0.0);
  EXPECT_EQ(e.F[4], 0.0);
  EXPECT_EQ(e.F[3], -1.0);  // w_b travels down at the auxiliary gain a = 1
}

TEST(LoweringTest, RelayStatusesNameTheJumpAndFreezeTime) {
  const LoweredSystem system(MakeScene("H1"));
  // Regions (mode_A, to_A, to_B, mode_B); a_zero false = region active.
  const std::vector<bool> sliding_a = {false, false, true, true};
  const std::vector<bool> jumping_to_b = {true, true, false, true};
  const std::vector<bool> sliding_b = {true, true, false, false};
  EXPECT_FALSE(system.TimeFrozen(sliding_a));
  EXPECT_TRUE(system.TimeFrozen(jumping_to_b));
  EXPECT_EQ(system.MemoryTargets(jumping_to_b), std::vector<int>{1});
  EXPECT_EQ(system.MemoryTargets(sliding_b), std::vector<int>{-1});
  const auto events = system.StatusEvents(3.0, sliding_a, jumping_to_b);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, EventKind::kRelaySwitch);
  EXPECT_EQ(events[0].what, "thermostat");
  EXPECT_EQ(events[0].detail, "A -> B");
  // The end of the frozen interval is not another switch.
  EXPECT_TRUE(system.StatusEvents(3.0, jumping_to_b, sliding_b).empty());
  const Vector y0 = system.InitialState();
  EXPECT_EQ(system.InitialEvents(0.0, y0, jumping_to_b).size(), 1u);
  EXPECT_TRUE(system.InitialEvents(0.0, y0, sliding_a).empty());
}

TEST(LoweringTest, StatusEventsNameTheSwitch) {
  const LoweredSystem system(MakeScene("F1"));
  // inside active (lambda_inside = 0: pair 0 b-zero) -> outside active.
  const auto events = system.StatusEvents(1.0, {false, true}, {true, false});
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, EventKind::kModeSwitch);
  EXPECT_EQ(events[0].detail, "inside -> outside");
  const auto slide = system.StatusEvents(2.0, {false, true}, {false, false});
  ASSERT_EQ(slide.size(), 1u);
  EXPECT_EQ(slide[0].kind, EventKind::kSlideStart);
}

}  // namespace
}  // namespace moreau
