// Sparse exact derivatives (SmoothFunction::SparseJacobian, SparseWeightedHessian;
// docs/sparse-derivatives.md): equal to the dense forward-mode AD on every model function of
// every catalog scene and example scene file, with fixed patterns, empty Hessian patterns for
// affine functions, point-dependent branches handled soundly, and cost that follows the true
// nonzeros (colours, not inputs).
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "../../lib/core/thread_pool.hpp"
#include "moreau/core/smooth_function.hpp"
#include "moreau/model/scene.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

#ifndef MOREAU_EXAMPLES_DIR
#error "MOREAU_EXAMPLES_DIR must name examples/ (tests/CMakeLists.txt)"
#endif

namespace moreau {
namespace {

// The sparse and the dense derivatives run the same dual-number operations on every path from
// an input to an output (a compressed direction carries one input per output, the others
// contribute exact zeros), and both accumulate weighted Hessians over outputs in increasing
// order: they agree to a few ulps of the entry. 1e-14 relative to max(1, |entry|) leaves room
// for a differently rounded association without hiding a wrong entry (O(1) or missing).
constexpr double kDerivativeTolerance = 1e-14;

std::vector<int> AllRows(int m) {
  std::vector<int> rows(static_cast<std::size_t>(m));
  for (int k = 0; k < m; ++k) rows[static_cast<std::size_t>(k)] = k;
  return rows;
}

std::string WrtName(Wrt wrt) { return wrt.p ? "All" : (wrt.u ? "XUT" : (wrt.t ? "XT" : "X")); }

struct Point {
  Vector x, u, p;
  double t = 0.0;
};

// Asserts |a - b| <= tolerance (1 + |b|) entrywise, naming the worst entry.
void ExpectClose(const Matrix& sparse, const Matrix& dense, const std::string& what) {
  ASSERT_EQ(sparse.rows(), dense.rows()) << what;
  ASSERT_EQ(sparse.cols(), dense.cols()) << what;
  if (dense.size() == 0) return;
  // Error relative to the bound, entrywise; NaN (a wrong or missing entry) compares false.
  const Matrix excess =
      (sparse - dense)
          .cwiseAbs()
          .cwiseQuotient((kDerivativeTolerance * (1.0 + dense.array().abs())).matrix());
  Eigen::Index i = 0, j = 0;
  const double worst = excess.maxCoeff(&i, &j);
  ASSERT_TRUE(worst <= 1.0 && sparse.allFinite() == dense.allFinite())
      << what << ": entry (" << i << ", " << j << ") sparse " << sparse(i, j) << " dense "
      << dense(i, j);
}

bool SamePattern(const SparseMatrix& a, const SparseMatrix& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols() || a.nonZeros() != b.nonZeros()) return false;
  for (Eigen::Index j = 0; j <= a.cols(); ++j) {
    if (a.outerIndexPtr()[j] != b.outerIndexPtr()[j]) return false;
  }
  for (Eigen::Index e = 0; e < a.nonZeros(); ++e) {
    if (a.innerIndexPtr()[e] != b.innerIndexPtr()[e]) return false;
  }
  return true;
}

// Compares the sparse derivatives of f at `point` with the dense ones for (wrt, rows, weights);
// returns the patterns for the invariance check.
void CompareWithDense(const SmoothFunction& f, const Point& point, Wrt wrt,
                      const std::vector<int>* rows, const Vector& weights, const std::string& what,
                      SparseMatrix* jac, SparseMatrix* hess) {
  const int m = f.num_outputs();
  const std::string where = what + " wrt " + WrtName(wrt) + (rows ? " (row subset)" : "");
  Vector dense_value, sparse_value;
  Matrix dense_jac;
  f.Jacobian(point.x, point.u, point.t, point.p, wrt, &dense_value, &dense_jac);
  ASSERT_TRUE(dense_value.allFinite() && dense_jac.allFinite()) << where << ": choose a point "
                                                                << "inside the domain";
  f.SparseJacobian(point.x, point.u, point.t, point.p, wrt, &sparse_value, jac, rows);
  ASSERT_EQ(sparse_value.size(), m) << where;
  const std::vector<int> selected = rows ? *rows : AllRows(m);
  std::vector<char> in_rows(static_cast<std::size_t>(m), 0);
  for (int k : selected) in_rows[static_cast<std::size_t>(k)] = 1;
  // Functions made of blocks compute the values of the rows asked for alone (the others NaN).
  const bool blocks = f.typed() != nullptr && f.typed()->block_outputs() > 0;
  for (int k = 0; k < m; ++k) {
    if (blocks && !in_rows[static_cast<std::size_t>(k)]) {
      EXPECT_TRUE(std::isnan(sparse_value[k])) << where << ": value " << k;
      continue;
    }
    EXPECT_NEAR(sparse_value[k], dense_value[k],
                kDerivativeTolerance * (1 + std::fabs(dense_value[k])))
        << where << ": value " << k;
  }
  Matrix expected = dense_jac;
  for (int k = 0; k < m; ++k) {
    if (!in_rows[static_cast<std::size_t>(k)]) expected.row(k).setZero();
  }
  for (int j = 0; j < jac->outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(*jac, j); it; ++it) {
      ASSERT_TRUE(in_rows[static_cast<std::size_t>(it.row())])
          << where << ": Jacobian entry stored in row " << it.row() << " outside the subset";
    }
  }
  ASSERT_NO_FATAL_FAILURE(ExpectClose(Matrix(*jac), expected, where + " Jacobian"));

  if (f.typed() == nullptr) return;  // hand-written Jacobian: no second derivatives
  Vector masked = Vector::Zero(m);
  for (int k : selected) masked[k] = weights[k];
  Matrix dense_hess;
  f.WeightedHessian(point.x, point.u, point.t, point.p, wrt, masked, &dense_hess);
  ASSERT_TRUE(dense_hess.allFinite()) << where;
  f.SparseWeightedHessian(point.x, point.u, point.t, point.p, wrt, weights, hess, rows);
  ASSERT_NO_FATAL_FAILURE(ExpectClose(Matrix(*hess), dense_hess, where + " Hessian"));
}

// The dense Hessian direction (functions of at most 16 columns, used by the lowered blocks in
// dense storage) against the sparse one and against the Hessian of each output times the
// direction. The sparse path seeds one input per colour of an output's support, the dense one
// every column: the same products, the other colours' contributions being exact zeros, so the
// two agree exactly (== treats -0 and +0 alike); the per-output Hessians sum in another order
// (kDerivativeTolerance).
void CompareHessianDirections(const SmoothFunction& f, const Point& point, Wrt wrt,
                              const Vector& direction, const std::string& where) {
  internal::TypedFunction* typed = f.typed();
  const int columns =
      wrt.Columns(static_cast<int>(point.x.size()), static_cast<int>(point.u.size()),
                  static_cast<int>(point.p.size()));
  if (typed == nullptr || columns > internal::Dual1::kCapacity) return;
  Matrix dense;
  typed->DenseHessianDirection(point.x, point.u, point.t, point.p, wrt, direction, &dense);
  SparseMatrix sparse;
  f.SparseHessianDirection(point.x, point.u, point.t, point.p, wrt, direction, &sparse);
  const Matrix from_sparse(sparse);
  ASSERT_EQ(dense.rows(), from_sparse.rows()) << where;
  ASSERT_EQ(dense.cols(), from_sparse.cols()) << where;
  for (Eigen::Index k = 0; k < dense.rows(); ++k) {
    for (Eigen::Index j = 0; j < dense.cols(); ++j) {
      ASSERT_EQ(dense(k, j), from_sparse(k, j))
          << where << ": Hessian direction entry (" << k << ", " << j << ")";
    }
  }
  Matrix expected(f.num_outputs(), columns), hessian;
  Vector unit = Vector::Zero(f.num_outputs());
  for (int k = 0; k < f.num_outputs(); ++k) {
    unit.setZero();
    unit[k] = 1.0;
    f.WeightedHessian(point.x, point.u, point.t, point.p, wrt, unit, &hessian);
    expected.row(k) = (hessian * direction).transpose();
  }
  ASSERT_NO_FATAL_FAILURE(ExpectClose(dense, expected, where + " Hessian direction"));
}

// A point near the scene's initial data: states and inputs perturbed by up to 10% of their
// scale, time inside the horizon, parameters by up to 1% (keeps every catalog function in its
// domain: positive densities, speeds and radii stay positive).
Point RandomPoint(const Scene& scene, std::mt19937* rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Point point;
  point.x = scene.initial_state;
  for (Eigen::Index i = 0; i < point.x.size(); ++i) {
    point.x[i] += 0.1 * unit(*rng) * (1.0 + std::fabs(point.x[i]));
  }
  std::uniform_real_distribution<double> fraction(0.0, 1.0);
  point.t = scene.initial_time + fraction(*rng) * (scene.final_time - scene.initial_time);
  point.u = scene.InputValues(point.t);
  for (Eigen::Index i = 0; i < point.u.size(); ++i) {
    point.u[i] += 0.1 * unit(*rng) * (1.0 + std::fabs(point.u[i]));
  }
  point.p = scene.ParameterValues();
  for (Eigen::Index i = 0; i < point.p.size(); ++i) point.p[i] *= 1.0 + 0.01 * unit(*rng);
  return point;
}

// Every model function of a scene, with a name for messages.
std::vector<std::pair<std::string, SmoothFunction>> ModelFunctions(const Scene& scene) {
  std::vector<std::pair<std::string, SmoothFunction>> functions;
  auto add = [&functions](const std::string& what, const SmoothFunction& f) {
    if (!f.empty()) functions.emplace_back(what, f);
  };
  add("dynamics", scene.dynamics);
  for (const Effect& effect : scene.effects) {
    const std::string name = EffectKind(effect) + " '" + EffectName(effect) + "'";
    if (const auto* set = std::get_if<MovingSet>(&effect)) {
      add(name + " constraints", set->constraints);
    } else if (const auto* switching = std::get_if<SwitchingSurfaces>(&effect)) {
      add(name + " surfaces", switching->surfaces);
      for (std::size_t i = 0; i < switching->modes.size(); ++i) {
        add(name + " mode " + std::to_string(i), switching->modes[i]);
      }
    } else if (const auto* relay = std::get_if<HysteresisRelay>(&effect)) {
      add(name + " input", relay->input);
      add(name + " field A", relay->mode_a);
      add(name + " field B", relay->mode_b);
    } else if (const auto* path = std::get_if<PathConstraints>(&effect)) {
      add(name + " constraints", path->constraints);
    }
  }
  return functions;
}

// The acceptance check on one scene: every function, Wrt::XT() and Wrt::All(), all rows and a
// random subset, random weights (some zero) and all-zero weights, at two random points whose
// patterns must agree.
void CheckScene(const Scene& scene, unsigned seed) {
  std::mt19937 rng(seed);
  const auto functions = ModelFunctions(scene);
  ASSERT_FALSE(functions.empty()) << scene.name;
  for (const auto& [what_function, f] : functions) {
    const std::string what = scene.name + " " + what_function + " ('" + f.name() + "')";
    const int m = f.num_outputs();
    std::uniform_real_distribution<double> weight(-2.0, 2.0);
    std::bernoulli_distribution coin(0.5);
    Vector weights(m);
    for (int k = 0; k < m; ++k) weights[k] = coin(rng) ? weight(rng) : 0.0;
    std::vector<int> subset;
    for (int k = 0; k < m; ++k) {
      if (coin(rng)) subset.push_back(k);
    }
    const Point first = RandomPoint(scene, &rng), second = RandomPoint(scene, &rng);
    for (Wrt wrt : {Wrt::XT(), Wrt::All()}) {
      for (const std::vector<int>* rows : {static_cast<const std::vector<int>*>(nullptr),
                                           static_cast<const std::vector<int>*>(&subset)}) {
        SparseMatrix jac_first, hess_first, jac_second, hess_second, hess_zero;
        ASSERT_NO_FATAL_FAILURE(
            CompareWithDense(f, first, wrt, rows, weights, what, &jac_first, &hess_first));
        ASSERT_NO_FATAL_FAILURE(
            CompareWithDense(f, second, wrt, rows, weights, what, &jac_second, &hess_second));
        if (!f.sparse_derivative_stats().point_dependent) {
          EXPECT_TRUE(SamePattern(jac_first, jac_second)) << what << ": Jacobian pattern moved";
          EXPECT_TRUE(SamePattern(hess_first, hess_second)) << what << ": Hessian pattern moved";
        }
        if (f.typed() == nullptr) continue;
        Vector direction(jac_first.cols());
        for (Eigen::Index j = 0; j < direction.size(); ++j) {
          direction[j] = coin(rng) ? weight(rng) : 0.0;  // some zero: inner constants
        }
        ASSERT_NO_FATAL_FAILURE(CompareHessianDirections(f, first, wrt, direction, what));
        // Zero weights: the same pattern, all zero, and no second-order evaluation.
        f.SparseWeightedHessian(second.x, second.u, second.t, second.p, wrt, Vector::Zero(m),
                                &hess_zero, rows);
        EXPECT_TRUE(SamePattern(hess_zero, hess_second)) << what;
        EXPECT_EQ(Matrix(hess_zero).lpNorm<Eigen::Infinity>(), 0.0) << what;
        EXPECT_EQ(f.sparse_derivative_stats().hessian_passes, 0) << what;
      }
    }
    // Catalog functions are branch-free: one detection (by the first derivative) serves every
    // call.
    EXPECT_EQ(f.sparse_derivative_stats().num_detections, f.typed() ? 1 : 0) << what;
  }
}

class CatalogSparseTest : public ::testing::TestWithParam<std::string> {};

TEST_P(CatalogSparseTest, SparseDerivativesEqualDenseOnEveryModelFunction) {
  CheckScene(MakeScene(GetParam()), 20240515u);
}

std::vector<std::string> CatalogNames() {
  std::vector<std::string> names;
  for (const SceneDefinition& definition : SceneCatalog()) names.push_back(definition.name);
  return names;
}

INSTANTIATE_TEST_SUITE_P(Catalog, CatalogSparseTest, ::testing::ValuesIn(CatalogNames()),
                         [](const auto& parameter) { return parameter.param; });

class SceneFileSparseTest : public ::testing::TestWithParam<std::string> {};

TEST_P(SceneFileSparseTest, SparseDerivativesEqualDenseOnEveryModelFunction) {
  const std::string path = std::string(MOREAU_EXAMPLES_DIR) + "/scenes/" + GetParam() + ".toml";
  CheckScene(LoadScene(path), 777u);
}

INSTANTIATE_TEST_SUITE_P(ExampleFiles, SceneFileSparseTest,
                         ::testing::Values("S1", "S2", "S3", "S4", "F1", "F2a", "F2b", "F2c", "F3",
                                           "F4", "H1", "H2", "H3", "dai_index2", "relay_feedback",
                                           "sliding_box"),
                         [](const auto& parameter) { return parameter.param; });

// ---- detection ------------------------------------------------------------------------------

// Entries (i, j) of the upper triangle of the sparse Hessian pattern of output k alone.
std::vector<std::pair<int, int>> HessianPatternOf(const SmoothFunction& f, int k, const Point& at,
                                                  Wrt wrt) {
  Vector weights = Vector::Zero(f.num_outputs());
  weights[k] = 1.0;
  const std::vector<int> rows{k};
  SparseMatrix hess;
  f.SparseWeightedHessian(at.x, at.u, at.t, at.p, wrt, weights, &hess, &rows);
  std::vector<std::pair<int, int>> entries;
  for (int j = 0; j < hess.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(hess, j); it; ++it) {
      if (it.row() <= j) entries.emplace_back(static_cast<int>(it.row()), j);
    }
  }
  return entries;
}

TEST(SparsityDetectionTest, PatternsFollowTheOperations) {
  // Inputs (Wrt::All): x0..x5 -> columns 0..5, u0 -> 6, t -> 7, p0 -> 8.
  const SmoothFunction f = MakeSmoothFunction(
      "ops", 7, [](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::exp;
        using std::sin;
        out[0] = x[0] * x[1] + 3.0 * x[2];            // product: only the mixed pair
        out[1] = sin(x[0]) + 0.0 * x[5];              // nonlinear unary: the square of its argument
        out[2] = x[3] / x[4];                         // quotient: (3,4) and (4,4)
        out[3] = 2.0 * x[5] - p[0] + u[0] / 4.0 + t;  // affine
        out[4] = exp(x[0] + x[1]);                    // nonlinear of a sum: all pairs of {0, 1}
        out[5] = p[0] * t * x[2];                     // product of three: the three mixed pairs
        out[6] = 5.0;                                 // constant
      });
  Point at;
  at.x = Vector{{0.3, -0.4, 0.5, 1.5, 2.5, -1.0}};
  at.u = Vector{{0.2}};
  at.p = Vector{{1.7}};
  at.t = 0.6;
  using Pairs = std::vector<std::pair<int, int>>;
  EXPECT_EQ(HessianPatternOf(f, 0, at, Wrt::All()), (Pairs{{0, 1}}));
  EXPECT_EQ(HessianPatternOf(f, 1, at, Wrt::All()), (Pairs{{0, 0}}));
  EXPECT_EQ(HessianPatternOf(f, 2, at, Wrt::All()), (Pairs{{3, 4}, {4, 4}}));
  EXPECT_EQ(HessianPatternOf(f, 3, at, Wrt::All()), Pairs{});
  EXPECT_EQ(HessianPatternOf(f, 4, at, Wrt::All()), (Pairs{{0, 0}, {0, 1}, {1, 1}}));
  EXPECT_EQ(HessianPatternOf(f, 5, at, Wrt::All()), (Pairs{{2, 7}, {2, 8}, {7, 8}}));
  EXPECT_EQ(HessianPatternOf(f, 5, at, Wrt::XT()), (Pairs{{2, 6}}));  // x2 t, columns x | t
  EXPECT_EQ(HessianPatternOf(f, 6, at, Wrt::All()), Pairs{});
  // Jacobian pattern: structural, including the entry multiplied by the constant 0.
  Vector value;
  SparseMatrix jac;
  f.SparseJacobian(at.x, at.u, at.t, at.p, Wrt::All(), &value, &jac);
  std::vector<std::vector<int>> rows(7);
  for (int j = 0; j < jac.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(jac, j); it; ++it) {
      rows[static_cast<std::size_t>(it.row())].push_back(j);
    }
  }
  EXPECT_EQ(rows[0], (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(rows[1], (std::vector<int>{0, 5}));
  EXPECT_EQ(rows[3], (std::vector<int>{5, 6, 7, 8}));
  EXPECT_EQ(rows[5], (std::vector<int>{2, 7, 8}));
  EXPECT_TRUE(rows[6].empty());
  EXPECT_FALSE(f.sparse_derivative_stats().point_dependent);
}

TEST(SparsityDetectionTest, AffineFunctionsCostNoSecondOrderWork) {
  // A linear constraint set c(x, t) = A x - b t with a dense-ish A: empty Hessian pattern.
  const SmoothFunction c = MakeSmoothFunction(
      "linear", 3, [](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        for (int k = 0; k < 3; ++k) {
          for (int i = 0; i < x.size(); ++i) out[k] += (k + 1.0) * (i - 2.0) * x[i];
          out[k] -= p[0] * 2.0 + t / 3.0;
        }
      });
  const Vector x = Vector::LinSpaced(40, -1.0, 1.0), u, p{{0.5}};
  SparseMatrix hess;
  c.SparseWeightedHessian(x, u, 0.2, p, Wrt::All(), Vector::Ones(3), &hess);
  EXPECT_EQ(hess.rows(), 42);
  EXPECT_EQ(hess.nonZeros(), 0);
  EXPECT_EQ(c.sparse_derivative_stats().hessian_passes, 0);
}

TEST(SparsityDetectionTest, BranchesAreFollowedOnBothSidesAndThePatternOnlyGrows) {
  const SmoothFunction f = MakeSmoothFunction(
      "branchy", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        using std::sin;
        if (ValueOf(x[0]) > 0.0) {  // the explicit branch (comparisons do not compile)
          out[0] = x[0] * x[1];
        } else {
          out[0] = sin(x[2]);
        }
        out[1] = x[3] * x[3];
      });
  const Vector u, p;
  const Vector weights{{1.5, -0.5}};
  SparseMatrix jac, hess;
  Vector value;
  std::vector<std::pair<Vector, std::string>> points = {
      {Vector{{0.7, 0.2, -0.3, 0.4}}, "x0 > 0"},
      {Vector{{-0.7, 0.2, -0.3, 0.4}}, "x0 < 0"},
      {Vector{{0.9, -0.5, 1.3, 0.1}}, "x0 > 0 again"}};
  for (const auto& [x, side] : points) {
    Matrix dense_jac, dense_hess;
    f.Jacobian(x, u, 0.0, p, Wrt::X(), &value, &dense_jac);
    f.WeightedHessian(x, u, 0.0, p, Wrt::X(), weights, &dense_hess);
    f.SparseJacobian(x, u, 0.0, p, Wrt::X(), &value, &jac);
    f.SparseWeightedHessian(x, u, 0.0, p, Wrt::X(), weights, &hess);
    ASSERT_NO_FATAL_FAILURE(ExpectClose(Matrix(jac), dense_jac, "Jacobian at " + side));
    ASSERT_NO_FATAL_FAILURE(ExpectClose(Matrix(hess), dense_hess, "Hessian at " + side));
  }
  const SparseDerivativeStats stats = f.sparse_derivative_stats();
  EXPECT_TRUE(stats.point_dependent);
  // The first dense derivative traces (the function's analysis), then every sparse call.
  EXPECT_EQ(stats.num_detections, 1 + 6);
  EXPECT_EQ(stats.num_pattern_growths, 1);  // the second side added entries once
  // The stored pattern is the union of both sides: row 0 has x0, x1 and x2.
  EXPECT_EQ(jac.nonZeros(), 4);
  EXPECT_EQ(hess.nonZeros(), 2 + 1 + 1);  // (0,1), (1,0), (2,2), (3,3)
}

TEST(SparsityDetectionTest, RowSubsetsMustBeSortedOutputs) {
  const SmoothFunction f = MakeSmoothFunction(
      "f", 3, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0];
        out[1] = x[1];
        out[2] = x[0] * x[1];
      });
  const Vector x{{1.0, 2.0}}, none;
  Vector value;
  SparseMatrix jac;
  const std::vector<int> unsorted{2, 0}, outside{0, 3};
  EXPECT_THROW(f.SparseJacobian(x, none, 0.0, none, Wrt::X(), &value, &jac, &unsorted),
               std::invalid_argument);
  EXPECT_THROW(f.SparseJacobian(x, none, 0.0, none, Wrt::X(), &value, &jac, &outside),
               std::invalid_argument);
}

// ---- cost follows the nonzeros ----------------------------------------------------------------

// N agents in the plane on a jittered grid, one output per pair of neighbours within distance
// 1.6 (grid spacing 1): |q_i - q_j|^2 - 1, the crowd-motion non-overlap constraint.
SmoothFunction NeighbourPairs(int agents, Vector* positions) {
  const int side = static_cast<int>(std::ceil(std::sqrt(agents)));
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> jitter(-0.1, 0.1);
  positions->resize(2 * agents);
  for (int i = 0; i < agents; ++i) {
    (*positions)[2 * i] = i % side + jitter(rng);
    (*positions)[2 * i + 1] = i / side + jitter(rng);
  }
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < agents; ++i) {
    for (int j = i + 1; j < agents; ++j) {
      const double dx = (*positions)[2 * i] - (*positions)[2 * j];
      const double dy = (*positions)[2 * i + 1] - (*positions)[2 * j + 1];
      if (dx * dx + dy * dy < 1.6 * 1.6) pairs.emplace_back(i, j);
    }
  }
  return MakeSmoothFunction(
      "pairs", static_cast<int>(pairs.size()),
      [pairs](const auto& q, const auto&, const auto&, const auto&, auto& out) {
        for (std::size_t k = 0; k < pairs.size(); ++k) {
          const auto [i, j] = pairs[k];
          const auto dx = q[2 * i] - q[2 * j];
          const auto dy = q[2 * i + 1] - q[2 * j + 1];
          out[static_cast<int>(k)] = dx * dx + dy * dy - 1.0;
        }
      });
}

TEST(SparseCostTest, ColoursDoNotGrowWithTheNumberOfInputs) {
  // The number of compressed directions is set by the neighbourhoods, not by N: the same on a
  // 36-agent and a 400-agent crowd (checked against the dense AD on the small one).
  int colors_small = 0;
  for (int agents : {36, 400}) {
    Vector q;
    const SmoothFunction c = NeighbourPairs(agents, &q);
    const int m = c.num_outputs();
    const Vector none;
    Vector value, weights = Vector::LinSpaced(m, -1.0, 2.0);
    SparseMatrix jac, hess;
    c.SparseJacobian(q, none, 0.0, none, Wrt::X(), &value, &jac);
    c.SparseWeightedHessian(q, none, 0.0, none, Wrt::X(), weights, &hess);
    const SparseDerivativeStats stats = c.sparse_derivative_stats();
    EXPECT_EQ(jac.nonZeros(), 4 * m);
    // Per pair: d2/dxi2, d2/dxi dxj, d2/dxj2 and the same for y (no x-y coupling).
    EXPECT_EQ(hess.nonZeros(), 2 * agents + 4 * m);
    if (agents == 36) {
      colors_small = stats.jacobian_colors;
      Matrix dense_jac, dense_hess;
      c.Jacobian(q, none, 0.0, none, Wrt::X(), &value, &dense_jac);
      c.WeightedHessian(q, none, 0.0, none, Wrt::X(), weights, &dense_hess);
      ASSERT_NO_FATAL_FAILURE(ExpectClose(Matrix(jac), dense_jac, "crowd Jacobian"));
      ASSERT_NO_FATAL_FAILURE(ExpectClose(Matrix(hess), dense_hess, "crowd Hessian"));
    } else {
      // A few more colours at most where the interior neighbourhoods are complete.
      EXPECT_LE(stats.jacobian_colors, colors_small + 4);
      EXPECT_LE(stats.jacobian_passes, 2);
      EXPECT_LE(stats.hessian_passes, 3);
    }
  }
}

TEST(SparseCostTest, ManyColoursSpanSeveralChunksOfDirections) {
  // Outputs on overlapping windows of 24 of 64 inputs: at least 24 colours, so the compressed
  // directions span two chunks of Dual1::kCapacity (two Dual1 passes; Dual2 passes for the
  // chunk pairs (0,0), (0,1), (1,1)). A coupled and a diagonal Hessian per window.
  constexpr int kInputs = 64, kWindow = 24, kStride = 4;
  constexpr int kOutputs = (kInputs - kWindow) / kStride + 1;
  const SmoothFunction coupled =
      MakeSmoothFunction("windows", 2 * kOutputs,
                         [](const auto& x, const auto&, const auto& t, const auto&, auto& out) {
                           using std::exp;
                           for (int k = 0; k < kOutputs; ++k) {
                             auto sum = 0.0 * t;
                             auto squares = 0.0 * t;
                             for (int i = k * kStride; i < k * kStride + kWindow; ++i) {
                               sum += (0.01 * i + 0.1) * x[i];
                               squares += x[i] * x[i];
                             }
                             out[2 * k] = exp(sum) * x[k * kStride] + t * x[k * kStride + 1];
                             out[2 * k + 1] = squares;
                           }
                         });
  Point at;
  at.x = Vector::LinSpaced(kInputs, -0.8, 0.9);
  at.t = 0.4;
  std::vector<int> odd, even;
  for (int k = 0; k < 2 * kOutputs; ++k) (k % 2 ? odd : even).push_back(k);
  const Vector weights = Vector::LinSpaced(2 * kOutputs, -1.0, 1.5);
  SparseMatrix jac, hess;
  for (Wrt wrt : {Wrt::XT(), Wrt::All()}) {
    ASSERT_NO_FATAL_FAILURE(
        CompareWithDense(coupled, at, wrt, nullptr, weights, "windows", &jac, &hess));
    EXPECT_GE(coupled.sparse_derivative_stats().jacobian_colors, kWindow);
    EXPECT_EQ(coupled.sparse_derivative_stats().jacobian_passes, 2);
    EXPECT_EQ(coupled.sparse_derivative_stats().hessian_passes, 3);
    ASSERT_NO_FATAL_FAILURE(
        CompareWithDense(coupled, at, wrt, &even, weights, "windows (coupled)", &jac, &hess));
    ASSERT_NO_FATAL_FAILURE(
        CompareWithDense(coupled, at, wrt, &odd, weights, "windows (squares)", &jac, &hess));
    // Diagonal second derivatives only: the off-diagonal chunk pair is skipped.
    EXPECT_EQ(coupled.sparse_derivative_stats().hessian_passes, 2);
  }
}

TEST(SparseCostTest, CopiesShareTheDetectedPatternAndPlansAreCachedPerRowSubset) {
  Vector q;
  const SmoothFunction c = NeighbourPairs(16, &q);
  const Vector none;
  Vector value;
  SparseMatrix jac;
  const std::vector<int> first{0, 2, 5}, second{1, 3};
  for (int repeat = 0; repeat < 3; ++repeat) {
    c.SparseJacobian(q, none, 0.0, none, Wrt::X(), &value, &jac, &first);
    c.SparseJacobian(q, none, 0.0, none, Wrt::X(), &value, &jac, &second);
  }
  EXPECT_EQ(c.sparse_derivative_stats().num_detections, 1);
  EXPECT_EQ(c.sparse_derivative_stats().num_cached_plans, 2);
  // A copy (as every scene and lowered system copies its functions) takes the pattern its
  // original detected: no traced evaluation of its own.
  const SmoothFunction copy = c;
  EXPECT_EQ(copy.sparse_derivative_stats().num_detections, 0);
  copy.SparseJacobian(q, none, 0.0, none, Wrt::X(), &value, &jac, &first);
  EXPECT_EQ(copy.sparse_derivative_stats().num_detections, 0);
  EXPECT_EQ(jac.nonZeros(), 12);  // three pairs, four coordinates each
}

// A switching effect's surfaces and mode fields are stacked anew at every lowering (once per
// run): a stack of the same parts (or of their copies, which share their analyses) takes the
// pattern the first stack detected; a stack of other parts, or of the same parts in another
// order, detects its own.
TEST(SparseCostTest, StacksOfTheSamePartsShareTheDetectedPattern) {
  Vector q;
  const SmoothFunction pairs = NeighbourPairs(9, &q);
  const SmoothFunction other = NeighbourPairs(9, &q);
  const Vector none;
  Vector value;
  SparseMatrix jac;
  auto detections = [&](const SmoothFunction& stacked) {
    stacked.SparseJacobian(q, none, 0.0, none, Wrt::X(), &value, &jac);
    return stacked.sparse_derivative_stats().num_detections;
  };
  const SmoothFunction first = MakeStackedFunction("first", {pairs, other});
  EXPECT_EQ(detections(first), 1);
  const SmoothFunction pairs_copy = pairs;
  const SmoothFunction again = MakeStackedFunction("again", {pairs_copy, other});
  EXPECT_EQ(detections(again), 0);
  Matrix dense_first, dense_again;
  first.SparseJacobian(q, none, 0.0, none, Wrt::X(), &value, &jac);
  dense_first = Matrix(jac);
  again.SparseJacobian(q, none, 0.0, none, Wrt::X(), &value, &jac);
  dense_again = Matrix(jac);
  EXPECT_EQ(dense_first, dense_again);
  EXPECT_EQ(detections(MakeStackedFunction("swapped", {other, pairs})), 1);
  EXPECT_EQ(detections(MakeStackedFunction("alone", {pairs})), 1);
}

TEST(SparseCostTest, StackedAndZeroFunctionsKeepTheirPartsPatterns) {
  Vector q;
  const SmoothFunction pairs = NeighbourPairs(9, &q);
  const SmoothFunction stacked =
      MakeStackedFunction("stacked", {pairs, MakeZeroFunction("zero", 2), pairs});
  const Vector none;
  Vector value;
  SparseMatrix jac_pairs, jac;
  pairs.SparseJacobian(q, none, 0.0, none, Wrt::XT(), &value, &jac_pairs);
  stacked.SparseJacobian(q, none, 0.0, none, Wrt::XT(), &value, &jac);
  EXPECT_EQ(jac.nonZeros(), 2 * jac_pairs.nonZeros());
  const int m = pairs.num_outputs();
  EXPECT_EQ(Matrix(jac).middleRows(m, 2).lpNorm<Eigen::Infinity>(), 0.0);
  EXPECT_EQ(Matrix(jac).bottomRows(m), Matrix(jac_pairs));
}

// ---- functions made of blocks ----------------------------------------------------------------

// Block b of a test family of `blocks` blocks over `agents` agents (x = 2 coordinates per agent,
// t, p = 2 parameters): two outputs coupling agent b with agent (7 b + 3) mod agents, and in
// every 13th block a sum over 12 agents (24 inputs: more than one chunk of 16 directions).
template <class X, class T, class P, class Out>
void TestBlock(int b, int agents, const X& x, const T& t, const P& p, Out& out) {
  using std::sin;
  const int i = b % agents, j = (7 * b + 3) % agents;
  const auto dx = x[2 * i] - x[2 * j];
  const auto dy = x[2 * i + 1] - x[2 * j + 1];
  out[0] = (dx * dx + dy * dy) * p[0] - 1.0;
  out[1] = sin(x[2 * i]) * x[2 * j + 1] + t * x[2 * i] * p[1];
  if (b % 13 == 0) {
    for (int k = 0; k < 12; ++k) {
      const int a = (b + 5 * k) % agents;
      out[1] += x[2 * a] * x[2 * a + 1] * 0.1;
    }
  }
}

SmoothFunction BlockFamily(int blocks, int agents) {
  return MakeBlockFunction("family", blocks, 2,
                           [agents](int b, const auto& x, const auto&, const auto& t, const auto& p,
                                    auto& out) { TestBlock(b, agents, x, t, p, out); });
}

// All blocks' outputs in order (the family written as one function).
template <class X, class T, class P, class Out>
void AllTestBlocks(int blocks, int agents, const X& x, const T& t, const P& p, Out& out) {
  for (int b = 0; b < blocks; ++b) {
    T values[2] = {T(0.0), T(0.0)};
    TestBlock(b, agents, x, t, p, values);
    out[2 * b] = values[0];
    out[2 * b + 1] = values[1];
  }
}

// The same outputs as one lambda.
SmoothFunction WholeFamily(int blocks, int agents) {
  return MakeSmoothFunction(
      "family", 2 * blocks,
      [blocks, agents](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        AllTestBlocks(blocks, agents, x, t, p, out);
      });
}

Point FamilyPoint(int agents) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Point point;
  point.x.resize(2 * agents);
  for (Eigen::Index i = 0; i < point.x.size(); ++i) point.x[i] = unit(rng);
  point.t = 0.3;
  point.p = Vector{{1.5, -0.7}};
  return point;
}

// Sparse derivatives of a function made of blocks (one block at a time, one direction per
// input of the block, only the blocks of the rows asked for) equal those of the same outputs
// written as one lambda (compressed forward mode over colours): the same dual-number
// operations per entry, weighted Hessians summed in another order (kDerivativeTolerance).
// Values and dense derivatives evaluate the blocks in order: equal exactly.
TEST(BlockFunctionTest, DerivativesEqualThoseOfTheSameOutputsWrittenAsOneLambda) {
  const int blocks = 60, agents = 40;
  const SmoothFunction block = BlockFamily(blocks, agents), whole = WholeFamily(blocks, agents);
  const Point point = FamilyPoint(agents);
  const int m = 2 * blocks;
  std::mt19937 rng(3);
  std::bernoulli_distribution coin(0.4);
  std::vector<int> subset;
  for (int k = 0; k < m; ++k) {
    if (coin(rng)) subset.push_back(k);
  }
  Vector weights(m);
  for (int k = 0; k < m; ++k) weights[k] = coin(rng) ? 0.5 + 0.01 * k : 0.0;
  Vector value_block, value_whole;
  block.Evaluate(point.x, point.u, point.t, point.p, &value_block);
  whole.Evaluate(point.x, point.u, point.t, point.p, &value_whole);
  EXPECT_EQ(value_block, value_whole);
  for (Wrt wrt : {Wrt::X(), Wrt::XT(), Wrt::All()}) {
    const std::string where = "wrt " + WrtName(wrt);
    Matrix dense_block, dense_whole;
    block.Jacobian(point.x, point.u, point.t, point.p, wrt, &value_block, &dense_block);
    whole.Jacobian(point.x, point.u, point.t, point.p, wrt, &value_whole, &dense_whole);
    EXPECT_EQ(dense_block, dense_whole) << where;
    const std::vector<const std::vector<int>*> row_sets = {nullptr, &subset};
    for (const std::vector<int>* rows : row_sets) {
      const std::string what = where + (rows ? " (row subset)" : "");
      SparseMatrix jac_block, jac_whole, hess_block, hess_whole;
      block.SparseJacobian(point.x, point.u, point.t, point.p, wrt, &value_block, &jac_block, rows);
      whole.SparseJacobian(point.x, point.u, point.t, point.p, wrt, &value_whole, &jac_whole, rows);
      ASSERT_TRUE(SamePattern(jac_block, jac_whole)) << what;
      ASSERT_NO_FATAL_FAILURE(ExpectClose(Matrix(jac_block), Matrix(jac_whole), what));
      // Values of the rows asked for; the others are not computed (NaN).
      const std::vector<int> selected = rows ? *rows : AllRows(m);
      std::vector<char> in_rows(static_cast<std::size_t>(m), 0);
      for (int k : selected) in_rows[static_cast<std::size_t>(k)] = 1;
      for (int k = 0; k < m; ++k) {
        if (in_rows[static_cast<std::size_t>(k)]) {
          EXPECT_EQ(value_block[k], value_whole[k]) << what << ": value " << k;
        } else {
          EXPECT_TRUE(std::isnan(value_block[k])) << what << ": value " << k;
        }
      }
      block.SparseWeightedHessian(point.x, point.u, point.t, point.p, wrt, weights, &hess_block,
                                  rows);
      whole.SparseWeightedHessian(point.x, point.u, point.t, point.p, wrt, weights, &hess_whole,
                                  rows);
      ASSERT_TRUE(SamePattern(hess_block, hess_whole)) << what;
      ASSERT_NO_FATAL_FAILURE(
          ExpectClose(Matrix(hess_block), Matrix(hess_whole), what + " Hessian"));
      Vector direction(jac_block.cols());
      for (Eigen::Index j = 0; j < direction.size(); ++j) direction[j] = coin(rng) ? 0.3 * j : 0.0;
      SparseMatrix along_block, along_whole;
      block.SparseHessianDirection(point.x, point.u, point.t, point.p, wrt, direction, &along_block,
                                   rows);
      whole.SparseHessianDirection(point.x, point.u, point.t, point.p, wrt, direction, &along_whole,
                                   rows);
      ASSERT_TRUE(SamePattern(along_block, along_whole)) << what;
      ASSERT_NO_FATAL_FAILURE(
          ExpectClose(Matrix(along_block), Matrix(along_whole), what + " Hessian direction"));
    }
  }
}

// ---- workspaces kept between evaluations -------------------------------------------------

// Counts down the evaluations of ThrowingFamily while positive; the one that brings it to zero
// throws: a model that stops half-way through a derivative evaluation, its seeds set.
std::atomic<int> g_evaluations_until_throw{0};

// The outputs of BlockFamily as one lambda (derivatives by colour passes over all inputs), or
// as blocks, either of which can throw.
SmoothFunction ThrowingFamily(int blocks, int agents, bool as_blocks) {
  const auto check = [] {
    if (g_evaluations_until_throw.load() > 0 && --g_evaluations_until_throw == 0) {
      throw std::runtime_error("the model throws");
    }
  };
  if (as_blocks) {
    return MakeBlockFunction("throwing", blocks, 2,
                             [agents, check](int b, const auto& x, const auto&, const auto& t,
                                             const auto& p, auto& out) {
                               check();
                               TestBlock(b, agents, x, t, p, out);
                             });
  }
  return MakeSmoothFunction(
      "throwing", 2 * blocks,
      [blocks, agents, check](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        check();
        AllTestBlocks(blocks, agents, x, t, p, out);
      });
}

bool SameBits(const Vector& a, const Vector& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}
bool SameBits(const SparseMatrix& a, const SparseMatrix& b) {
  return SamePattern(a, b) &&
         std::memcmp(a.valuePtr(), b.valuePtr(),
                     sizeof(double) * static_cast<std::size_t>(a.nonZeros())) == 0;
}

// A function keeps its dual-number inputs (and, on threads, each worker's copy) between
// evaluations. Derivatives at a point that differs from the last in a few entries, and at the
// same point after evaluations that threw with their seeds set, equal those of a fresh
// function bit for bit: Jacobians (Dual1 inputs), Hessian directions and weighted Hessians
// (Dual2 inputs), as one lambda and as blocks (on 1 and 3 threads: more blocks than the
// parallel threshold, so the workers' copies are tested too).
TEST(SparseDerivativesTest, KeptInputsGiveTheBitsOfAFreshFunctionAfterChangesAndThrows) {
  const int blocks = 1100, agents = 300;
  const Point x0 = FamilyPoint(agents);
  Point x1 = x0;
  // Four states and a parameter change, the other inputs keep their bits. The parameter is
  // never seeded (derivatives with respect to x and t): only refreshing the kept inputs brings
  // its new value. State 111 (agent 55) is among the last inputs of block 0, which has 28:
  // beyond its first chunk of 16 directions, a constant in that chunk's pass.
  for (int k : {0, 17, 111, 301}) x1.x[k] += 0.125;
  x1.p[0] += 0.25;
  Vector direction = Vector::Zero(x0.x.size() + 1);
  for (Eigen::Index k = 0; k < direction.size(); ++k) direction[k] = 0.25 + 0.01 * k;
  Vector weights = Vector::Zero(2 * blocks);  // outputs of weight zero cost nothing: some
  for (int k = 0; k < 2 * blocks; ++k) weights[k] = k % 5 == 2 ? 0.0 : 1.0 + 0.5 * k;
  // The first output of every block: its inputs are a subset of the second's (TestBlock), so
  // a block asked for these rows reads inputs it is not differentiated in.
  std::vector<int> first_outputs;
  for (int b = 0; b < blocks; ++b) first_outputs.push_back(2 * b);
  struct Results {
    Vector value, first_value;
    SparseMatrix jac, first_jac, along, hess;
  };
  const auto evaluate = [&](const SmoothFunction& f, const Point& at) {
    Results r;
    f.SparseJacobian(at.x, at.u, at.t, at.p, Wrt::XT(), &r.first_value, &r.first_jac,
                     &first_outputs);
    f.SparseJacobian(at.x, at.u, at.t, at.p, Wrt::XT(), &r.value, &r.jac);
    f.SparseHessianDirection(at.x, at.u, at.t, at.p, Wrt::XT(), direction, &r.along);
    f.SparseWeightedHessian(at.x, at.u, at.t, at.p, Wrt::XT(), weights, &r.hess);
    return r;
  };
  const auto expect_same = [](const Results& a, const Results& b, const std::string& what) {
    EXPECT_TRUE(SameBits(a.value, b.value)) << what << ": values";
    EXPECT_TRUE(SameBits(a.jac, b.jac)) << what << ": Jacobian";
    EXPECT_TRUE(SameBits(a.first_value, b.first_value)) << what << ": values of some rows";
    EXPECT_TRUE(SameBits(a.first_jac, b.first_jac)) << what << ": Jacobian of some rows";
    EXPECT_TRUE(SameBits(a.along, b.along)) << what << ": Hessian direction";
    EXPECT_TRUE(SameBits(a.hess, b.hess)) << what << ": weighted Hessian";
  };
  for (bool as_blocks : {false, true}) {
    const Results fresh0 = evaluate(ThrowingFamily(blocks, agents, as_blocks), x0);
    const Results fresh1 = evaluate(ThrowingFamily(blocks, agents, as_blocks), x1);
    // The test can fail: the three inputs' change shows in every kind of result.
    ASSERT_FALSE(SameBits(fresh0.value, fresh1.value));
    ASSERT_FALSE(SameBits(fresh0.jac, fresh1.jac));
    ASSERT_FALSE(SameBits(fresh0.along, fresh1.along));
    ASSERT_FALSE(SameBits(fresh0.hess, fresh1.hess));
    for (int threads : {1, 3}) {
      const std::string what = std::string(as_blocks ? "blocks" : "one lambda") + ", " +
                               std::to_string(threads) + " threads";
      internal::ThreadPool pool(threads);
      const SmoothFunction f = ThrowingFamily(blocks, agents, as_blocks);
      f.typed()->set_thread_pool(&pool);
      expect_same(evaluate(f, x0), fresh0, what + ", x0");
      expect_same(evaluate(f, x1), fresh1, what + ", x1 after x0");
      Vector value;
      SparseMatrix matrix;
      // The second evaluation of each call throws: one lambda, its second colour pass (its
      // first seeds stay set); blocks, the second block.
      g_evaluations_until_throw = 2;
      EXPECT_THROW(f.SparseJacobian(x1.x, x1.u, x1.t, x1.p, Wrt::XT(), &value, &matrix),
                   std::runtime_error)
          << what;
      if (as_blocks) {  // (one lambda differentiates these rows in one colour pass)
        g_evaluations_until_throw = 2;
        EXPECT_THROW(
            f.SparseJacobian(x1.x, x1.u, x1.t, x1.p, Wrt::XT(), &value, &matrix, &first_outputs),
            std::runtime_error)
            << what;
      }
      g_evaluations_until_throw = 2;
      EXPECT_THROW(f.SparseHessianDirection(x1.x, x1.u, x1.t, x1.p, Wrt::XT(), direction, &matrix),
                   std::runtime_error)
          << what;
      g_evaluations_until_throw = 2;
      EXPECT_THROW(f.SparseWeightedHessian(x1.x, x1.u, x1.t, x1.p, Wrt::XT(), weights, &matrix),
                   std::runtime_error)
          << what;
      g_evaluations_until_throw = 0;
      expect_same(evaluate(f, x1), fresh1, what + ", x1 after throws at x1");
      f.typed()->set_thread_pool(nullptr);
    }
  }
}

// The block path on any number of threads gives the same bits: each block's entries are
// computed alone and written to their own places (more blocks than the parallel threshold).
TEST(BlockFunctionTest, JacobiansAreBitwiseTheSameOnAnyNumberOfThreads) {
  const int blocks = 2000, agents = 700;
  const SmoothFunction f = BlockFamily(blocks, agents);
  const Point point = FamilyPoint(agents);
  std::vector<int> subset;
  for (int k = 0; k < 2 * blocks; k += 3) subset.push_back(k);
  const std::vector<const std::vector<int>*> row_sets = {nullptr, &subset};
  std::vector<Vector> reference_values(row_sets.size());
  std::vector<SparseMatrix> references(row_sets.size());
  for (int threads : {1, 2, 3, 5}) {
    internal::ThreadPool pool(threads);
    f.typed()->set_thread_pool(&pool);
    for (std::size_t r = 0; r < row_sets.size(); ++r) {
      Vector value;
      SparseMatrix jac;
      f.SparseJacobian(point.x, point.u, point.t, point.p, Wrt::XT(), &value, &jac, row_sets[r]);
      if (threads == 1) {
        references[r] = jac;
        reference_values[r] = value;
        continue;
      }
      const std::string what = std::to_string(threads) + " threads, rows " + std::to_string(r);
      ASSERT_TRUE(SamePattern(jac, references[r])) << what;
      EXPECT_EQ(0, std::memcmp(jac.valuePtr(), references[r].valuePtr(),
                               sizeof(double) * static_cast<std::size_t>(jac.nonZeros())))
          << what;
      EXPECT_EQ(0, std::memcmp(value.data(), reference_values[r].data(),
                               sizeof(double) * static_cast<std::size_t>(value.size())))
          << what;  // NaN rows included: the same bits
    }
    f.typed()->set_thread_pool(nullptr);
  }
}

// Enclosures of some rows of a function made of blocks (Bounds with rows: only the blocks that
// hold them) are those of the whole function's enclosure, bit for bit (the same interval
// operations per block), on any number of threads; rows of blocks not asked for are unbounded.
TEST(BlockFunctionTest, BoundsOfSomeRowsEqualTheWholeEnclosureOnAnyNumberOfThreads) {
  // More blocks asked for than the enclosures' parallel threshold (8192 blocks).
  const int blocks = 13000, agents = 700;
  const SmoothFunction f = BlockFamily(blocks, agents);
  const Point point = FamilyPoint(agents);
  const Vector x_lower = point.x.array() - 0.01, x_upper = point.x.array() + 0.02;
  Vector whole_lower, whole_upper;
  ASSERT_TRUE(f.Bounds(x_lower, x_upper, point.u, 0.2, 0.4, point.p, &whole_lower, &whole_upper));
  std::vector<int> subset;
  for (int k = 1; k < 2 * blocks; k += 3) subset.push_back(k);  // both outputs of some blocks
  for (int threads : {1, 2, 3, 5}) {
    internal::ThreadPool pool(threads);
    f.typed()->set_thread_pool(&pool);
    Vector lower, upper;
    ASSERT_TRUE(f.Bounds(x_lower, x_upper, point.u, 0.2, 0.4, point.p, &lower, &upper, &subset));
    f.typed()->set_thread_pool(nullptr);
    std::vector<bool> asked(2 * blocks, false);
    for (int k : subset) asked[static_cast<std::size_t>(k)] = true;
    int mismatches = 0, computed_unasked_blocks = 0;
    for (int k = 0; k < 2 * blocks; ++k) {
      const bool block_asked = asked[static_cast<std::size_t>(2 * (k / 2))] ||
                               asked[static_cast<std::size_t>(2 * (k / 2) + 1)];
      if (asked[static_cast<std::size_t>(k)]) {
        mismatches += std::memcmp(&lower[k], &whole_lower[k], sizeof(double)) != 0 ||
                      std::memcmp(&upper[k], &whole_upper[k], sizeof(double)) != 0;
      } else if (!block_asked) {
        computed_unasked_blocks += !(lower[k] == -HUGE_VAL && upper[k] == HUGE_VAL);
      }
    }
    EXPECT_EQ(mismatches, 0) << threads << " threads";
    EXPECT_EQ(computed_unasked_blocks, 0) << threads << " threads";
  }
}

// A branch that the box does not decide makes the enclosure unavailable only where it is
// evaluated: in the block that branches, not for rows of other blocks.
TEST(BlockFunctionTest, AnUndecidedBranchMattersOnlyInItsOwnBlock) {
  const SmoothFunction f =
      MakeBlockFunction("relu_blocks", 3, 1,
                        [](int b, const auto& x, const auto&, const auto&, const auto&, auto& out) {
                          out[0] = b == 1 && ValueOf(x[b]) > 0.0 ? x[b] : 2.0 * x[b];
                        });
  const Vector x_lower{{-1.0, -1.0, -1.0}}, x_upper{{1.0, 1.0, 1.0}};
  Vector lower, upper;
  EXPECT_FALSE(f.Bounds(x_lower, x_upper, Vector(), 0.0, 0.0, Vector(), &lower, &upper));
  const std::vector<int> with_branch = {0, 1}, without_branch = {0, 2};
  EXPECT_FALSE(
      f.Bounds(x_lower, x_upper, Vector(), 0.0, 0.0, Vector(), &lower, &upper, &with_branch));
  ASSERT_TRUE(
      f.Bounds(x_lower, x_upper, Vector(), 0.0, 0.0, Vector(), &lower, &upper, &without_branch));
  // 2 x over [-1, 1]: [-2, 2] rounded outward by one ulp; block 1 was not evaluated.
  EXPECT_EQ(lower[2], std::nextafter(-2.0, -3.0));
  EXPECT_EQ(upper[2], std::nextafter(2.0, 3.0));
  EXPECT_TRUE(lower[1] == -HUGE_VAL && upper[1] == HUGE_VAL);
}

}  // namespace
}  // namespace moreau
