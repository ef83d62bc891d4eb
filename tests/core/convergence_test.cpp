#include "moreau/core/convergence.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

namespace moreau {
namespace {

// The fit works on logarithms of the data: log(C h^p) carries a relative rounding error of a
// few ulps of |log e| <= 60, and the slope divides by a spread of log h of order one. 1e-10
// is far above that (~1e-13) and far below anything a convergence study resolves.
constexpr double kExactFitTolerance = 1e-10;

// h_k = 0.1 / 2^k, k = 0..n-1: the halving sequences the studies use.
std::vector<double> Halving(int n) {
  std::vector<double> h;
  for (int k = 0; k < n; ++k) h.push_back(0.1 / std::pow(2.0, k));
  return h;
}

std::vector<double> PowerLaw(const std::vector<double>& h, double constant, double order) {
  std::vector<double> e;
  for (double step : h) e.push_back(constant * std::pow(step, order));
  return e;
}

// Deterministic uniform numbers in [-1, 1] (64-bit LCG, Knuth's MMIX constants), the same on
// every platform (std::uniform_real_distribution is not specified bit for bit).
class Uniform {
 public:
  explicit Uniform(std::uint64_t seed) : state_(seed) {}
  double Next() {
    state_ = state_ * 6364136223846793005ULL + 1442695040888963407ULL;
    return 2.0 * static_cast<double>(state_ >> 11) / 9007199254740992.0 - 1.0;
  }

 private:
  std::uint64_t state_;
};

TEST(FitOrderTest, ExactPowerLawsRecoverTheirOrderAndConstant) {
  const std::vector<double> h = Halving(5);
  for (double order : {0.5, 1.0, 2.0, 3.0, 5.0, 7.0}) {
    for (double constant : {1e-3, 1.0, 40.0}) {
      const OrderFit fit = FitOrder(h, PowerLaw(h, constant, order), 0.0);
      EXPECT_EQ(fit.points_used, 5) << "p = " << order;
      EXPECT_NEAR(fit.order, order, kExactFitTolerance) << "C = " << constant;
      EXPECT_NEAR(fit.constant, std::log(constant), kExactFitTolerance) << "p = " << order;
    }
  }
  // Unevenly spaced, unsorted step sizes are fine too.
  const std::vector<double> uneven = {0.013, 0.3, 0.0021, 0.07};
  EXPECT_NEAR(FitOrder(uneven, PowerLaw(uneven, 2.0, 3.0), 0.0).order, 3.0, kExactFitTolerance);
}

TEST(FitOrderTest, PairwiseOrdersOfAnExactPowerLawAreTheOrder) {
  const std::vector<double> h = Halving(5);
  const std::vector<double> orders = PairwiseOrders(h, PowerLaw(h, 3.0, 5.0));
  ASSERT_EQ(orders.size(), 4u);
  for (double p : orders) EXPECT_NEAR(p, 5.0, kExactFitTolerance);
  EXPECT_TRUE(PairwiseOrders({0.1}, {1.0}).empty());
}

// A fifth-order method whose error saturates at round-off: the points at or below the floor
// must not enter the fit.
TEST(FitOrderTest, PointsAtOrBelowTheFloorAreExcluded) {
  constexpr double kFloor = 1e-12;
  const std::vector<double> h = Halving(7);
  std::vector<double> e = PowerLaw(h, 1.0, 5.0);  // 1e-5 ... 1.5e-14
  // Round-off plateau: the last three points sit at or below the floor.
  e[4] = kFloor;  // exactly at the floor: excluded ("at or below")
  e[5] = 8e-13;
  e[6] = 9e-13;
  const OrderFit fit = FitOrder(h, e, kFloor);
  EXPECT_EQ(fit.points_used, 4);
  EXPECT_NEAR(fit.order, 5.0, kExactFitTolerance);
  // Without the floor the plateau drags the slope down (to 4.31 here): the floor is what makes
  // the fit meaningful.
  EXPECT_LT(FitOrder(h, e, 0.0).order, 4.5);
}

TEST(FitOrderTest, NonFiniteErrorsAreExcluded) {
  const std::vector<double> h = Halving(5);
  std::vector<double> e = PowerLaw(h, 2.0, 3.0);
  e[1] = std::numeric_limits<double>::quiet_NaN();
  e[3] = std::numeric_limits<double>::infinity();
  const OrderFit fit = FitOrder(h, e, 0.0);
  EXPECT_EQ(fit.points_used, 3);
  EXPECT_NEAR(fit.order, 3.0, kExactFitTolerance);
}

TEST(FitOrderTest, TooFewDistinctPointsGiveNoOrder) {
  EXPECT_LT(FitOrder({}, {}, 0.0).points_used, 2);
  EXPECT_LT(FitOrder({0.1}, {1e-3}, 0.0).points_used, 2);
  // Two points, one below the floor.
  EXPECT_LT(FitOrder({0.1, 0.05}, {1e-3, 1e-15}, 1e-12).points_used, 2);
  // All step sizes equal: no slope can be fitted.
  EXPECT_LT(FitOrder({0.1, 0.1, 0.1}, {1e-3, 2e-3, 3e-3}, 0.0).points_used, 2);
}

// Multiplicative noise e_k = C h_k^p (1 + delta_k) with |delta_k| <= delta perturbs log e_k by
// eps_k with |eps_k| <= eta = -log(1 - delta). The least-squares slope is
// p + sum (x_k - xbar) eps_k / sum (x_k - xbar)^2 (x = log h), so
//   |fitted - p| <= eta sum |x_k - xbar| / sum (x_k - xbar)^2.
// For five halvings this is 0.866 eta: 10% noise (eta = 0.105) moves the order by at most 0.091.
double NoiseBound(const std::vector<double>& h, double delta) {
  double mean = 0.0;
  for (double step : h) mean += std::log(step);
  mean /= static_cast<double>(h.size());
  double absolute = 0.0, squares = 0.0;
  for (double step : h) {
    absolute += std::fabs(std::log(step) - mean);
    squares += (std::log(step) - mean) * (std::log(step) - mean);
  }
  return -std::log(1.0 - delta) * absolute / squares;
}

TEST(FitOrderTest, NoiseOfKnownSizeKeepsTheOrderWithinTheBound) {
  const std::vector<double> h = Halving(5);
  constexpr double kNoise = 0.1;
  const double bound = NoiseBound(h, kNoise);
  EXPECT_NEAR(bound, 0.866 * -std::log(0.9), 1e-3);  // the value quoted above
  Uniform uniform(20240601);
  for (double order : {1.0, 3.0, 5.0, 7.0}) {
    for (int trial = 0; trial < 200; ++trial) {
      std::vector<double> e = PowerLaw(h, 0.5, order);
      for (double& value : e) value *= 1.0 + kNoise * uniform.Next();
      const OrderFit fit = FitOrder(h, e, 0.0);
      ASSERT_EQ(fit.points_used, 5);
      EXPECT_LE(std::fabs(fit.order - order), bound + kExactFitTolerance)
          << "p = " << order << ", trial " << trial;
    }
  }
  // The bound is sharp for log-perturbations |eps_k| <= eta: eps_k = -eta on the coarse half
  // and +eta on the fine half (against the sign of x_k - xbar) tilts the line by exactly the
  // bound towards lower orders.
  std::vector<double> worst = PowerLaw(h, 0.5, 3.0);
  const double eta = -std::log(1.0 - kNoise);
  for (std::size_t k = 0; k < h.size(); ++k) {
    if (k < 2) worst[k] *= std::exp(-eta);
    if (k > 2) worst[k] *= std::exp(eta);
  }
  EXPECT_NEAR(FitOrder(h, worst, 0.0).order, 3.0 - bound, kExactFitTolerance);
}

TEST(FitOrderTest, BadInputThrows) {
  EXPECT_THROW(FitOrder({0.1, 0.05}, {1e-3}, 0.0), std::invalid_argument);
  EXPECT_THROW(FitOrder({0.1, 0.0}, {1e-3, 1e-4}, 0.0), std::invalid_argument);
  EXPECT_THROW(FitOrder({0.1, -0.05}, {1e-3, 1e-4}, 0.0), std::invalid_argument);
  // A non-positive step size is bad input even where its error would be excluded by the floor.
  EXPECT_THROW(FitOrder({0.1, 0.05, -0.01}, {1e-3, 1e-4, 1e-20}, 1e-12), std::invalid_argument);
  EXPECT_THROW(PairwiseOrders({0.1, 0.05}, {1e-3}), std::invalid_argument);
  try {
    FitOrder({0.1, 0.05, 0.025}, {1e-3, 1e-4}, 0.0);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("3 step sizes but 2 errors"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace moreau
