#include "moreau/linalg/linear_solver.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace moreau {
namespace {

// A diagonally dominant random sparse matrix (about 5 nonzeros per row), well conditioned.
SystemMatrix RandomSparse(int n, bool sparse, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::uniform_int_distribution<int> column(0, n - 1);
  SystemMatrix a;
  a.Reset(n, sparse);
  for (int i = 0; i < n; ++i) {
    a.AddEntry(i, i, 6.0);
    for (int k = 0; k < 4; ++k) a.AddEntry(i, column(rng), value(rng));
  }
  a.Finalize();
  return a;
}

// Agreement of two backward-stable LU solves of a well-conditioned system (cond ~ 10):
// a few hundred ulps of O(1) solutions.
constexpr double kAgreement = 1e-13;

// Both sparse backends: UMFPACK (LinearSolverKind::kSparseLu) and KLU.
const LinearSolverKind kSparseKinds[] = {LinearSolverKind::kSparseLu, LinearSolverKind::kKlu};

TEST(LinearSolverTest, DenseAndSparseAgreeOnLargeSparseSystem) {
  constexpr int n = 3000;
  const SystemMatrix dense = RandomSparse(n, false, 7);
  const SystemMatrix sparse = RandomSparse(n, true, 7);
  auto dense_lu = MakeLinearSolver(LinearSolverKind::kDenseLu, n, n * n);
  ASSERT_EQ(dense_lu->Factorize(dense), FactorizationStatus::kSuccess);
  const Vector b = Vector::LinSpaced(n, -1.0, 2.0);
  Vector x_dense = b, t_dense = b;
  dense_lu->Solve(x_dense);
  dense_lu->SolveTransposed(t_dense);
  for (LinearSolverKind kind : kSparseKinds) {
    auto lu = MakeLinearSolver(kind, n, 5.0 * n);
    ASSERT_EQ(lu->kind(), kind);
    ASSERT_EQ(lu->Factorize(sparse), FactorizationStatus::kSuccess) << ToString(kind);
    Vector x_sparse = b;
    lu->Solve(x_sparse);
    EXPECT_LE((x_dense - x_sparse).lpNorm<Eigen::Infinity>(), kAgreement) << ToString(kind);
    EXPECT_LE((sparse.Multiply(x_sparse) - b).lpNorm<Eigen::Infinity>(), kAgreement)
        << ToString(kind);
    // Transposed solves agree too.
    Vector t_sparse = b;
    lu->SolveTransposed(t_sparse);
    EXPECT_LE((t_dense - t_sparse).lpNorm<Eigen::Infinity>(), kAgreement) << ToString(kind);
    // Several right-hand sides at once.
    Matrix several(n, 2);
    several << b, 2.0 * b;
    lu->SolveMatrix(several);
    EXPECT_LE((several.col(1) - 2.0 * x_dense).lpNorm<Eigen::Infinity>(), 2.0 * kAgreement);
  }
}

// A saddle-point matrix [I  J^T; J  0] (a zero diagonal block, as the multipliers of active
// constraints give): both backends solve it; the solution is checked by its residual.
TEST(LinearSolverTest, SaddlePointSystems) {
  constexpr int n = 400, m = 150;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::uniform_int_distribution<int> column(0, n - 1);
  SystemMatrix a;
  a.Reset(n + m, true);
  for (int i = 0; i < n; ++i) a.AddEntry(i, i, 1.0);
  for (int k = 0; k < m; ++k) {
    a.AddEntry(n + k, k, 1.0);  // full row rank: column k of the identity plus noise
    for (int e = 0; e < 3; ++e) {
      const int j = column(rng);
      const double v = value(rng);
      a.AddEntry(n + k, j, v);
      a.AddEntry(j, n + k, v);
    }
    a.AddEntry(k, n + k, 1.0);
  }
  a.Finalize();
  const Vector b = Vector::LinSpaced(n + m, 1.0, -1.0);
  for (LinearSolverKind kind : kSparseKinds) {
    auto lu = MakeLinearSolver(kind, n + m, 7.0 * (n + m));
    ASSERT_EQ(lu->Factorize(a), FactorizationStatus::kSuccess) << ToString(kind);
    Vector x = b;
    lu->Solve(x);
    EXPECT_LE((a.Multiply(x) - b).lpNorm<Eigen::Infinity>(), 1e-11) << ToString(kind);
  }
}

// The k x k grid's five-point pattern with O(1) neighbour couplings of random sign and the
// given diagonal entries. With 1e-6 there, KLU's threshold pivoting (0.001 of the column)
// refuses every diagonal pivot the AMD ordering counted on, and fills in (k = 40: 6.4 times
// the entries the ordering estimated); with 5 (diagonally dominant) it keeps to the ordering.
SystemMatrix Grid(int k, double diagonal) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> magnitude(0.5, 1.0);
  SystemMatrix a;
  a.Reset(k * k, true);
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j < k; ++j) {
      const int row = i * k + j;
      a.AddEntry(row, row, diagonal);
      for (const int column : {j > 0 ? row - 1 : -1, j + 1 < k ? row + 1 : -1, i > 0 ? row - k : -1,
                               i + 1 < k ? row + k : -1}) {
        if (column >= 0) a.AddEntry(row, column, (rng() % 2 == 0 ? 1.0 : -1.0) * magnitude(rng));
      }
    }
  }
  a.Finalize();
  return a;
}

Vector SolveWith(LinearSolver* lu, const SystemMatrix& a, const Vector& b) {
  EXPECT_EQ(lu->Factorize(a), FactorizationStatus::kSuccess);
  Vector x = b;
  lu->Solve(x);
  return x;
}

// kAutomatic above kDenseSizeLimit: KLU while its factorizations keep to their ordering (the
// same bits as KLU on request, first factorization), UMFPACK from the first that fills in
// (the same bits as UMFPACK), and UMFPACK thereafter.
TEST(LinearSolverTest, AutomaticSparseLuHandsOverToUmfpackWhenKluFillsIn) {
  const SystemMatrix sound = Grid(40, 5.0);
  const SystemMatrix filling = Grid(40, 1e-6);
  const int n_sound = sound.size(), n_filling = filling.size();
  ASSERT_GT(n_filling, kDenseSizeLimit);
  auto solve = [](LinearSolverKind kind, const SystemMatrix& a) {
    auto lu = MakeLinearSolver(kind, a.size(), 5.0 * a.size());
    return SolveWith(lu.get(), a, Vector::LinSpaced(a.size(), -1.0, 2.0));
  };
  const Vector b_sound = Vector::LinSpaced(n_sound, -1.0, 2.0);
  const Vector b_filling = Vector::LinSpaced(n_filling, -1.0, 2.0);

  auto automatic = MakeLinearSolver(LinearSolverKind::kAutomatic, n_sound, 5.0 * n_sound);
  EXPECT_EQ(automatic->kind(), LinearSolverKind::kKlu);
  const Vector x_sound = SolveWith(automatic.get(), sound, b_sound);
  EXPECT_TRUE(x_sound == solve(LinearSolverKind::kKlu, sound));
  EXPECT_LE((sound.Multiply(x_sound) - b_sound).lpNorm<Eigen::Infinity>(), kAgreement);

  // The filling matrix: KLU's own solution differs from UMFPACK's (else the test could not
  // tell them apart); the automatic solver gives UMFPACK's, with a small residual.
  const Vector x_klu = solve(LinearSolverKind::kKlu, filling);
  const Vector x_umfpack = solve(LinearSolverKind::kSparseLu, filling);
  ASSERT_FALSE(x_klu == x_umfpack);
  const Vector x_filling = SolveWith(automatic.get(), filling, b_filling);
  EXPECT_TRUE(x_filling == x_umfpack);
  // Normwise backward error |A x - b| / (|A| |x| + |b|) of UMFPACK with its iterative
  // refinement: at most a few ulps (measured 2.9e-17; KLU's own solution has 1.7e-14).
  constexpr double kBackwardError = 4.0 * std::numeric_limits<double>::epsilon();
  EXPECT_LE((filling.Multiply(x_filling) - b_filling).lpNorm<Eigen::Infinity>(),
            kBackwardError * (filling.InfinityNorm() * x_filling.lpNorm<Eigen::Infinity>() +
                              b_filling.lpNorm<Eigen::Infinity>()));
  Vector t_filling = b_filling, t_umfpack = b_filling;
  automatic->SolveTransposed(t_filling);
  auto umfpack = MakeLinearSolver(LinearSolverKind::kSparseLu, n_filling, 5.0 * n_filling);
  ASSERT_EQ(umfpack->Factorize(filling), FactorizationStatus::kSuccess);
  umfpack->SolveTransposed(t_umfpack);
  EXPECT_TRUE(t_filling == t_umfpack);

  // The hand-over is kept: the sound matrix now goes to UMFPACK too.
  EXPECT_TRUE(SolveWith(automatic.get(), sound, b_sound) ==
              solve(LinearSolverKind::kSparseLu, sound));
  EXPECT_EQ(automatic->num_factorizations(), 3);
}

// kAutomatic above kDenseSizeLimit gives a matrix whose ordering already predicts more than
// ten times its entries in L + U to UMFPACK before KLU factorizes it: a random sparse matrix
// of 3000 rows with five entries each is estimated at 135 times its entries (a grid's
// five-point pattern, as above, stays below ten).
TEST(LinearSolverTest, AutomaticSparseLuGivesUmfpackWhatTheOrderingPredictsToFill) {
  const SystemMatrix a = RandomSparse(3000, true, 11);
  const Vector b = Vector::LinSpaced(a.size(), -1.0, 2.0);
  auto solve = [&](LinearSolverKind kind) {
    auto lu = MakeLinearSolver(kind, a.size(), 5.0 * a.size());
    return SolveWith(lu.get(), a, b);
  };
  const Vector x_umfpack = solve(LinearSolverKind::kSparseLu);
  ASSERT_FALSE(solve(LinearSolverKind::kKlu) == x_umfpack);  // else the test tells nothing
  auto automatic = MakeLinearSolver(LinearSolverKind::kAutomatic, a.size(), 5.0 * a.size());
  EXPECT_EQ(automatic->kind(), LinearSolverKind::kKlu);
  EXPECT_TRUE(SolveWith(automatic.get(), a, b) == x_umfpack);
  EXPECT_EQ(automatic->num_factorizations(), 1);
}

TEST(LinearSolverTest, RefactorizationWithSamePattern) {
  constexpr int n = 500;
  for (LinearSolverKind kind : kSparseKinds) {
    auto lu = MakeLinearSolver(kind, n, 5.0 * n);
    for (unsigned seed : {1u, 1u, 2u}) {  // same pattern twice (refactor), then a new pattern
      const SystemMatrix a = RandomSparse(n, true, seed);
      ASSERT_EQ(lu->Factorize(a), FactorizationStatus::kSuccess);
      Vector x = Vector::Ones(n);
      lu->Solve(x);
      EXPECT_LE((a.Multiply(x) - Vector::Ones(n)).lpNorm<Eigen::Infinity>(), kAgreement)
          << ToString(kind);
    }
    EXPECT_EQ(lu->num_factorizations(), 3);
  }
}

// The dense LU has a kernel of its own for small systems and Eigen's blocked LU for larger
// ones: both must pivot (random dense matrices, not diagonally dominant) and solve plain,
// transposed and multiple right-hand sides. Sizes on both sides of the switch (64).
TEST(LinearSolverTest, DenseLuSolvesRandomDenseSystemsOfAllSizes) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  for (int n : {1, 2, 5, 16, 63, 64, 65, 100}) {
    Matrix m(n, n);
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) m(i, j) = value(rng);
    }
    if (n > 1) m(0, 0) = 0.0;  // the first column needs a row swap
    SystemMatrix a;
    a.Reset(n, false);
    a.AddBlock(0, 0, m);
    a.Finalize();
    auto lu = MakeLinearSolver(LinearSolverKind::kDenseLu, n, 1.0 * n * n);
    ASSERT_EQ(lu->Factorize(a), FactorizationStatus::kSuccess) << "n = " << n;
    // Backward-stable solves of random matrices (cond up to ~1e3 here): residuals of a few
    // thousand ulps of the O(1) right-hand side.
    const double tolerance = 1e-11;
    const Vector b = Vector::LinSpaced(n, -1.0, 2.0);
    Vector x = b, t = b;
    lu->Solve(x);
    lu->SolveTransposed(t);
    EXPECT_LE((m * x - b).lpNorm<Eigen::Infinity>(), tolerance) << "n = " << n;
    EXPECT_LE((m.transpose() * t - b).lpNorm<Eigen::Infinity>(), tolerance) << "n = " << n;
    Matrix rhs(n, 2);
    rhs.col(0) = b;
    rhs.col(1) = -2.0 * b;
    lu->SolveMatrix(rhs);
    EXPECT_LE((rhs.col(0) - x).lpNorm<Eigen::Infinity>(), tolerance) << "n = " << n;
    EXPECT_LE((rhs.col(1) + 2.0 * x).lpNorm<Eigen::Infinity>(), tolerance) << "n = " << n;
  }
}

TEST(LinearSolverTest, SingularAndNonFiniteMatricesAreReported) {
  for (LinearSolverKind kind :
       {LinearSolverKind::kDenseLu, LinearSolverKind::kSparseLu, LinearSolverKind::kKlu}) {
    const bool sparse = kind != LinearSolverKind::kDenseLu;
    SystemMatrix a;
    a.Reset(3, sparse);
    a.AddEntry(0, 0, 1.0);
    a.AddEntry(1, 1, 1.0);
    a.AddEntry(2, 0, 1.0);  // third row equals the first: rank 2
    a.AddEntry(0, 2, 0.0);
    a.AddEntry(2, 2, 0.0);
    a.Finalize();
    auto solver = MakeLinearSolver(kind, 3, 9);
    EXPECT_EQ(solver->Factorize(a), FactorizationStatus::kSingular) << ToString(kind);
    SystemMatrix b;
    b.Reset(2, sparse);
    b.AddEntry(0, 0, std::numeric_limits<double>::quiet_NaN());
    b.AddEntry(1, 1, 1.0);
    b.Finalize();
    EXPECT_EQ(solver->Factorize(b), FactorizationStatus::kNonFinite) << ToString(kind);
  }
}

// Unknowns in different units: a well-conditioned matrix with its columns scaled by powers of
// two from 2^-40 to 2^40 (1e-12 to 1e12, as an element length of 1e-6 s beside multipliers of
// 1e6) is not singular for the dense LU, and its solution is the unscaled one scaled back
// (partial pivoting is exact under power-of-two column scaling: the same pivots, the same
// rounding); with a column that repeats another (times 2^30) the matrix stays singular. Sizes
// 10 and 40 take the small-system loops, 70 Eigen's blocked LU (above 64 unknowns).
TEST(LinearSolverTest, DenseColumnScalesAreNotSingularity) {
  for (int n : {10, 40, 70}) {
    const SystemMatrix base = RandomSparse(n, /*sparse=*/false, 7);
    Vector scales(n);
    for (int j = 0; j < n; ++j) scales[j] = std::ldexp(1.0, -40 + (80 * j) / (n - 1));
    const Matrix& dense = base.dense();
    SystemMatrix scaled, singular;
    scaled.Reset(n, false);
    singular.Reset(n, false);
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        if (dense(i, j) == 0.0) continue;
        scaled.AddEntry(i, j, dense(i, j) * scales[j]);
        // Column n - 1 becomes 2^30 times column 0 (scaled): rank n - 1.
        if (j != n - 1) singular.AddEntry(i, j, dense(i, j) * scales[j]);
        if (j == 0) singular.AddEntry(i, n - 1, dense(i, 0) * scales[0] * std::ldexp(1.0, 30));
      }
    }
    scaled.Finalize();
    singular.Finalize();
    auto solver = MakeLinearSolver(LinearSolverKind::kDenseLu, n, 5.0 * n);
    ASSERT_EQ(solver->Factorize(scaled), FactorizationStatus::kSuccess) << "n = " << n;
    Vector x = Vector::LinSpaced(n, -1.0, 1.0);
    Vector rhs = dense * x;
    solver->Solve(rhs);
    EXPECT_LE((rhs.cwiseProduct(scales) - x).lpNorm<Eigen::Infinity>(), kAgreement) << "n = " << n;
    EXPECT_EQ(solver->Factorize(singular), FactorizationStatus::kSingular) << "n = " << n;
  }
}

TEST(LinearSolverTest, AutomaticChoiceBySizeAndDensity) {
  EXPECT_EQ(MakeLinearSolver(LinearSolverKind::kAutomatic, 100, 1e4)->kind(),
            LinearSolverKind::kDenseLu);
  EXPECT_EQ(MakeLinearSolver(LinearSolverKind::kAutomatic, 5000, 5e4)->kind(),
            LinearSolverKind::kKlu);
  EXPECT_EQ(MakeLinearSolver(LinearSolverKind::kAutomatic, 5000, 5000.0 * 5000)->kind(),
            LinearSolverKind::kDenseLu);
  EXPECT_EQ(ParseLinearSolverKind("klu"), LinearSolverKind::kKlu);
  EXPECT_THROW(ParseLinearSolverKind("cholesky"), std::invalid_argument);
}

}  // namespace
}  // namespace moreau
