#include <gtest/gtest.h>

#include <random>

#include "moreau/model/lowered_system.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Central differences with step 1e-6 have truncation error ~1e-12 |f'''| and round-off
// ~1e-10 |f|; derivatives of O(1)-O(10) functions agree to this relative tolerance.
constexpr double kFiniteDifference = 1e-6;
constexpr double kDerivativeAgreement = 1e-6;

// A two-surface Filippov scene (four modes) and a moving set with a projection subspace.
Scene TwoSurfaceScene() {
  Scene scene;
  scene.name = "two_surfaces";
  scene.state_names = {"a", "b"};
  scene.initial_state = Vector{{0.3, -0.2}};
  scene.final_time = 1.0;
  const int k = scene.AddParameter("k", 1.5, "coefficient");
  InputSpec input;
  input.name = "u";
  input.signal.values = {0.7};
  scene.inputs.push_back(input);
  SwitchingSurfaces switching;
  switching.name = "quadrants";
  switching.surface_names = {"c0", "c1"};
  switching.surfaces = MakeSmoothFunction(
      "c", 2, [k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = x[0] - 0.1 * sin(t) + p[k] * u[0] * x[1] * x[1];
        out[1] = x[1] + x[0] * x[0] * p[k];
      });
  switching.mode_names = {"m0", "m1", "m2", "m3"};
  for (int mode = 0; mode < 4; ++mode) {
    switching.modes.push_back(MakeSmoothFunction(
        "f" + std::to_string(mode), 2,
        [mode, k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
          using std::cos;
          out[0] = (mode + 1.0) * x[1] + u[0] * t;
          out[1] = -p[k] * x[0] * (mode - 1.5) + cos(x[0] * x[1]);
        }));
  }
  scene.effects.push_back(switching);
  MovingSet set;
  set.name = "disc";
  set.constraint_names = {"inside"};
  set.constraints = MakeSmoothFunction(
      "disc.c", 1, [k](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        using std::cos;
        out[0] = 4.0 - (x[0] - cos(t)) * (x[0] - cos(t)) - p[k] * x[1] * x[1] * x[0];
      });
  set.projection_basis = Matrix{{1.0}, {0.0}};  // project along the first state only
  scene.effects.push_back(set);
  return scene;
}

// Checks every derivative block of `system` at (y, z) against central differences.
void CheckDerivatives(LoweredSystem* system, const Vector& y, const Vector& z,
                      const std::string& label) {
  PointEvaluation exact;
  system->Evaluate(y, z, Derivatives::kAll, &exact);
  auto compare = [&](const Matrix& analytic, const Matrix& numeric, const std::string& what) {
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
  const Scene scene = name == "two_surfaces" ? TwoSurfaceScene() : MakeScene(name);
  LoweringOptions options;
  options.switching_form = form;
  LoweredSystem system(scene, options);
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> uniform(-0.9, 0.9);
  for (int trial = 0; trial < 3; ++trial) {
    Vector y = system.InitialState();
    for (Eigen::Index i = 0; i < y.size(); ++i) y[i] += uniform(rng);
    Vector z(system.num_algebraic());
    for (Eigen::Index i = 0; i < z.size(); ++i) z[i] = 0.5 + 0.5 * uniform(rng);
    CheckDerivatives(&system, y, z, name + " trial " + std::to_string(trial));
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
                      std::pair{std::string("two_surfaces"), SwitchingForm::kHeaviside}),
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
  const LoweredSystem stewart(TwoSurfaceScene()), step(TwoSurfaceScene(), heaviside);
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
