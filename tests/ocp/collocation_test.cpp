// The collocation transcription's NLP (ocp/collocation.hpp, private to moreau::ocp; docs/ocp.md,
// "Collocation transcription"): exact first derivatives against central differences, and a
// constraint Jacobian whose nonzeros grow linearly in N, and the full doorway solve (about 25 s
// of CPU in the release preset; skipped under the sanitizers, where it takes many minutes).
#include "../../ocp/collocation.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "moreau/ocp/catalog.hpp"
#include "moreau/ocp/ocp.hpp"

namespace moreau {
namespace {

using ocp_internal::CollocationNlp;

// The Jacobian as a dense matrix (IPOPT adds duplicate entries of the structure).
Matrix DenseJacobian(const CollocationNlp& nlp, const Vector& values) {
  Matrix dense = Matrix::Zero(nlp.num_constraints(), nlp.num_variables());
  const auto& structure = nlp.JacobianStructure();
  for (std::size_t i = 0; i < structure.size(); ++i) {
    dense(structure[i].first, structure[i].second) += values[static_cast<Eigen::Index>(i)];
  }
  return dense;
}

// Central differences with step kStep (relative to 1 + |z_i|): the NLP's functions are smooth
// (collocation equations, products, constraint values at fixed points; no integration inside),
// so truncation O(kStep^2) and rounding O(1e-16 / kStep) are both far below kTolerance.
constexpr double kStep = 1e-6;
// Agreement relative to the size of the derivative column (as for the shooting NLPs, issue 10).
constexpr double kTolerance = 1e-6;
// Variables checked per point, drawn with a fixed seed (all of them would take seconds under
// the sanitizers; every block type is among them at N = 20).
constexpr int kColumnsPerPoint = 120;

// The doorway's pushing plan (contacts active: nonzero multipliers, pieces on the walls) and two
// random perturbations of it.
TEST(OcpCollocation, ExactFirstDerivativesMatchCentralDifferences) {
  const OcpProblem problem = MakeOcpProblem("doorway");
  const OcpOptions options = MakeOcpOptions("doorway");
  ASSERT_EQ(options.transcription, OcpTranscription::kCollocation);
  CollocationNlp nlp(problem, options);
  nlp.SetRelaxedLevel(options.homotopy.front());
  std::mt19937 random(20261126);
  const Vector guess = nlp.InitialGuess();
  for (int trial = 0; trial < 3; ++trial) {
    Vector z = guess;
    if (trial > 0) {
      std::uniform_real_distribution<double> noise(-1e-2, 1e-2);
      for (Eigen::Index i = 0; i < z.size(); ++i) z[i] += noise(random) * (1.0 + std::abs(z[i]));
    }
    double objective = 0.0;
    Vector constraints, gradient, values;
    std::string message;
    ASSERT_TRUE(nlp.Evaluate(z, &objective, &constraints, &gradient, &values, &message)) << message;
    const Matrix jacobian = DenseJacobian(nlp, values);
    std::uniform_int_distribution<Eigen::Index> column(0, z.size() - 1);
    for (int draw = 0; draw < kColumnsPerPoint; ++draw) {
      const Eigen::Index i = column(random);
      const double step = kStep * (1.0 + std::abs(z[i]));
      Vector plus = z, minus = z;
      plus[i] += step;
      minus[i] -= step;
      double f_plus = 0.0, f_minus = 0.0;
      Vector c_plus, c_minus;
      ASSERT_TRUE(nlp.Evaluate(plus, &f_plus, &c_plus, nullptr, nullptr, &message)) << message;
      ASSERT_TRUE(nlp.Evaluate(minus, &f_minus, &c_minus, nullptr, nullptr, &message)) << message;
      const double scale =
          std::max({1.0, std::abs(gradient[i]), jacobian.col(i).lpNorm<Eigen::Infinity>()});
      EXPECT_NEAR((f_plus - f_minus) / (2.0 * step), gradient[i], kTolerance * scale)
          << "objective, variable " << i << ", trial " << trial;
      const Vector central = (c_plus - c_minus) / (2.0 * step);
      Eigen::Index row = 0;
      const double error = (central - jacobian.col(i)).cwiseAbs().maxCoeff(&row);
      EXPECT_LE(error, kTolerance * scale)
          << "variable " << i << ", trial " << trial << ", row " << row << ": exact "
          << jacobian(row, i) << ", central " << central[row];
    }
  }
}

// One element's blocks couple only its neighbours: the nonzeros grow exactly linearly in N.
TEST(OcpCollocation, JacobianNonzerosGrowLinearlyInTheIntervals) {
  std::vector<double> counts;
  for (int n : {20, 40, 80}) {
    OcpProblem problem = MakeOcpProblem("doorway");
    problem.intervals = n;
    problem.initial_controls.resize(0, 0);
    const CollocationNlp nlp(problem, MakeOcpOptions("doorway"));
    counts.push_back(static_cast<double>(nlp.JacobianStructure().size()));
  }
  EXPECT_DOUBLE_EQ(counts[2] - counts[1], 2.0 * (counts[1] - counts[0]));
}

// The doorway (`moreau ocp doorway`; docs/ocp.md, "Doorway"): solved on the exact level, the
// slider through the doorway, complementarity exact, and the re-simulations of the optimal
// controls agreeing with each other. Its IPOPT iterations were documented at 405 and silently
// became 501 after changes at round-off level elsewhere (another local optimum, objective
// 74.04 instead of 73.60): the bound guards against a path that gets materially longer.
// 501 measured at 6cd2ed1; about 20% margin.
constexpr int kDoorwayIterations = 600;
// The slider ends past the doorway (y = 0) near the target height 1 (the penalty balances it
// with the control cost at 0.995).
constexpr double kSliderThroughHeight = 0.9;
// Cross-complementarity products on the exact level: IPOPT's tolerance is 1e-10 on the
// scaled problem; measured 1e-14.
constexpr double kDoorwayComplementarity = 1e-9;
// IDA (rtol 1e-12) and FESD (10x finer grid) re-simulations of the same controls: measured
// 3.5e-11 apart (docs/ocp.md). Both are accurate far beyond this; what it excludes is IDA
// missing a contact (1.15e-4 before the hidden-root search, docs/ida.md).
constexpr double kResimulationsAgree = 1e-6;
// Distance of either re-simulation from the NLP's own x(T): 4.6e-4, the corner the
// transcription cuts between collocation points (docs/ocp.md, not fixed); guarded so that it
// cannot grow unnoticed.
constexpr double kNlpAgainstResimulation = 1e-3;

TEST(OcpCollocation, DoorwaySolvesOnTheExactLevel) {
#if MOREAU_SANITIZED
  GTEST_SKIP() << "the full doorway solve takes many minutes under the sanitizers";
#endif
  const OcpResult result = SolveOcp(MakeOcpProblem("doorway"), MakeOcpOptions("doorway"));
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;
  EXPECT_LE(result.stats.iterations, kDoorwayIterations);
  ASSERT_EQ(result.final_state.size(), 4);
  EXPECT_GT(result.final_state[1], kSliderThroughHeight);
  EXPECT_GE(result.complementarity_residual, 0.0);
  EXPECT_LE(result.complementarity_residual, kDoorwayComplementarity);
  ASSERT_TRUE(result.verified) << result.verification_message;
  ASSERT_TRUE(result.fesd_verified) << result.fesd_verification_message;
  EXPECT_LE((result.resimulated_final_state - result.fesd_resimulated_final_state).norm(),
            kResimulationsAgree);
  EXPECT_LE(result.resimulated_state_difference, kNlpAgainstResimulation);
  EXPECT_LE(result.fesd_resimulated_state_difference, kNlpAgainstResimulation);
}

// What the collocation transcription cannot take is refused by name.
TEST(OcpCollocation, RefusesWhatItCannotTranscribe) {
  OcpOptions options = MakeOcpOptions("doorway");
  EXPECT_THROW(CollocationNlp(MakeOcpProblem("turbo_car"), options), std::invalid_argument);
  OcpProblem doorway = MakeOcpProblem("doorway");
  options.homotopy = {};
  EXPECT_THROW(SolveOcp(doorway, options), std::invalid_argument);
}

}  // namespace
}  // namespace moreau
