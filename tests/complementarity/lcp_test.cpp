#include "moreau/complementarity/lcp.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "moreau/complementarity/ncp_function.hpp"

namespace moreau {
namespace {

// Acceptance: residual max_i |min(z_i, w_i)| <= 1e-12 for O(1) data.
constexpr double kResidual = 1e-12;
// Documented iteration bound for these LCP families (FB-Newton with active-set steps);
// measured maxima are well below (see the test output).
constexpr long kMaxIterations = 25;

TEST(NcpFunctionTest, FischerBurmeisterValuesAndGeneralizedJacobian) {
  EXPECT_EQ(FischerBurmeister(0.0, 0.0).value, 0.0);
  EXPECT_NEAR(FischerBurmeister(0.0, 0.0).da, 1.0 - std::sqrt(0.5), 1e-16);
  EXPECT_NEAR(FischerBurmeister(0.0, 0.0).db, 1.0 - std::sqrt(0.5), 1e-16);
  EXPECT_EQ(FischerBurmeister(2.0, 0.0).value, 0.0);
  EXPECT_EQ(FischerBurmeister(0.0, 3.0).value, 0.0);
  EXPECT_NEAR(FischerBurmeister(3.0, 4.0).value, 2.0, 1e-15);
  EXPECT_NEAR(FischerBurmeister(-3.0, 4.0).value, -4.0, 1e-15);
  const NcpValue v = FischerBurmeister(3.0, 4.0);
  EXPECT_NEAR(v.da, 1.0 - 0.6, 1e-16);
  EXPECT_NEAR(v.db, 1.0 - 0.8, 1e-16);
  // No cancellation for a large and b tiny: phi ~ b (exact 2ab / (a + b + r)).
  EXPECT_NEAR(FischerBurmeister(1e8, 1e-9).value, 1e-9, 1e-22);
  EXPECT_EQ(MinMap(1.0, 2.0).value, 1.0);
  EXPECT_EQ(MinMap(1.0, 2.0).da, 1.0);
  EXPECT_EQ(MinMap(3.0, 2.0).db, 1.0);
}

// A positive definite M = A^T A / n + (B - B^T) / sqrt(n) + 0.1 I (monotone, unique solution).
Matrix MonotoneMatrix(int n, std::mt19937* rng) {
  std::normal_distribution<double> normal;
  Matrix a(n, n), b(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      a(i, j) = normal(*rng);
      b(i, j) = normal(*rng);
    }
  }
  Matrix m = a.transpose() * a / n + (b - b.transpose()) / std::sqrt(static_cast<double>(n));
  m.diagonal().array() += 0.1;
  return m;
}

void ExpectSolved(const LcpResult& result, const Matrix& m, const Vector& q,
                  const std::string& label) {
  ASSERT_TRUE(result.z.allFinite() && result.w.allFinite()) << label << ": NaN in the result";
  EXPECT_TRUE(result.converged()) << label << ": " << result.message;
  EXPECT_LE(result.residual, kResidual) << label;
  EXPECT_LE((m * result.z + q - result.w).lpNorm<Eigen::Infinity>(), 1e-12) << label;
  EXPECT_LE(result.stats.iterations, kMaxIterations) << label << ": " << result.stats.Summary();
}

class MonotoneLcpTest : public ::testing::TestWithParam<int> {};

TEST_P(MonotoneLcpTest, SolvedToResidualWithinIterationBound) {
  const int n = GetParam();
  for (unsigned seed : {1u, 2u, 3u}) {
    std::mt19937 rng(seed * 1000u + static_cast<unsigned>(n));
    const Matrix m = MonotoneMatrix(n, &rng);
    std::normal_distribution<double> normal;
    Vector q(n);
    for (int i = 0; i < n; ++i) q[i] = normal(rng);
    const LcpResult result = SolveLcp(m, q);
    ExpectSolved(result, m, q, "n = " + std::to_string(n) + ", seed " + std::to_string(seed));
  }
}

INSTANTIATE_TEST_SUITE_P(Sizes, MonotoneLcpTest, ::testing::Values(10, 30, 100, 300, 1000));

class DegenerateLcpTest : public ::testing::TestWithParam<int> {};

TEST_P(DegenerateLcpTest, SolvedAtSolutionsWithBothSidesZero) {
  // Solution with a third of the indices degenerate (z_i = w_i = 0), built by choosing
  // (z*, w*) and q = w* - M z*.
  const int n = GetParam();
  for (unsigned seed : {11u, 12u}) {
    std::mt19937 rng(seed * 7919u + static_cast<unsigned>(n));
    const Matrix m = MonotoneMatrix(n, &rng);
    std::uniform_real_distribution<double> positive(0.5, 2.0);
    Vector z_star = Vector::Zero(n), w_star = Vector::Zero(n);
    for (int i = 0; i < n; ++i) {
      if (i % 3 == 0) z_star[i] = positive(rng);
      if (i % 3 == 1) w_star[i] = positive(rng);
    }
    const Vector q = w_star - m * z_star;
    const LcpResult result = SolveLcp(m, q);
    const std::string label = "n = " + std::to_string(n) + ", seed " + std::to_string(seed);
    ExpectSolved(result, m, q, label);
    // M positive definite: the solution is unique.
    EXPECT_LE((result.z - z_star).lpNorm<Eigen::Infinity>(), 1e-10) << label;
  }
}

INSTANTIATE_TEST_SUITE_P(Sizes, DegenerateLcpTest, ::testing::Values(10, 30, 100, 300));

TEST(LcpTest, MurtysProblem) {
  // M upper triangular with 1 on the diagonal and 2 above, q = -e: a P-matrix whose unique
  // solution is z = e_n (exponentially hard for Murty's/Bard's pivoting method). Damped
  // FB-Newton from z0 = 0 crosses a long plateau: it needs O(n) iterations (measured 13, 18,
  // 40, 89 for n = 8, 16, 32, 64), so the documented bound here is 1.5 n + 10.
  for (int n : {8, 16, 32, 64}) {
    Matrix m = Matrix::Zero(n, n);
    for (int i = 0; i < n; ++i) {
      m(i, i) = 1.0;
      for (int j = i + 1; j < n; ++j) m(i, j) = 2.0;
    }
    const Vector q = -Vector::Ones(n);
    SemismoothNewtonOptions options;
    options.max_iterations = 200;
    const LcpResult result = SolveLcp(m, q, options);
    ASSERT_TRUE(result.z.allFinite());
    EXPECT_TRUE(result.converged()) << "n = " << n << ": " << result.message;
    EXPECT_LE(result.residual, kResidual);
    EXPECT_LE(result.stats.iterations, 1.5 * n + 10) << result.stats.Summary();
    Vector expected = Vector::Zero(n);
    expected[n - 1] = 1.0;
    EXPECT_LE((result.z - expected).lpNorm<Eigen::Infinity>(), 1e-12) << "n = " << n;
  }
}

TEST(LcpTest, InfeasibleLcpEndsWithADocumentedStatus) {
  // w = -z - 1 can never be >= 0 for z >= 0: no solution. The solver must stop with a
  // status and a reason, finite iterates, and no exception.
  const Matrix m = -Matrix::Identity(3, 3);
  const Vector q = -Vector::Ones(3);
  const LcpResult result = SolveLcp(m, q);
  EXPECT_FALSE(result.converged());
  EXPECT_TRUE(result.z.allFinite());
  EXPECT_FALSE(result.message.empty());
}

// Kojima-Shindo NCP: 0 <= x ⟂ F(x) >= 0 with two solutions, (1, 0, 3, 0) (nondegenerate) and
// (sqrt(6)/2, 0, 0, 1/2) (degenerate: x_2 = F_2 = 0).
class KojimaShindo final : public MixedComplementaritySystem {
 public:
  int num_unknowns() const override { return 4; }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return 4; }
  bool Evaluate(const Vector& x, bool with_jacobian, Vector* r, Vector* a, Vector* b) override {
    r->resize(0);
    *a = x;
    if (with_jacobian) x_ = x;  // AssembleJacobian uses the last point with derivatives
    b->resize(4);
    (*b)[0] = 3 * x[0] * x[0] + 2 * x[0] * x[1] + 2 * x[1] * x[1] + x[2] + 3 * x[3] - 6;
    (*b)[1] = 2 * x[0] * x[0] + x[0] + x[1] * x[1] + 3 * x[2] + 2 * x[3] - 2;
    (*b)[2] = 3 * x[0] * x[0] + x[0] * x[1] + 2 * x[1] * x[1] + 2 * x[2] + 3 * x[3] - 1;
    (*b)[3] = x[0] * x[0] + 3 * x[1] * x[1] + 2 * x[2] + 3 * x[3] - 3;
    return true;
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    const Vector& x = x_;
    Matrix f(4, 4);
    f << 6 * x[0] + 2 * x[1], 2 * x[0] + 4 * x[1], 1, 3,  //
        4 * x[0] + 1, 2 * x[1], 3, 2,                     //
        6 * x[0] + x[1], x[0] + 4 * x[1], 2, 3,           //
        2 * x[0], 6 * x[1], 2, 3;
    Matrix j = db.asDiagonal() * f;
    j.diagonal() += da;
    jacobian->AddBlock(0, 0, j);
  }

 private:
  Vector x_;
};

TEST(SemismoothNewtonTest, KojimaShindoFromSeveralStarts) {
  SemismoothNewton newton;
  const Vector solutions[2] = {Vector{{1.0, 0.0, 3.0, 0.0}},
                               Vector{{std::sqrt(6.0) / 2, 0.0, 0.0, 0.5}}};
  for (const Vector& start :
       {Vector{{0.0, 0.0, 0.0, 0.0}}, Vector{{1.0, 1.0, 1.0, 1.0}}, Vector{{2.0, 0.5, 0.1, 1.0}}}) {
    KojimaShindo system;
    const SemismoothNewtonResult result = newton.Solve(system, start);
    ASSERT_TRUE(result.converged()) << result.message;
    const double distance =
        std::min((result.solution - solutions[0]).norm(), (result.solution - solutions[1]).norm());
    EXPECT_LE(distance, 1e-10) << result.solution.transpose();
    EXPECT_LE(result.complementarity_residual, kResidual);
    EXPECT_LE(result.stats.iterations, kMaxIterations) << result.stats.Summary();
  }
}

// defer_initial_jacobian: a guess that is a solution is accepted on values alone (no
// derivatives evaluated); any other guess gives exactly the iterates of the plain solve.
TEST(SemismoothNewtonTest, DeferredInitialJacobianOnlySkipsDerivativesAtASolution) {
  SemismoothNewtonOptions deferred_options;
  deferred_options.defer_initial_jacobian = true;
  SemismoothNewton plain, deferred(deferred_options);
  const Vector solution{{std::sqrt(6.0) / 2, 0.0, 0.0, 0.5}};  // to round-off
  KojimaShindo at_solution;
  const SemismoothNewtonResult accepted = deferred.Solve(at_solution, solution);
  ASSERT_TRUE(accepted.converged()) << accepted.message;
  EXPECT_EQ(accepted.stats.iterations, 0);
  EXPECT_EQ(accepted.stats.jacobian_evaluations, 0);
  EXPECT_EQ(accepted.solution, solution);
  for (const Vector& start : {Vector{{0.0, 0.0, 0.0, 0.0}}, Vector{{2.0, 0.5, 0.1, 1.0}}}) {
    KojimaShindo a, b;
    const SemismoothNewtonResult expected = plain.Solve(a, start);
    const SemismoothNewtonResult result = deferred.Solve(b, start);
    ASSERT_TRUE(expected.converged() && result.converged()) << expected.message << result.message;
    EXPECT_EQ(result.solution, expected.solution);  // bitwise: the same iterates
    EXPECT_EQ(result.residual_history, expected.residual_history);
    EXPECT_EQ(result.stats.residual_evaluations, expected.stats.residual_evaluations + 1);
  }
}

TEST(SemismoothNewtonTest, MinMapSolvesTheSameProblems) {
  SemismoothNewtonOptions options;
  options.ncp_function = NcpFunctionKind::kMin;
  std::mt19937 rng(5);
  const Matrix m = MonotoneMatrix(50, &rng);
  const Vector q = Vector::LinSpaced(50, -1.0, 1.0);
  const LcpResult fb = SolveLcp(m, q);
  const LcpResult min = SolveLcp(m, q, options);
  ASSERT_TRUE(fb.converged() && min.converged()) << fb.message << min.message;
  EXPECT_LE((fb.z - min.z).lpNorm<Eigen::Infinity>(), 1e-11);
}

// A sparse LCP: M tridiagonal (2.5 on the diagonal, -1 below, -0.8 above: strictly
// diagonally dominant, a P-matrix, so one solution), q_i = sin(0.37 i).
SparseMatrix TridiagonalMatrix(int n) {
  std::vector<Eigen::Triplet<double, int>> entries;
  for (int i = 0; i < n; ++i) {
    entries.emplace_back(i, i, 2.5);
    if (i > 0) entries.emplace_back(i, i - 1, -1.0);
    if (i + 1 < n) entries.emplace_back(i, i + 1, -0.8);
  }
  SparseMatrix m(n, n);
  m.setFromTriplets(entries.begin(), entries.end());
  return m;
}
Vector TridiagonalRightSide(int n) {
  Vector q(n);
  for (int i = 0; i < n; ++i) q[i] = std::sin(0.37 * i);
  return q;
}

TEST(SemismoothNewtonTest, SparseAndDenseLinearAlgebraAgree) {
  // A sparse monotone LCP (tridiagonal M, n = 2000) through KLU and through the dense LU.
  constexpr int n = 2000;
  const Matrix m = Matrix(TridiagonalMatrix(n));
  const Vector q = TridiagonalRightSide(n);
  SemismoothNewtonOptions dense_options, sparse_options;
  dense_options.linear_solver = LinearSolverKind::kDenseLu;
  sparse_options.linear_solver = LinearSolverKind::kSparseLu;
  const LcpResult dense = SolveLcp(m, q, dense_options);
  const LcpResult sparse = SolveLcp(m, q, sparse_options);
  ExpectSolved(dense, m, q, "dense");
  ExpectSolved(sparse, m, q, "sparse");
  EXPECT_LE((dense.z - sparse.z).lpNorm<Eigen::Infinity>(), 1e-12);
}

// The LCP 0 <= z _|_ M z + q >= 0 (TridiagonalMatrix, TridiagonalRightSide) as a mixed
// complementarity system, a = z and b = M z + q, with a sparse Jacobian.
class TridiagonalLcp final : public MixedComplementaritySystem {
 public:
  explicit TridiagonalLcp(int n) : m_(TridiagonalMatrix(n)), q_(TridiagonalRightSide(n)) {}
  int num_unknowns() const override { return static_cast<int>(q_.size()); }
  int num_equations() const override { return 0; }
  int num_pairs() const override { return num_unknowns(); }
  double EstimatedJacobianNonzeros() const override { return static_cast<double>(m_.nonZeros()); }
  bool Evaluate(const Vector& x, bool, Vector* r, Vector* a, Vector* b) override {
    r->resize(0);
    *a = x;
    *b = m_ * x + q_;
    return true;
  }
  void AssembleJacobian(const Vector& da, const Vector& db, SystemMatrix* jacobian) override {
    const SparseMatrix weighted = db.asDiagonal() * m_;
    jacobian->AddSparseBlock(0, 0, weighted);
    for (int i = 0; i < num_unknowns(); ++i) jacobian->AddEntry(i, i, da[i]);
  }

 private:
  SparseMatrix m_;
  Vector q_;
};

// One solver alternating between systems of two sizes (as FESD's fixed steps alternate between
// a step's elements and its error estimate's comparison element) keeps a linear solver per size:
// back at a size, it factorizes with the solver it used there before, and every solve gives the
// bits of a solver that never saw the other size.
TEST(SemismoothNewtonTest, AlternatingSizesKeepTheirLinearSolvers) {
  SemismoothNewtonOptions options;
  options.linear_solver = LinearSolverKind::kSparseLu;
  SemismoothNewton alternating(options);
  TridiagonalLcp large(3000), small(1000);
  long large_factorizations = 0, small_factorizations = 0;
  for (int round = 0; round < 3; ++round) {
    for (TridiagonalLcp* system : {&large, &small}) {
      const Vector start = Vector::Zero(system->num_unknowns());
      const SemismoothNewtonResult result = alternating.Solve(*system, start);
      SemismoothNewton fresh(options);
      const SemismoothNewtonResult expected = fresh.Solve(*system, start);
      ASSERT_TRUE(expected.converged()) << expected.message;
      ASSERT_TRUE(result.converged()) << result.message;
      EXPECT_EQ(result.solution, expected.solution) << "round " << round;  // bitwise
      EXPECT_EQ(result.residual_history, expected.residual_history) << "round " << round;
      // The kept solver has counted this size's factorizations of every round so far (a new
      // solver would count this round's only).
      long& count = system == &large ? large_factorizations : small_factorizations;
      count += expected.stats.factorizations;
      ASSERT_NE(alternating.last_jacobian_solver(), nullptr);
      EXPECT_EQ(alternating.last_jacobian_solver()->num_factorizations(), count)
          << "round " << round;
    }
  }
}

// r(w) = (w_1 - 5, w_2 - 5) with a Jacobian reported as c [1 1; 1 1] (singular, c = 0.05):
// no Newton direction exists, and steepest descent on the merit reduces |r_1 + r_2| by the
// factor 1 - 2c per step, a decrease of the merit by 19% per step that the window test never
// calls stagnation, but 1e-12 is 270 steps away. The solve must stop after the documented
// streak of steepest-descent steps (8) with kStagnated, not run to max_iterations.
class SingularJacobianSystem final : public MixedComplementaritySystem {
 public:
  int num_unknowns() const override { return 2; }
  int num_equations() const override { return 2; }
  int num_pairs() const override { return 0; }
  bool Evaluate(const Vector& w, bool /*with_jacobian*/, Vector* r, Vector* a, Vector* b) override {
    *r = w.array() - 5.0;
    a->resize(0);
    b->resize(0);
    return true;
  }
  void AssembleJacobian(const Vector& /*da*/, const Vector& /*db*/,
                        SystemMatrix* jacobian) override {
    jacobian->AddBlock(0, 0, Matrix::Constant(2, 2, 0.05));
  }
};

TEST(SemismoothNewtonTest, SteepestDescentCrawlEndsAsStagnated) {
  // The streak after which the solve stops (kMaxGradientStreak in semismooth_newton.cpp), before
  // another factorization.
  constexpr long kGradientStreak = 8;
  SingularJacobianSystem system;
  SemismoothNewton newton;  // max_iterations = 100
  const SemismoothNewtonResult result = newton.Solve(system, Vector::Zero(2));
  EXPECT_EQ(result.status, NewtonStatus::kStagnated) << result.message;
  EXPECT_NE(result.message.find("no Newton descent direction"), std::string::npos)
      << result.message;
  EXPECT_EQ(result.stats.gradient_steps, kGradientStreak) << result.stats.Summary();
  EXPECT_EQ(result.stats.iterations, kGradientStreak) << result.stats.Summary();
  // Every step decreased the residual (a crawl, not a failure of the line search).
  for (std::size_t k = 1; k < result.residual_history.size(); ++k) {
    EXPECT_LT(result.residual_history[k], result.residual_history[k - 1]);
  }
}

TEST(SemismoothNewtonTest, InvalidOptionsAreRejected) {
  SemismoothNewtonOptions options;
  options.tolerance = 0.0;
  EXPECT_THROW(SemismoothNewton{options}, std::invalid_argument);
  options = {};
  options.armijo = 0.7;
  EXPECT_THROW(SemismoothNewton{options}, std::invalid_argument);
  EXPECT_THROW(SolveLcp(Matrix::Identity(2, 2), Vector::Ones(3)), std::invalid_argument);
}

}  // namespace
}  // namespace moreau
