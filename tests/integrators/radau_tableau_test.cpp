#include "moreau/integrators/radau_tableau.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace moreau {
namespace {

// Order conditions hold to round-off in the coefficients (computed in long double, rounded
// to double): a few ulps times the size of the sums.
constexpr double kCoefficientTolerance = 1e-14;

class RadauTableauTest : public ::testing::TestWithParam<int> {};

TEST_P(RadauTableauTest, SatisfiesTheSimplifyingOrderConditions) {
  const int s = GetParam();
  const RadauTableau& t = RadauIIA(s);
  ASSERT_EQ(t.c.size(), s);
  EXPECT_EQ(t.c[s - 1], 1.0);
  // B(2s - 1): sum_j b_j c_j^{k-1} = 1/k.
  for (int k = 1; k <= 2 * s - 1; ++k) {
    double sum = 0.0;
    for (int j = 0; j < s; ++j) sum += t.b[j] * std::pow(t.c[j], k - 1);
    EXPECT_NEAR(sum, 1.0 / k, kCoefficientTolerance) << "B(" << k << ")";
  }
  // C(s): sum_j a_ij c_j^{k-1} = c_i^k / k.
  for (int i = 0; i < s; ++i) {
    for (int k = 1; k <= s; ++k) {
      double sum = 0.0;
      for (int j = 0; j < s; ++j) sum += t.a(i, j) * std::pow(t.c[j], k - 1);
      EXPECT_NEAR(sum, std::pow(t.c[i], k) / k, kCoefficientTolerance) << "C(" << k << ")";
    }
  }
  // D(s - 1): sum_i b_i c_i^{k-1} a_ij = b_j (1 - c_j^k) / k.
  for (int j = 0; j < s; ++j) {
    for (int k = 1; k <= s - 1; ++k) {
      double sum = 0.0;
      for (int i = 0; i < s; ++i) sum += t.b[i] * std::pow(t.c[i], k - 1) * t.a(i, j);
      EXPECT_NEAR(sum, t.b[j] * (1 - std::pow(t.c[j], k)) / k, kCoefficientTolerance)
          << "D(" << k << ")";
    }
  }
  // Stiffly accurate, increasing nodes, A^{-1} consistent.
  EXPECT_LE((t.a.row(s - 1).transpose() - t.b).lpNorm<Eigen::Infinity>(), 0.0);
  for (int i = 1; i < s; ++i) EXPECT_LT(t.c[i - 1], t.c[i]);
  EXPECT_LE((t.a * t.a_inverse - Matrix::Identity(s, s)).lpNorm<Eigen::Infinity>(), 1e-12);
  // The error estimator annihilates the clock (exact for y' = 1): e^T c = -gamma0.
  EXPECT_NEAR(t.error_weights.dot(t.c), -t.gamma0, 1e-12);
}

TEST_P(RadauTableauTest, InterpolantReproducesStagesAndPolynomials) {
  const int s = GetParam();
  const RadauTableau& t = RadauIIA(s);
  for (int i = 0; i < s; ++i) {
    const Vector w = t.InterpolationWeights(t.c[i]);
    for (int j = 0; j < s; ++j) EXPECT_NEAR(w[j], i == j ? 1.0 : 0.0, 1e-13);
  }
  // u(theta) = theta^s exactly (degree s polynomial through 0 and the nodes).
  Vector z(s);
  for (int j = 0; j < s; ++j) z[j] = std::pow(t.c[j], s);
  for (double theta : {0.25, 0.6, 1.3}) {
    EXPECT_NEAR(t.InterpolationWeights(theta).dot(z), std::pow(theta, s), 1e-12);
    EXPECT_NEAR(t.InterpolationDerivativeWeights(theta).dot(z), s * std::pow(theta, s - 1), 1e-11);
  }
}

INSTANTIATE_TEST_SUITE_P(Stages, RadauTableauTest, ::testing::Range(1, kMaxRadauStages + 1));

TEST(RadauTableauKnownValues, ThreeStageNodesAndWeights) {
  const RadauTableau& t = RadauIIA(3);
  const double r6 = std::sqrt(6.0);
  EXPECT_NEAR(t.c[0], (4 - r6) / 10, 1e-16);
  EXPECT_NEAR(t.c[1], (4 + r6) / 10, 1e-16);
  EXPECT_NEAR(t.b[0], (16 - r6) / 36, 1e-16);
  EXPECT_NEAR(t.b[1], (16 + r6) / 36, 1e-16);
  EXPECT_NEAR(t.b[2], 1.0 / 9, 1e-16);
  EXPECT_NEAR(t.a(0, 0), (88 - 7 * r6) / 360, 1e-16);
  EXPECT_NEAR(RadauIIA(2).c[0], 1.0 / 3, 1e-16);
  EXPECT_NEAR(RadauIIA(2).a(0, 1), -1.0 / 12, 1e-16);
  EXPECT_THROW(RadauIIA(0), std::invalid_argument);
  EXPECT_THROW(RadauIIA(kMaxRadauStages + 1), std::invalid_argument);
}

}  // namespace
}  // namespace moreau
