// The Hermite interpolant's extremum and lower bound (integrators/common/crossing_search.hpp):
// FESD's search between an element's nodes for free sides without interval bounds (index-1
// complementarity) samples the interpolant through the start and the stages, and skips the
// samples where the interpolant's Bernstein bound already clears the threshold.
#include "../../integrators/common/crossing_search.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace moreau::internal {
namespace {

// Samples of a fine grid: a stand-in for the interpolant's true minimum over [0, 1].
constexpr int kFineSamples = 1 << 14;

// Values and slopes of p at the nodes.
template <class P, class DP>
void Sample(const std::vector<double>& nodes, P p, DP dp, std::vector<double>* values,
            std::vector<double>* slopes) {
  values->clear();
  slopes->clear();
  for (double x : nodes) {
    values->push_back(p(x));
    slopes->push_back(dp(x));
  }
}

TEST(HermiteTest, TheInterpolantOfAPolynomialIsThePolynomial) {
  // p(x) = (x - 0.3)^2 - 0.01: degree 2 <= 2 n - 1, reproduced exactly; its minimum -0.01.
  const std::vector<double> nodes = {0.0, 0.5, 1.0};
  std::vector<double> values, slopes;
  Sample(
      nodes, [](double x) { return (x - 0.3) * (x - 0.3) - 0.01; },
      [](double x) { return 2.0 * (x - 0.3); }, &values, &slopes);
  double theta = 0.0;
  // The samples nearest 0.3 of the grid (k + 1/2) / 1000 are 0.2995 and 0.3005:
  // p = -0.01 + 2.5e-7 at both.
  EXPECT_NEAR(HermiteMinimum(nodes, values, slopes, 1000, &theta), -0.01 + 2.5e-7, 1e-14);
  EXPECT_NEAR(theta, 0.3, 5e-4 + 1e-12);
  EXPECT_LE(HermiteLowerBound(nodes, values, slopes), -0.01);
}

TEST(HermiteTest, TheLowerBoundIsBelowEverySample) {
  // Random data on the nodes an element has (its start and Radau IIA stages, s = 1..7): the
  // bound is never above the interpolant's fine samples.
  std::mt19937 random(7);
  std::uniform_real_distribution<double> value(-1.0, 1.0), slope(-20.0, 20.0);
  const std::vector<std::vector<double>> node_sets = {
      {0.0, 1.0},
      {0.0, 1.0 / 3.0, 1.0},
      {0.0, 0.155051025721682, 0.644948974278318, 1.0},
      {0.0, 0.0571041961145177, 0.276843013638124, 0.583590432368917, 0.860240135656219, 1.0},
      {0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 1.0}};
  for (const std::vector<double>& nodes : node_sets) {
    for (int trial = 0; trial < 200; ++trial) {
      std::vector<double> values, slopes;
      for (std::size_t i = 0; i < nodes.size(); ++i) {
        values.push_back(value(random));
        slopes.push_back(slope(random));
      }
      double theta = 0.0;
      const double fine = HermiteMinimum(nodes, values, slopes, kFineSamples, &theta);
      EXPECT_LE(HermiteLowerBound(nodes, values, slopes), fine)
          << nodes.size() << " nodes, trial " << trial;
    }
  }
}

TEST(HermiteTest, TheLowerBoundClearsAFreeSideFarFromZero) {
  // A diode current of 1 changing by 10% over the element (the common case: no switch near):
  // the bound is positive, so that the samples are skipped; and it is within the size of the
  // change of the true minimum (a bound that is useful, not merely safe).
  const std::vector<double> nodes = {0.0, 0.155051025721682, 0.644948974278318, 1.0};
  std::vector<double> values, slopes;
  Sample(
      nodes, [](double x) { return 1.0 - 0.1 * std::sin(3.0 * x); },
      [](double x) { return -0.3 * std::cos(3.0 * x); }, &values, &slopes);
  double theta = 0.0;
  const double minimum = HermiteMinimum(nodes, values, slopes, kFineSamples, &theta);
  const double bound = HermiteLowerBound(nodes, values, slopes);
  EXPECT_GT(bound, 0.0);
  EXPECT_LE(bound, minimum);
  EXPECT_GT(bound, minimum - 0.1);
}

// After a search, CrossingWorkspace::bounded says which watched functions have a finite lower
// bound over the whole step (FESD reads it to pick the functions its Hermite path checks,
// instead of bounding the element again). Functions on theta in [0, 1]: f0 = (theta - 0.5)^2
// + level (bounded: its enclosure over [a, b] from the endpoint values and the vertex), f1
// without an enclosure (-inf, +inf), f2 bounded but not watched. With level 0.1 the first bound
// clears f0 (no subdivision); with level -0.01 f0 dips below zero near 0.5, so the search
// subdivides and finds it, and the flags still describe the whole step.
TEST(SearchTest, TheWorkspaceSaysWhichWatchedFunctionsTheWholeStepBounds) {
  for (double level : {0.1, -0.01}) {
    auto f0 = [level](double theta) { return (theta - 0.5) * (theta - 0.5) + level; };
    auto values = [&](double theta, Vector* out) {
      *out = Vector::Constant(3, 1.0);
      (*out)[0] = f0(theta);
      return true;
    };
    auto bounds = [&](double a, double b, Vector* lower, Vector* upper) {
      const double inf = std::numeric_limits<double>::infinity();
      const double low = (a <= 0.5 && 0.5 <= b) ? level : std::min(f0(a), f0(b));
      *lower = Vector::Constant(3, -inf);
      *upper = Vector::Constant(3, inf);
      (*lower)[0] = low;
      (*upper)[0] = std::max(f0(a), f0(b));
      (*lower)[2] = 0.5;
      (*upper)[2] = 2.0;
    };
    const CrossingFunctionRefs functions{values, bounds};
    const std::vector<char> watched = {1, 1, 0};
    const Vector thresholds = Vector::Constant(3, 1e-9);
    CrossingWorkspace workspace;
    const Crossing crossing = SearchCrossing(watched, thresholds, functions, {}, &workspace);
    EXPECT_EQ(crossing.outcome, level > 0.0 ? CrossingOutcome::kNone : CrossingOutcome::kFound)
        << "level " << level;
    if (level > 0.0) {
      EXPECT_EQ(crossing.bound_evaluations, 1);
    }
    ASSERT_EQ(workspace.bounded.size(), 3u);
    EXPECT_EQ(workspace.bounded[0], 1) << "level " << level;
    EXPECT_EQ(workspace.bounded[1], 0) << "level " << level;
    EXPECT_EQ(workspace.bounded[2], 0) << "level " << level;  // bounded, but not watched
  }
}

}  // namespace
}  // namespace moreau::internal
