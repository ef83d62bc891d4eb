#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "../problems/test_scenes.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

constexpr double kFiniteDifference = 1e-6;
constexpr double kDerivativeAgreement = 1e-6;  // central differences, O(1) functions
constexpr double kCandidate = 1e-9;            // pairs zero to within this are candidates

void ExpectNear(const Matrix& analytic, const Matrix& numeric, const std::string& what) {
  ASSERT_EQ(analytic.rows(), numeric.rows()) << what;
  ASSERT_EQ(analytic.cols(), numeric.cols()) << what;
  EXPECT_LE((analytic - numeric).lpNorm<Eigen::Infinity>(),
            kDerivativeAgreement * (1.0 + numeric.lpNorm<Eigen::Infinity>()))
      << what << "\nanalytic\n"
      << analytic << "\nnumeric\n"
      << numeric;
}

// Stacks all rows of a velocity-level evaluation: equations, then a, then b.
Vector Stack(const VelocityLevelEvaluation& e) {
  Vector all(e.equations.size() + e.a.size() + e.b.size());
  all << e.equations, e.a, e.b;
  return all;
}

void CheckVelocityDerivatives(LoweredSystem* system, const Vector& y, const Vector& v,
                              const std::vector<PairRole>& roles, const std::string& label) {
  VelocityLevelEvaluation exact;
  system->EvaluateVelocityLevel(y, v, roles, Derivatives::kAll, &exact);
  auto stacked = [](const DerivativeMatrix& a, const DerivativeMatrix& b,
                    const DerivativeMatrix& c) {
    Matrix m(a.rows() + b.rows() + c.rows(), a.cols());
    m << a.ToDense(), b.ToDense(), c.ToDense();
    return m;
  };
  auto numeric = [&](int n, auto perturb) {
    Matrix d(Stack(exact).size(), n);
    for (int j = 0; j < n; ++j) {
      VelocityLevelEvaluation plus, minus;
      perturb(j, kFiniteDifference, &plus);
      perturb(j, -kFiniteDifference, &minus);
      d.col(j) = (Stack(plus) - Stack(minus)) / (2 * kFiniteDifference);
    }
    return d;
  };
  ExpectNear(stacked(exact.equations_v, exact.a_v, exact.b_v),
             numeric(static_cast<int>(v.size()),
                     [&](int j, double e, VelocityLevelEvaluation* out) {
                       Vector vv = v;
                       vv[j] += e;
                       system->EvaluateVelocityLevel(y, vv, roles, Derivatives::kNone, out);
                     }),
             label + " d/dv");
  ExpectNear(stacked(exact.equations_y, exact.a_y, exact.b_y),
             numeric(static_cast<int>(y.size()),
                     [&](int j, double e, VelocityLevelEvaluation* out) {
                       Vector yy = y;
                       yy[j] += e;
                       system->EvaluateVelocityLevel(yy, v, roles, Derivatives::kNone, out);
                     }),
             label + " d/dy");
  const Vector p = system->parameters();
  ExpectNear(stacked(exact.equations_p, exact.a_p, exact.b_p),
             numeric(static_cast<int>(p.size()),
                     [&](int j, double e, VelocityLevelEvaluation* out) {
                       Vector pp = p;
                       pp[j] += e;
                       system->SetParameters(pp);
                       system->EvaluateVelocityLevel(y, v, roles, Derivatives::kNone, out);
                       system->SetParameters(p);
                     }),
             label + " d/dp");
}

TEST(VelocityLevelTest, DerivativesMatchCentralDifferences) {
  for (const char* name : {"S2", "S3", "F1", "F2c"}) {
    for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
      for (DerivativeStorage storage : {DerivativeStorage::kDense, DerivativeStorage::kSparse}) {
        LoweringOptions options;
        options.switching_form = form;
        options.storage = storage;
        LoweredSystem system(MakeScene(name), options);
        Vector y = system.InitialState();
        y.head(system.num_scene_states()).array() += 0.3;
        y[system.clock_index()] += 0.7;
        Vector v = Vector::LinSpaced(system.num_algebraic(), 0.2, 0.9);
        const int np = system.num_pairs();
        // Mixed roles: alternate decided sides and one complementary pair.
        std::vector<PairRole> roles(static_cast<std::size_t>(np));
        for (int k = 0; k < np; ++k) {
          roles[static_cast<std::size_t>(k)] =
              k == 0 ? PairRole::kComplementary : (k % 2 ? PairRole::kAZero : PairRole::kBZero);
        }
        CheckVelocityDerivatives(
            &system, y, v, roles,
            std::string(name) + " " + ToString(form) + " " + ToString(storage));
      }
    }
  }
}

TEST(VelocityLevelTest, TimeFreezingDerivativesMatchCentralDifferences) {
  for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
    for (DerivativeStorage storage : {DerivativeStorage::kDense, DerivativeStorage::kSparse}) {
      LoweringOptions options;
      options.switching_form = form;
      options.storage = storage;
      LoweredSystem system(testing::MixedHysteresisScene(), options);
      Vector y = system.InitialState();
      y.head(system.num_scene_states()).array() += 0.3;
      y[2] = 0.1;  // memories off their rest values
      y[3] = 0.8;
      y[system.clock_index()] += 0.7;
      const Vector v = Vector::LinSpaced(system.num_algebraic(), 0.2, 0.9);
      const int np = system.num_pairs();
      std::vector<PairRole> roles(static_cast<std::size_t>(np));
      for (int k = 0; k < np; ++k) {
        roles[static_cast<std::size_t>(k)] =
            k % 3 == 0 ? PairRole::kComplementary : (k % 2 ? PairRole::kAZero : PairRole::kBZero);
      }
      CheckVelocityDerivatives(&system, y, v, roles, "mixed_hysteresis " + ToString(form));

      // Event indicators with respect to y and p (the relay thresholds are parameters).
      std::vector<bool> a_zero(static_cast<std::size_t>(np), true);
      for (int k = 0; k < np; k += 3) a_zero[static_cast<std::size_t>(k)] = false;
      IndicatorEvaluation exact;
      system.EvaluateEventIndicators(y, v, a_zero, Derivatives::kAll, &exact);
      auto numeric = [&](int n, auto perturb) {
        Matrix d(np, n);
        for (int j = 0; j < n; ++j) {
          IndicatorEvaluation plus, minus;
          perturb(j, kFiniteDifference, &plus);
          perturb(j, -kFiniteDifference, &minus);
          d.col(j) = (plus.values - minus.values) / (2 * kFiniteDifference);
        }
        return d;
      };
      ExpectNear(exact.d_y.ToDense(),
                 numeric(static_cast<int>(y.size()),
                         [&](int j, double e, IndicatorEvaluation* out) {
                           Vector yy = y;
                           yy[j] += e;
                           system.EvaluateEventIndicators(yy, v, a_zero, Derivatives::kNone, out);
                         }),
                 "mixed_hysteresis indicators d/dy");
      const Vector p = system.parameters();
      ExpectNear(exact.d_p.ToDense(),
                 numeric(static_cast<int>(p.size()),
                         [&](int j, double e, IndicatorEvaluation* out) {
                           Vector pp = p;
                           pp[j] += e;
                           system.SetParameters(pp);
                           system.EvaluateEventIndicators(y, v, a_zero, Derivatives::kNone, out);
                           system.SetParameters(p);
                         }),
                 "mixed_hysteresis indicators d/dp");
    }
  }
}

TEST(VelocityLevelTest, IndicatorDerivativesMatchCentralDifferences) {
  for (const char* name : {"S2", "F1"}) {
    for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
      LoweringOptions options;
      options.switching_form = form;
      LoweredSystem system(MakeScene(name), options);
      Vector y = system.InitialState();
      y.head(system.num_scene_states()).array() += 0.3;
      const Vector v = Vector::LinSpaced(system.num_algebraic(), 0.2, 0.9);
      std::vector<bool> a_zero(static_cast<std::size_t>(system.num_pairs()), true);
      a_zero[0] = false;  // Stewart: mode 0 active; moving set: first constraint inactive
      IndicatorEvaluation exact;
      system.EvaluateEventIndicators(y, v, a_zero, Derivatives::kAll, &exact);
      Matrix dy(system.num_pairs(), y.size());
      for (Eigen::Index j = 0; j < y.size(); ++j) {
        IndicatorEvaluation plus, minus;
        Vector yp = y, ym = y;
        yp[j] += kFiniteDifference;
        ym[j] -= kFiniteDifference;
        system.EvaluateEventIndicators(yp, v, a_zero, Derivatives::kNone, &plus);
        system.EvaluateEventIndicators(ym, v, a_zero, Derivatives::kNone, &minus);
        dy.col(j) = (plus.values - minus.values) / (2 * kFiniteDifference);
      }
      ExpectNear(exact.d_y.ToDense(), dy, std::string(name) + " indicators d/dy");
    }
  }
}

StatusDecision DecideAt(const std::string& scene, const Vector& x, double t,
                        SwitchingForm form = SwitchingForm::kStewart) {
  LoweringOptions options;
  options.switching_form = form;
  LoweredSystem system(MakeScene(scene), options);
  Vector y(system.num_states());
  y << x, t;
  return system.DecideStatuses(y, kCandidate);
}

TEST(StatusDecisionTest, ContactLeavingAndCrossing) {
  // S1 at the wall (x = t = 1): x' = -1 + lambda must follow the wall: lambda = 2, active.
  StatusDecision d = DecideAt("S1", Vector{{1.0}}, 1.0);
  ASSERT_TRUE(d.solved) << d.message;
  EXPECT_TRUE(d.a_zero[0]);
  EXPECT_NEAR(d.v[0], 2.0, 1e-12);
  // S3 entering the floor at (sqrt3, -1): lambda = sqrt3 keeps x2 on the floor.
  d = DecideAt("S3", Vector{{std::sqrt(3.0), -1.0}}, 5 * std::numbers::pi / 12);
  ASSERT_TRUE(d.solved) << d.message;
  EXPECT_TRUE(d.a_zero[0]);
  EXPECT_NEAR(d.v[0], std::sqrt(3.0), 1e-12);
  // S3 at the leaving point (0, -1): lambda = 0 and c' = 0 (degenerate); it leaves.
  d = DecideAt("S3", Vector{{0.0, -1.0}}, 1.0);
  ASSERT_TRUE(d.solved) << d.message;
  EXPECT_FALSE(d.a_zero[0]);
  EXPECT_FALSE(d.ambiguous);
  // F1 on the unit circle: both fields point outward, the state crosses into "outside".
  for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
    d = DecideAt("F1", Vector{{1.0, 0.0}}, 1.0, form);
    ASSERT_TRUE(d.solved) << d.message;
    EXPECT_FALSE(d.ambiguous);
    if (form == SwitchingForm::kStewart) {
      EXPECT_TRUE(d.a_zero[0]);   // theta_inside = 0
      EXPECT_FALSE(d.a_zero[1]);  // lambda_outside = 0: outside active
    } else {
      EXPECT_FALSE(d.a_zero[0]);  // alpha != 0 ...
      EXPECT_TRUE(d.a_zero[1]);   // ... 1 - alpha = 0: positive side
    }
  }
}

TEST(StatusDecisionTest, SlidingModes) {
  for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
    // F2b at x = 0: attractive surface, sliding with x' = 0.
    StatusDecision d = DecideAt("F2b", Vector{{0.0}}, 0.5, form);
    ASSERT_TRUE(d.solved) << d.message;
    EXPECT_FALSE(d.ambiguous);
    EXPECT_FALSE(d.a_zero[0]);
    EXPECT_FALSE(d.a_zero[1]);  // both b sides zero: sliding in either form
    // F2c at t = 1: the sliding mode ends (x' = 0 either way); the state leaves upward.
    d = DecideAt("F2c", Vector{{0.0}}, 1.0, form);
    ASSERT_TRUE(d.solved) << d.message;
    EXPECT_FALSE(d.ambiguous);
    if (form == SwitchingForm::kStewart) {
      EXPECT_TRUE(d.a_zero[0]);   // below inactive
      EXPECT_FALSE(d.a_zero[1]);  // above active
    }
    // F2d at x = 0: repulsive surface; three continuations, the slow one (x' = 0) is taken.
    d = DecideAt("F2d", Vector{{0.0}}, 0.0, form);
    ASSERT_TRUE(d.solved) << d.message;
    EXPECT_TRUE(d.ambiguous) << d.message;
    EXPECT_FALSE(d.a_zero[0]);
    EXPECT_FALSE(d.a_zero[1]);
  }
}

TEST(StatusDecisionTest, InteriorPointsAreDecidedWithoutCandidates) {
  const StatusDecision d = DecideAt("S3", Vector{{1.0, 0.5}}, 0.0);
  ASSERT_TRUE(d.solved);
  EXPECT_EQ(d.candidates, 0);
  EXPECT_FALSE(d.a_zero[0]);  // inactive: lambda = 0
  EXPECT_EQ(d.v[0], 0.0);
}

}  // namespace
}  // namespace moreau
