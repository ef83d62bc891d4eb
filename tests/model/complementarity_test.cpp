// The Complementarity effect in the model layer (docs/complementarity.md): validation with
// clear messages, exact derivatives of both lowerings (stage and velocity level, event
// indicators) against central differences, the status decision at a diode switch, and the
// scene-file form.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include "../problems/test_scenes.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Central differences with step 1e-6 on O(1) functions: truncation ~1e-12, round-off ~1e-10;
// derivatives agree to this relative tolerance.
constexpr double kFiniteDifference = 1e-6;
constexpr double kDerivativeAgreement = 1e-6;
// Pairs zero to within this count as zero on both sides (status decisions).
constexpr double kCandidate = 1e-9;

template <class F>
void ExpectInvalid(F f, const std::string& fragment) {
  try {
    f();
    FAIL() << "expected std::invalid_argument containing '" << fragment << "'";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos)
        << "message: " << error.what();
  }
}

void ExpectNear(const Matrix& analytic, const Matrix& numeric, const std::string& what) {
  ASSERT_EQ(analytic.rows(), numeric.rows()) << what;
  ASSERT_EQ(analytic.cols(), numeric.cols()) << what;
  EXPECT_LE((analytic - numeric).lpNorm<Eigen::Infinity>(),
            kDerivativeAgreement * (1.0 + numeric.lpNorm<Eigen::Infinity>()))
      << what << "\nanalytic\n"
      << analytic << "\nnumeric\n"
      << numeric;
}

// Central differences of `f` (a vector of values) over n perturbed coordinates.
template <class F>
Matrix Numeric(int rows, int n, F f) {
  Matrix d(rows, n);
  for (int j = 0; j < n; ++j)
    d.col(j) = (f(j, kFiniteDifference) - f(j, -kFiniteDifference)) / (2 * kFiniteDifference);
  return d;
}

// ---- validation ----------------------------------------------------------------------------

Complementarity& Effect(Scene* scene) { return std::get<Complementarity>(scene->effects[0]); }

TEST(ComplementarityValidationTest, BadDefinitionsGetClearErrors) {
  Scene scene = MakeScene("rectifier");
  EXPECT_NO_THROW(ValidateScene(scene));

  Effect(&scene).pair_names.clear();
  ExpectInvalid([&] { ValidateScene(scene); }, "complementarity system 'diode' has no pairs");

  scene = MakeScene("rectifier");
  Effect(&scene).pair_names = {"D", "D"};
  ExpectInvalid([&] { ValidateScene(scene); }, "duplicate name 'D'");

  scene = MakeScene("rectifier");
  Effect(&scene).input_matrix =
      MakeSmoothFunction("B3", 3, [](const auto&, const auto&, const auto&, const auto&, auto&) {});
  ExpectInvalid([&] { ValidateScene(scene); },
                "input matrix B ('B3') must have n_x * m = 2 * 1 = 2 outputs (row-major), got 3");

  scene = MakeScene("rectifier");
  Effect(&scene).input_matrix = SmoothFunction();
  ExpectInvalid([&] { ValidateScene(scene); }, "input matrix B is missing");

  scene = MakeScene("rectifier");
  Effect(&scene).output =
      MakeSmoothFunction("g2", 2, [](const auto&, const auto&, const auto&, const auto&, auto&) {});
  ExpectInvalid([&] { ValidateScene(scene); }, "output g ('g2') must have 1 outputs, got 2");

  scene = MakeScene("rectifier");
  Effect(&scene).output = MakeSmoothFunction(
      "g", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[2];  // a state that does not exist
      });
  ExpectInvalid([&] { ValidateScene(scene); }, "reads x[2], but x has 2 components");

  scene = MakeScene("rectifier");
  Effect(&scene).feedthrough =
      MakeSmoothFunction("D4", 4, [](const auto&, const auto&, const auto&, const auto&, auto&) {});
  ExpectInvalid([&] { ValidateScene(scene); },
                "feedthrough D ('D4') must have m * m = 1 * 1 = 1 outputs (row-major), got 4");

  // D = -R: not a P-matrix; the message names the minor and the index-2 alternative.
  scene = MakeScene("rectifier");
  Effect(&scene).feedthrough = MakeSmoothFunction(
      "minus_R", 1,
      [](const auto&, const auto&, const auto&, const auto&, auto& out) { out[0] = -1000.0; });
  ExpectInvalid([&] { ValidateScene(scene); },
                "the feedthrough D must be a P-matrix (all principal minors positive)");
  ExpectInvalid([&] { ValidateScene(scene); },
                "the principal minor of rows and columns {1} is -1000 (must be > 0). For D = 0 "
                "leave D out (index-2 form)");

  scene = MakeScene("rectifier");
  Effect(&scene).feedthrough = MakeSmoothFunction(
      "nan", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        using std::sqrt;
        out[0] = sqrt(-1.0 - x[0] * x[0]);
      });
  ExpectInvalid([&] { ValidateScene(scene); }, "('nan') is not finite at the initial state");

  // Index 2 (no D): w = g(x0) must start nonnegative.
  scene = MakeScene("buck");
  EXPECT_NO_THROW(ValidateScene(scene));
  scene.initial_state[0] = -0.5;
  ExpectInvalid([&] { ValidateScene(scene); },
                "infeasible initial state: pair 'D' of complementarity system 'diode' has w = g = "
                "-0.5 < 0");
  EXPECT_NO_THROW(ValidateScene(scene, /*check_initial_feasibility=*/false));
}

TEST(ComplementarityValidationTest, PMatrixTest) {
  EXPECT_EQ(PMatrixViolation(Matrix{{2.0, 1.0}, {-1.0, 2.0}}), "");  // PD symmetric part
  // Not positive definite in its symmetric part, but every principal minor is positive.
  EXPECT_EQ(PMatrixViolation(Matrix{{1.0, -3.0}, {0.0, 1.0}}), "");
  EXPECT_EQ(PMatrixViolation(Matrix{{1.0, 2.0}, {2.0, 1.0}}),
            "the principal minor of rows and columns {1, 2} is -3 (must be > 0)");
  // A singular minor is not positive (round-off of an exact zero included).
  const std::string singular = PMatrixViolation(Matrix{{1.0, 1.0}, {1.0, 1.0}});
  EXPECT_NE(singular.find("{1, 2}"), std::string::npos) << singular;
  // The bridge's D (symmetric positive definite) and the same without the diodes'
  // on-resistance: D1 and D3 in series across a source half and the load are a loop of
  // diodes only (singular minor {1, 3}).
  Scene bridge = MakeScene("diode_bridge");
  EXPECT_NO_THROW(ValidateScene(bridge));
  SetSceneValue(&bridge, "R_on", 0.0);
  ExpectInvalid([&] { ValidateScene(bridge); },
                "the principal minor of rows and columns {1, 3} is 0 (must be > 0)");
  ExpectInvalid([] { PMatrixViolation(Matrix::Zero(2, 3)); }, "D must be square, got 2 x 3");
}

// ---- lowering ------------------------------------------------------------------------------

TEST(ComplementarityLoweringTest, SizesAndSides) {
  LoweredSystem system(testing::ComplementarityScene());
  EXPECT_EQ(system.num_algebraic(), 3);  // lambda only: no equations, one unknown per pair
  EXPECT_EQ(system.num_equations(), 0);
  EXPECT_EQ(system.num_pairs(), 3);
  EXPECT_EQ(system.pairs()[0].continuous, ContinuousSide::kBoth);
  EXPECT_EQ(system.pairs()[0].b_unknown, 0);
  EXPECT_EQ(system.pairs()[1].b_unknown, 1);
  EXPECT_EQ(system.pairs()[2].continuous, ContinuousSide::kA);
  EXPECT_EQ(system.continuous_algebraic(), (std::vector<bool>{true, true, false}));
  EXPECT_EQ(system.algebraic_names(),
            (std::vector<std::string>{"diodes.lambda_d1", "diodes.lambda_d2", "wall.lambda_w"}));
}

// Stage evaluation: F, A, B and all their derivatives.
TEST(ComplementarityLoweringTest, DerivativesMatchCentralDifferences) {
  for (bool relay : {false, true}) {
    LoweredSystem system(testing::ComplementarityScene(relay));
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> uniform(-0.5, 0.5);
    Vector y = system.InitialState();
    for (int i = 0; i < system.num_scene_states(); ++i) y[i] += uniform(rng);
    y[system.clock_index()] = 0.7;
    Vector z(system.num_algebraic());
    for (Eigen::Index i = 0; i < z.size(); ++i) z[i] = 0.5 + uniform(rng);
    PointEvaluation exact;
    system.Evaluate(y, z, Derivatives::kAll, &exact);
    auto stack = [](const PointEvaluation& e) {
      Vector all(e.F.size() + e.A.size() + e.B.size());
      all << e.F, e.A, e.B;
      return all;
    };
    auto stacked = [](const DerivativeMatrix& f, const DerivativeMatrix& a,
                      const DerivativeMatrix& b) {
      Matrix m(f.rows() + a.rows() + b.rows(), f.cols());
      m << f.ToDense(), a.ToDense(), b.ToDense();
      return m;
    };
    const int rows = static_cast<int>(stack(exact).size());
    const std::string label = relay ? "with relay" : "without relay";
    ExpectNear(stacked(exact.F_y, exact.A_y, exact.B_y),
               Numeric(rows, static_cast<int>(y.size()),
                       [&](int j, double e) {
                         Vector yy = y;
                         yy[j] += e;
                         PointEvaluation out;
                         system.Evaluate(yy, z, Derivatives::kNone, &out);
                         return stack(out);
                       }),
               label + " d/dy");
    ExpectNear(stacked(exact.F_z, exact.A_z, exact.B_z),
               Numeric(rows, static_cast<int>(z.size()),
                       [&](int j, double e) {
                         Vector zz = z;
                         zz[j] += e;
                         PointEvaluation out;
                         system.Evaluate(y, zz, Derivatives::kNone, &out);
                         return stack(out);
                       }),
               label + " d/dz");
    const Vector u = system.inputs(), p = system.parameters();
    ExpectNear(stacked(exact.F_u, exact.A_u, exact.B_u),
               Numeric(rows, static_cast<int>(u.size()),
                       [&](int j, double e) {
                         Vector uu = u;
                         uu[j] += e;
                         system.SetInputs(uu);
                         PointEvaluation out;
                         system.Evaluate(y, z, Derivatives::kNone, &out);
                         system.SetInputs(u);
                         return stack(out);
                       }),
               label + " d/du");
    ExpectNear(stacked(exact.F_p, exact.A_p, exact.B_p),
               Numeric(rows, static_cast<int>(p.size()),
                       [&](int j, double e) {
                         Vector pp = p;
                         pp[j] += e;
                         system.SetParameters(pp);
                         PointEvaluation out;
                         system.Evaluate(y, z, Derivatives::kNone, &out);
                         system.SetParameters(p);
                         return stack(out);
                       }),
               label + " d/dp");
  }
}

// Velocity level (consistent index-1 values inside F, second-order terms of D(x, u, t, p)) and
// event indicators, for several role patterns.
TEST(ComplementarityLoweringTest, VelocityLevelAndIndicatorDerivativesMatchCentralDifferences) {
  for (bool relay : {false, true}) {
    LoweredSystem system(testing::ComplementarityScene(relay));
    Vector y = system.InitialState();
    y.head(system.num_scene_states()) += Vector{{0.1, -0.2, 0.3}};
    y[system.clock_index()] = 0.7;
    const int nz = system.num_algebraic(), np = system.num_pairs();
    const Vector v = Vector::LinSpaced(nz, 0.3, 0.9);
    std::vector<std::vector<PairRole>> patterns = {
        {PairRole::kAZero, PairRole::kAZero, PairRole::kAZero},
        {PairRole::kAZero, PairRole::kBZero, PairRole::kBZero},
        {PairRole::kComplementary, PairRole::kAZero, PairRole::kComplementary},
        {PairRole::kBZero, PairRole::kComplementary, PairRole::kAZero}};
    for (auto roles : patterns) {
      // The relay's pairs (after the complementarity pairs): its first region active.
      for (int k = 3; k < np; ++k) roles.push_back(k == 3 ? PairRole::kBZero : PairRole::kAZero);
      auto stack = [](const VelocityLevelEvaluation& e) {
        Vector all(e.equations.size() + e.a.size() + e.b.size());
        all << e.equations, e.a, e.b;
        return all;
      };
      auto stacked = [](const DerivativeMatrix& da, const DerivativeMatrix& db,
                        const DerivativeMatrix& dc) {
        const Matrix a = da.ToDense(), b = db.ToDense(), c = dc.ToDense();
        Matrix m(a.rows() + b.rows() + c.rows(), a.cols());
        m << a, b, c;
        return m;
      };
      VelocityLevelEvaluation exact;
      system.EvaluateVelocityLevel(y, v, roles, Derivatives::kAll, &exact);
      const int rows = static_cast<int>(stack(exact).size());
      const std::string label = std::string(relay ? "relay " : "") + "roles " +
                                std::to_string(static_cast<int>(roles[0])) +
                                std::to_string(static_cast<int>(roles[1])) +
                                std::to_string(static_cast<int>(roles[2]));
      ExpectNear(stacked(exact.equations_v, exact.a_v, exact.b_v),
                 Numeric(rows, nz,
                         [&](int j, double e) {
                           Vector vv = v;
                           vv[j] += e;
                           VelocityLevelEvaluation out;
                           system.EvaluateVelocityLevel(y, vv, roles, Derivatives::kNone, &out);
                           return stack(out);
                         }),
                 label + " d/dv");
      ExpectNear(stacked(exact.equations_y, exact.a_y, exact.b_y),
                 Numeric(rows, static_cast<int>(y.size()),
                         [&](int j, double e) {
                           Vector yy = y;
                           yy[j] += e;
                           VelocityLevelEvaluation out;
                           system.EvaluateVelocityLevel(yy, v, roles, Derivatives::kNone, &out);
                           return stack(out);
                         }),
                 label + " d/dy");
      const Vector u = system.inputs(), p = system.parameters();
      ExpectNear(stacked(exact.equations_u, exact.a_u, exact.b_u),
                 Numeric(rows, static_cast<int>(u.size()),
                         [&](int j, double e) {
                           Vector uu = u;
                           uu[j] += e;
                           system.SetInputs(uu);
                           VelocityLevelEvaluation out;
                           system.EvaluateVelocityLevel(y, v, roles, Derivatives::kNone, &out);
                           system.SetInputs(u);
                           return stack(out);
                         }),
                 label + " d/du");
      ExpectNear(stacked(exact.equations_p, exact.a_p, exact.b_p),
                 Numeric(rows, static_cast<int>(p.size()),
                         [&](int j, double e) {
                           Vector pp = p;
                           pp[j] += e;
                           system.SetParameters(pp);
                           VelocityLevelEvaluation out;
                           system.EvaluateVelocityLevel(y, v, roles, Derivatives::kNone, &out);
                           system.SetParameters(p);
                           return stack(out);
                         }),
                 label + " d/dp");
    }
    // Indicators: index-1 pairs from the consistent values at y (both statuses), the index-2
    // pair's multiplier (active) from v.
    for (const std::vector<bool>& base :
         {std::vector<bool>{true, false, true}, std::vector<bool>{false, true, false}}) {
      std::vector<bool> a_zero = base;
      for (int k = 3; k < np; ++k) a_zero.push_back(k != 3);
      IndicatorEvaluation exact;
      system.EvaluateEventIndicators(y, v, a_zero, Derivatives::kAll, &exact);
      auto values = [&](const Vector& yy, const Vector& vv) {
        IndicatorEvaluation out;
        system.EvaluateEventIndicators(yy, vv, a_zero, Derivatives::kNone, &out);
        return Vector(out.values);
      };
      ExpectNear(exact.d_y.ToDense(),
                 Numeric(np, static_cast<int>(y.size()),
                         [&](int j, double e) {
                           Vector yy = y;
                           yy[j] += e;
                           return values(yy, v);
                         }),
                 "indicators d/dy");
      ExpectNear(exact.d_v.ToDense(),
                 Numeric(np, nz,
                         [&](int j, double e) {
                           Vector vv = v;
                           vv[j] += e;
                           return values(y, vv);
                         }),
                 "indicators d/dv");
      const Vector p = system.parameters();
      ExpectNear(exact.d_p.ToDense(),
                 Numeric(np, static_cast<int>(p.size()),
                         [&](int j, double e) {
                           Vector pp = p;
                           pp[j] += e;
                           system.SetParameters(pp);
                           const Vector out = values(y, v);
                           system.SetParameters(p);
                           return out;
                         }),
                 "indicators d/dp");
    }
  }
}

// The slopes of the indicators along a direction (what the search between an element's nodes
// needs): the values bit for bit those of the evaluation with derivatives, the slopes d_y . dy
// to round-off, for every status pattern of the index-1 and index-2 pairs, at several states
// and directions with a time component. The two differ in the order of their operations
// (the direction applied before or after the solve with the active block D_ss), so they agree
// to round-off of the terms they add: a free side w = g + D lambda has the slope
// A_y dy + D (dlambda/dy) dy (A_y: w's derivative with the multipliers held), whose terms can
// be much larger than their sum (the bridge's blocking diodes: volts that cancel to millivolts).
// Allowed: kSlopeRoundOff times the sum of the magnitudes of those terms (observed: at most
// 0.014 of it). A relay (no slopes of its own) makes the system decline, so that the caller falls
// back to d_y.
TEST(ComplementarityLoweringTest, IndicatorSlopesAreTheDerivativesAlongTheDirection) {
  constexpr double kSlopeRoundOff = 64 * std::numeric_limits<double>::epsilon();
  std::mt19937 random(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (const Scene& scene : {testing::ComplementarityScene(false), MakeScene("rectifier"),
                             MakeScene("diode_bridge"), MakeScene("buck")}) {
    LoweredSystem system(scene);
    const int ny = system.num_states(), np = system.num_pairs(), nz = system.num_algebraic();
    for (int trial = 0; trial < 4; ++trial) {
      Vector y = system.InitialState();
      for (int i = 0; i < system.num_scene_states(); ++i) y[i] += 0.3 * unit(random);
      y[system.clock_index()] =
          scene.initial_time + (scene.final_time - scene.initial_time) * 0.25 * (trial + 0.5);
      Vector dy(ny);
      for (int i = 0; i < ny; ++i) dy[i] = unit(random);
      const Vector v = Vector::LinSpaced(nz, 0.3, 0.9);
      for (unsigned mask = 0; mask < (1u << np); ++mask) {
        std::vector<bool> a_zero(static_cast<std::size_t>(np));
        for (int k = 0; k < np; ++k) a_zero[static_cast<std::size_t>(k)] = (mask >> k) & 1u;
        const std::string label =
            scene.name + " trial " + std::to_string(trial) + " statuses " + std::to_string(mask);
        IndicatorEvaluation reference;
        system.EvaluateEventIndicators(y, v, a_zero, Derivatives::kStates, &reference);
        Vector values, slopes;
        ASSERT_TRUE(system.EvaluateEventIndicatorSlopes(y, v, a_zero, dy, &values, &slopes))
            << label;
        const Matrix d_y = reference.d_y.ToDense();
        // The multipliers (pair k's unknown is z_k here): the conducting pairs' free sides, and
        // their rates d_y; zero for the others. A_y and A_z (= D) at those multipliers.
        ASSERT_EQ(nz, np) << label;
        Vector z = Vector::Zero(nz);
        Matrix rates = Matrix::Zero(nz, ny);
        for (int k = 0; k < np; ++k) {
          if (!a_zero[static_cast<std::size_t>(k)]) continue;
          z[k] = reference.values[k];
          rates.row(k) = d_y.row(k);
        }
        PointEvaluation point;
        system.Evaluate(y, z, Derivatives::kStates, &point);
        const Matrix a_y = point.A_y.ToDense(), a_z = point.A_z.ToDense();
        for (int k = 0; k < np; ++k) {
          EXPECT_EQ(values[k], reference.values[k]) << label << " pair " << k;  // the same bits
          const double slope = d_y.row(k).dot(dy);
          const double terms = a_y.row(k).cwiseAbs().dot(dy.cwiseAbs()) +
                               (a_z.row(k).cwiseAbs() * rates.cwiseAbs()).dot(dy.cwiseAbs()) +
                               d_y.row(k).cwiseAbs().dot(dy.cwiseAbs());
          EXPECT_NEAR(slopes[k], slope, kSlopeRoundOff * terms) << label << " pair " << k;
        }
      }
    }
  }
  LoweredSystem with_relay(testing::ComplementarityScene(true));
  Vector values, slopes;
  EXPECT_FALSE(with_relay.EvaluateEventIndicatorSlopes(
      with_relay.InitialState(), Vector::Zero(with_relay.num_algebraic()),
      std::vector<bool>(static_cast<std::size_t>(with_relay.num_pairs()), false),
      Vector::Ones(with_relay.num_states()), &values, &slopes));
}

// The index-1 guess solves the LCP at the state: complementary to round-off.
TEST(ComplementarityLoweringTest, InitialGuessSolvesTheLcp) {
  LoweredSystem system(testing::ComplementarityScene());
  for (double shift : {-1.0, 0.0, 0.7}) {
    Vector y = system.InitialState();
    y[0] += shift;
    const Vector z = system.InitialAlgebraicGuess(y);
    PointEvaluation e;
    system.Evaluate(y, z, Derivatives::kNone, &e);
    for (int k = 0; k < 2; ++k) {
      EXPECT_GE(e.A[k], -1e-14) << shift;
      EXPECT_GE(e.B[k], -1e-14) << shift;
      EXPECT_LE(std::min(e.A[k], e.B[k]), 1e-14) << shift;
    }
  }
}

// The guess from every wrong active set (the previous values' signs) still solves the LCP:
// a guessed set that is not complementary is corrected by principal pivots or by the LCP
// solver, never returned. The diode bridge (four diodes, D a P-matrix) at states across its
// conduction modes, every one of the 16 guessed sets. kComplementarity: round-off of
// multipliers of size 1e-2 (amperes) from voltages of size 10.
TEST(ComplementarityLoweringTest, InitialGuessFromAnyActiveSetSolvesTheLcp) {
  constexpr double kComplementarity = 1e-12;
  LoweredSystem system(MakeScene("diode_bridge"));
  const int m = system.num_pairs();
  ASSERT_EQ(m, 4);
  for (double phase : {0.3, 1.4, 2.9, 4.0, 5.5}) {
    // The load at 4 V, the 10 V, 50 Hz source at this phase: one pair of diodes conducts near
    // the source's peaks, none near its zeros.
    Vector y = system.InitialState();
    y[0] = 4.0;
    y[system.clock_index()] = phase / (2.0 * std::numbers::pi * 50.0);
    for (unsigned set = 0; set < (1u << m); ++set) {
      Vector previous = Vector::Zero(system.num_algebraic());
      for (int k = 0; k < m; ++k) previous[k] = (set >> k) & 1u ? 1.0 : 0.0;
      const Vector z = system.InitialAlgebraicGuess(y, &previous);
      PointEvaluation e;
      system.Evaluate(y, z, Derivatives::kNone, &e);
      for (int k = 0; k < m; ++k) {
        EXPECT_GE(e.A[k], -kComplementarity) << phase << " " << set;
        EXPECT_GE(e.B[k], -kComplementarity) << phase << " " << set;
        EXPECT_LE(std::min(e.A[k], e.B[k]), kComplementarity) << phase << " " << set;
      }
    }
  }
}

// The velocity level of decided roles is affine in the rates v (the block's
// AffineInAlgebraicForDecidedRoles: a status decision's trials and the solves of fixed
// statuses are then solved on a linear model expanded at one evaluation): for every decided
// assignment of the roles, the rows at the midpoint of two rates are the mean of their rows,
// and d/dv is the same at both. The affine claim is exact; kAffineRoundOff allows the
// round-off of rows of size |v| ~ 1e3 (the rectifier's rates in A/s).
TEST(ComplementarityLoweringTest, VelocityLevelOfDecidedRolesIsAffineInTheRates) {
  constexpr double kAffineRoundOff = 1e-12;
  for (const Scene& scene :
       {MakeScene("rectifier"), MakeScene("diode_bridge"), testing::ComplementarityScene(false)}) {
    LoweredSystem system(scene);
    Vector y = system.InitialState();
    y.head(system.num_scene_states()) += Vector::LinSpaced(system.num_scene_states(), 0.3, -0.2);
    const int nz = system.num_algebraic(), np = system.num_pairs();
    ASSERT_EQ(nz, np) << scene.name;  // (the rates of the multipliers)
    const Vector v0 = 1e3 * Vector::LinSpaced(nz, -0.7, 0.9);
    const Vector v1 = 1e3 * Vector::LinSpaced(nz, 1.1, -0.4);
    const Vector mid = 0.5 * (v0 + v1);
    for (unsigned mask = 0; mask < (1u << np); ++mask) {
      std::vector<PairRole> roles;
      for (int k = 0; k < np; ++k)
        roles.push_back((mask >> k) & 1u ? PairRole::kAZero : PairRole::kBZero);
      VelocityLevelEvaluation e0, e1, em;
      system.EvaluateVelocityLevel(y, v0, roles, Derivatives::kNone, &e0);
      system.EvaluateVelocityLevel(y, v1, roles, Derivatives::kNone, &e1);
      system.EvaluateVelocityLevel(y, mid, roles, Derivatives::kNone, &em);
      ASSERT_EQ(em.a.size(), 0);  // decided roles: equations only
      const Vector mean = 0.5 * (e0.equations + e1.equations);
      const double size =
          1.0 + e0.equations.cwiseAbs().maxCoeff() + e1.equations.cwiseAbs().maxCoeff();
      EXPECT_LE((em.equations - mean).cwiseAbs().maxCoeff(), kAffineRoundOff * size)
          << scene.name << " roles " << mask;
      const Matrix jacobian0 = e0.equations_v.ToDense(), jacobian1 = e1.equations_v.ToDense();
      EXPECT_LE((jacobian0 - jacobian1).cwiseAbs().maxCoeff(),
                kAffineRoundOff * (1.0 + jacobian0.cwiseAbs().maxCoeff()))
          << scene.name << " roles " << mask;
    }
  }
}

// ---- status decisions ----------------------------------------------------------------------

StatusDecision DecideRectifier(double v_c, double i_l) {
  LoweredSystem system(MakeScene("rectifier"));
  return system.DecideStatuses(Vector{{v_c, i_l, 0.0}}, kCandidate);
}

TEST(ComplementarityDecisionTest, DiodeSwitchesFollowTheRateLcp) {
  // v_C = 0 falling (i_L > 0): lambda' = 0 and w' = i_L/C > 0, the diode blocks.
  StatusDecision d = DecideRectifier(0.0, 0.05);
  ASSERT_TRUE(d.solved) << d.message;
  EXPECT_EQ(d.candidates, 1);
  EXPECT_FALSE(d.a_zero[0]);
  EXPECT_FALSE(d.ambiguous);
  // v_C = 0 rising (i_L < 0): w' = 0 and lambda' = v_C'/R = -i_L/(R C) > 0, it conducts.
  d = DecideRectifier(0.0, -0.05);
  ASSERT_TRUE(d.solved) << d.message;
  EXPECT_TRUE(d.a_zero[0]);
  EXPECT_NEAR(d.v[0], 0.05 / (1e3 * 1e-6), 1e-9);  // the rate lambda' in A/s
  // Away from zero: no candidates, decided by the values.
  d = DecideRectifier(3.0, 0.0);
  ASSERT_TRUE(d.solved);
  EXPECT_EQ(d.candidates, 0);
  EXPECT_TRUE(d.a_zero[0]);  // conducting: w = 0
  d = DecideRectifier(-3.0, 0.0);
  EXPECT_EQ(d.candidates, 0);
  EXPECT_FALSE(d.a_zero[0]);  // blocking: lambda = 0
}

TEST(ComplementarityDecisionTest, BridgeStartsConductingInPairs) {
  // At t = 0 every diode has lambda = w = 0; the source rises, so D1 and D4 conduct.
  LoweredSystem system(MakeScene("diode_bridge"));
  const StatusDecision d = system.DecideStatuses(system.InitialState(), kCandidate);
  ASSERT_TRUE(d.solved) << d.message;
  EXPECT_EQ(d.candidates, 4);
  EXPECT_FALSE(d.ambiguous) << d.message;
  EXPECT_EQ(d.a_zero, (std::vector<bool>{true, false, false, true}));
}

// ---- scene files ---------------------------------------------------------------------------

TEST(ComplementaritySceneFileTest, BadMatricesAreLocated) {
  const std::string head = R"(name = "c"
states = ["v", "i"]
x0 = [1.0, 0.0]
tf = 1.0
[[effects]]
kind = "complementarity"
name = "diode"
output = ["-v"]
)";
  ExpectInvalid([&] { ParseScene(head + "input_matrix = [[\"1\"]]\n", "bad.toml"); },
                "effects[0].input_matrix): expected 2 entries (B: one row per state, one entry "
                "per pair), got 1");
  ExpectInvalid(
      [&] { ParseScene(head + "input_matrix = [[\"1\", \"2\"], [\"0\"]]\n", "bad.toml"); },
      "(effects[0].input_matrix[0]): expected 1 entry (one entry per pair), got 2");
  ExpectInvalid(
      [&] {
        ParseScene(head + "input_matrix = [[\"1\"], [\"0\"]]\nfeedthrough = [[\"v\", \"1\"]]\n",
                   "bad.toml");
      },
      "(effects[0].feedthrough[0]): expected 1 entry (one entry per pair), got 2");
  ExpectInvalid(
      [&] {
        ParseScene(head + "input_matrix = [[\"1\"], [\"0\"]]\nfeedthrough = [[\"-1\"]]\n",
                   "bad.toml");
      },
      "the feedthrough D must be a P-matrix");
  ExpectInvalid(
      [&] { ParseScene(head + "input_matrix = [[\"1\"], [\"0\"]]\nD = 1\n", "bad.toml"); },
      "unknown key 'D'");
  ExpectInvalid([&] { ParseScene(head, "bad.toml"); }, "missing required key 'input_matrix'");
  EXPECT_NO_THROW(ParseScene(head + "input_matrix = [[\"1\"], [\"0\"]]\nfeedthrough = [[\"2\"]]\n",
                             "good.toml"));
}

}  // namespace
}  // namespace moreau
