// Sparse derivative storage (DerivativeStorage::kSparse: sparse AD, compressed blocks) against
// dense storage (dense forward-mode AD) on every catalog scene: the same point evaluations,
// velocity-level rows and event indicators, entry by entry (docs/sparse-systems.md).

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <type_traits>
#include <utility>

#include "../problems/test_scenes.hpp"
#include "moreau/core/interval.hpp"
#include "moreau/linalg/linear_solver.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Both storages compute the same exact derivatives by different AD orders (one dense pass
// per 16 inputs against compressed colours), so entries agree to a few ulps of the largest
// entry of their block; 1e-13 relative to max(1, |block|) leaves room for sums of O(10) terms.
constexpr double kStorageAgreement = 1e-13;

void ExpectSame(const DerivativeMatrix& dense, const DerivativeMatrix& sparse,
                const std::string& what) {
  ASSERT_FALSE(dense.is_sparse()) << what;
  ASSERT_TRUE(sparse.is_sparse()) << what;
  ASSERT_EQ(dense.rows(), sparse.rows()) << what;
  ASSERT_EQ(dense.cols(), sparse.cols()) << what;
  const Matrix a = dense.ToDense(), b = sparse.ToDense();
  const double scale = std::max(1.0, a.lpNorm<Eigen::Infinity>());
  EXPECT_LE((a - b).lpNorm<Eigen::Infinity>(), kStorageAgreement * scale) << what;
}

void ExpectSame(const Vector& a, const Vector& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  const double scale = std::max(1.0, a.lpNorm<Eigen::Infinity>());
  EXPECT_LE((a - b).lpNorm<Eigen::Infinity>(), kStorageAgreement * scale) << what;
}

// Bit for bit (signs of zeros included), and the same stored entries.
void ExpectSameBits(const Vector& a, const Vector& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  if (a.size() == 0) return;  // (no data pointers to compare)
  EXPECT_EQ(std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())), 0)
      << what;
}
void ExpectSameBits(const DerivativeMatrix& a, const DerivativeMatrix& b, const std::string& what) {
  ASSERT_TRUE(a.is_sparse() && b.is_sparse()) << what;
  const SparseMatrix& p = a.sparse();
  const SparseMatrix& q = b.sparse();
  ASSERT_EQ(p.rows(), q.rows()) << what;
  ASSERT_EQ(p.cols(), q.cols()) << what;
  ASSERT_EQ(p.nonZeros(), q.nonZeros()) << what;
  ASSERT_TRUE(p.isCompressed() && q.isCompressed()) << what;
  const auto n = static_cast<std::size_t>(p.nonZeros());
  EXPECT_TRUE(
      std::equal(p.outerIndexPtr(), p.outerIndexPtr() + p.outerSize() + 1, q.outerIndexPtr()))
      << what;
  if (n == 0) return;  // (no entries: Eigen may hold no storage)
  EXPECT_TRUE(std::equal(p.innerIndexPtr(), p.innerIndexPtr() + n, q.innerIndexPtr())) << what;
  EXPECT_EQ(std::memcmp(p.valuePtr(), q.valuePtr(), sizeof(double) * n), 0) << what;
}
// The same values, entry for entry (stored or not; a zero's sign aside).
void ExpectSameValues(const DerivativeMatrix& a, const DerivativeMatrix& b,
                      const std::string& what) {
  ASSERT_EQ(a.rows(), b.rows()) << what;
  ASSERT_EQ(a.cols(), b.cols()) << what;
  EXPECT_TRUE((a.ToDense().array() == b.ToDense().array()).all()) << what;
}

struct Pair {
  LoweredSystem dense, sparse;
};

Pair Lower(const Scene& scene, SwitchingForm form, RelayForm relays) {
  LoweringOptions options;
  options.switching_form = form;
  options.relay_form = relays;
  options.require_feasible_initial_state = false;
  LoweringOptions sparse_options = options;
  options.storage = DerivativeStorage::kDense;
  sparse_options.storage = DerivativeStorage::kSparse;
  return {LoweredSystem(scene, options), LoweredSystem(scene, sparse_options)};
}

std::vector<Scene> Scenes() {
  std::vector<Scene> scenes;
  for (const SceneDefinition& definition : SceneCatalog()) {
    Scene scene = definition.make();
    if (scene.dynamics.has_sparse_state_jacobian()) continue;  // sparse storage only
    scenes.push_back(std::move(scene));
  }
  scenes.push_back(testing::TwoSurfaceScene());
  scenes.push_back(testing::MixedHysteresisScene());
  scenes.push_back(testing::MixedHysteresisScene(true));
  scenes.push_back(testing::ComplementarityScene());
  scenes.push_back(testing::ComplementarityScene(true));
  return scenes;
}

// The compressed matrix is created on first sparse use (DerivativeMatrix holds none while
// dense): storages switch both ways, copies carry it, and an empty sparse matrix reads as zero.
TEST(SparseStorage, DerivativeMatrixSwitchesStorageAndCopies) {
  DerivativeMatrix m;
  m.SetZero(2, 3, false);
  m.Add(1, 2, 4.0);
  EXPECT_EQ(m.ToDense()(1, 2), 4.0);
  m.SetZero(2, 3, true);
  m.Add(0, 1, 1.5);
  m.Add(0, 1, 0.5);  // duplicates are summed by Finalize
  m.Finalize();
  ASSERT_TRUE(m.is_sparse());
  EXPECT_EQ(m.ToDense()(0, 1), 2.0);
  EXPECT_EQ(m.ToDense()(1, 2), 0.0);
  EXPECT_EQ(m.NonZeros(), 1.0);
  const DerivativeMatrix copy = m;
  EXPECT_EQ(copy.sparse().nonZeros(), 1);
  EXPECT_EQ(copy.ToDense(), m.ToDense());
  m.SetZero(2, 3, false);
  EXPECT_EQ(m.ToDense(), Matrix::Zero(2, 3));
  EXPECT_EQ(copy.ToDense()(0, 1), 2.0);  // the copy owns its storage
  DerivativeMatrix empty;
  empty.SetZero(3, 2, true);
  empty.Finalize();
  EXPECT_EQ(empty.sparse().rows(), 3);
  EXPECT_EQ(empty.ToDense(), Matrix::Zero(3, 2));
  const double visited = empty.Visit([](const auto& storage) { return storage.norm(); });
  EXPECT_EQ(visited, 0.0);
}

// A kept matrix finalized again (the plan of its last compression replayed while the entries
// keep their positions, a new sort when they move or change order) equals a fresh matrix bit for
// bit, and both equal Eigen's setFromTriplets. The duplicates' values make their summation order
// visible: (1e16 + 1) - 1e16 is 0 from left to right and 1 in another order; -0.0 alone stays
// -0.0 only if the first entry of a position is assigned, not added to zero.
TEST(SparseStorage, FinalizeAgainEqualsAFreshMatrixBitForBit) {
  constexpr int kRows = 7, kCols = 5;
  std::mt19937 random(17);
  std::uniform_int_distribution<int> row(0, kRows - 1), col(0, kCols - 1);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::vector<DerivativeMatrix::Entry> entries;
  for (int k = 0; k < 40; ++k) entries.push_back({row(random), col(random), value(random)});
  entries.push_back({3, 2, 1e16});
  entries.push_back({3, 2, 1.0});
  entries.push_back({3, 2, -1e16});
  entries.push_back({6, 4, -0.0});
  auto fill = [](DerivativeMatrix* m, SystemMatrix* a,
                 const std::vector<DerivativeMatrix::Entry>& list) {
    m->SetZero(kRows, kCols, true);
    a->Reset(kRows, true);
    for (const auto& e : list) {
      m->Add(e.r, e.c, e.v);
      a->AddEntry(e.r, e.c, e.v);
    }
    m->Finalize();
    a->Finalize();
  };
  auto expect_fresh = [&](const DerivativeMatrix& kept, const SystemMatrix& kept_system,
                          const std::vector<DerivativeMatrix::Entry>& list,
                          const std::string& what) {
    DerivativeMatrix fresh;
    SystemMatrix fresh_system;
    fill(&fresh, &fresh_system, list);
    ExpectSameBits(kept, fresh, what);
    std::vector<Eigen::Triplet<double, int>> triplets;
    for (const auto& e : list) triplets.emplace_back(e.r, e.c, e.v);
    DerivativeMatrix eigen;
    SparseMatrix expected(kRows, kCols);
    expected.setFromTriplets(triplets.begin(), triplets.end());
    eigen.SetZero(kRows, kCols, true);
    eigen.Assign(expected);
    ExpectSameBits(kept, eigen, what + " (setFromTriplets)");
    DerivativeMatrix system_part, fresh_system_part;
    system_part.SetZero(kRows, kRows, true);
    system_part.Assign(kept_system.sparse_matrix());
    fresh_system_part.SetZero(kRows, kRows, true);
    fresh_system_part.Assign(fresh_system.sparse_matrix());
    ExpectSameBits(system_part, fresh_system_part, what + " (system matrix)");
  };
  DerivativeMatrix kept;
  SystemMatrix kept_system;
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "first");
  ASSERT_EQ(kept.ToDense()(3, 2), 0.0);
  ASSERT_TRUE(std::signbit(kept.ToDense()(6, 4)));
  // The same positions with new values: the replay.
  for (auto& e : entries) {
    if (e.r != 3 || e.c != 2) e.v = value(random);
  }
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "new values");
  // Two entries swapped (the same positions in another order, so the same stored pattern):
  // first two at different rows of one column, then two in one row and different columns.
  auto swap_where = [&](const auto& differ) {
    for (std::size_t a = 0; a < entries.size(); ++a) {
      for (std::size_t b = a + 1; b < entries.size(); ++b) {
        if (differ(entries[a], entries[b])) {
          std::swap(entries[a], entries[b]);
          return true;
        }
      }
    }
    return false;
  };
  ASSERT_TRUE(swap_where([](const auto& a, const auto& b) { return a.c == b.c && a.r != b.r; }));
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "swapped in a column");
  ASSERT_TRUE(swap_where([](const auto& a, const auto& b) { return a.r == b.r && a.c != b.c; }));
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "swapped in a row");
  // One entry moved (same count, another position), then one entry fewer, then back.
  entries[5].r = (entries[5].r + 1) % kRows;
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "an entry moved");
  const DerivativeMatrix::Entry last = entries.back();
  entries.pop_back();
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "an entry fewer");
  entries.push_back(last);
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "back");
  // A copy carries its plan with its matrix; Assign replaces the matrix and drops the plan.
  DerivativeMatrix copy = kept;
  SystemMatrix copy_system = kept_system;
  entries[0].v = 2.5;
  fill(&copy, &copy_system, entries);
  expect_fresh(copy, copy_system, entries, "copy");
  SparseMatrix other(kRows, kCols);
  other.insert(0, 0) = 1.0;
  kept.SetZero(kRows, kCols, true);
  kept.Assign(other);
  fill(&kept, &kept_system, entries);
  expect_fresh(kept, kept_system, entries, "after Assign");
}

TEST(SparseStorage, EvaluationsEqualDenseOnEveryCatalogScene) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-0.5, 0.5);
  int compared = 0;
  for (const Scene& scene : Scenes()) {
    for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
      for (RelayForm relays : {RelayForm::kTimeFreezing, RelayForm::kDiscreteMemory}) {
        Pair pair = Lower(scene, form, relays);
        LoweredSystem& dense = pair.dense;
        LoweredSystem& sparse = pair.sparse;
        ASSERT_FALSE(dense.sparse());
        ASSERT_TRUE(sparse.sparse());
        const std::string label = scene.name + " " + ToString(form) +
                                  (relays == RelayForm::kTimeFreezing ? "" : " discrete");
        for (int trial = 0; trial < 2; ++trial) {
          Vector y = dense.InitialState();
          for (int i = 0; i < dense.num_scene_states(); ++i) y[i] += uniform(rng);
          y[dense.clock_index()] += 0.3 + uniform(rng);
          Vector z(dense.num_algebraic());
          for (Eigen::Index i = 0; i < z.size(); ++i) z[i] = 0.5 + uniform(rng);
          PointEvaluation a, b;
          dense.Evaluate(y, z, Derivatives::kAll, &a);
          sparse.Evaluate(y, z, Derivatives::kAll, &b);
          ExpectSame(a.F, b.F, label + " F");
          ExpectSame(a.G, b.G, label + " G");
          ExpectSame(a.A, b.A, label + " A");
          ExpectSame(a.B, b.B, label + " B");
          const std::pair<const char*, DerivativeMatrix PointEvaluation::*> blocks[] = {
              {"F_y", &PointEvaluation::F_y}, {"F_z", &PointEvaluation::F_z},
              {"G_y", &PointEvaluation::G_y}, {"G_z", &PointEvaluation::G_z},
              {"A_y", &PointEvaluation::A_y}, {"A_z", &PointEvaluation::A_z},
              {"B_y", &PointEvaluation::B_y}, {"B_z", &PointEvaluation::B_z},
              {"F_u", &PointEvaluation::F_u}, {"G_u", &PointEvaluation::G_u},
              {"A_u", &PointEvaluation::A_u}, {"B_u", &PointEvaluation::B_u},
              {"F_p", &PointEvaluation::F_p}, {"G_p", &PointEvaluation::G_p},
              {"A_p", &PointEvaluation::A_p}, {"B_p", &PointEvaluation::B_p}};
          for (const auto& [name, member] : blocks)
            ExpectSame(a.*member, b.*member, label + " " + name);
          if (dense.num_pairs() == 0) continue;

          // Velocity level with mixed roles (one complementary pair) and event indicators.
          std::vector<PairRole> roles(static_cast<std::size_t>(dense.num_pairs()));
          std::vector<bool> a_zero(roles.size());
          for (std::size_t k = 0; k < roles.size(); ++k) {
            roles[k] =
                k == 0 ? PairRole::kComplementary : (k % 2 ? PairRole::kAZero : PairRole::kBZero);
            a_zero[k] = k % 3 != 0;
          }
          VelocityLevelEvaluation va, vb;
          dense.EvaluateVelocityLevel(y, z, roles, Derivatives::kAll, &va);
          sparse.EvaluateVelocityLevel(y, z, roles, Derivatives::kAll, &vb);
          ExpectSame(va.equations, vb.equations, label + " velocity equations");
          ExpectSame(va.a, vb.a, label + " velocity a");
          ExpectSame(va.b, vb.b, label + " velocity b");
          ExpectSame(va.equations_v, vb.equations_v, label + " equations_v");
          ExpectSame(va.equations_y, vb.equations_y, label + " equations_y");
          ExpectSame(va.equations_u, vb.equations_u, label + " equations_u");
          ExpectSame(va.equations_p, vb.equations_p, label + " equations_p");
          ExpectSame(va.a_v, vb.a_v, label + " a_v");
          ExpectSame(va.a_y, vb.a_y, label + " a_y");
          ExpectSame(va.b_v, vb.b_v, label + " b_v");
          ExpectSame(va.b_y, vb.b_y, label + " b_y");
          ExpectSame(va.b_p, vb.b_p, label + " b_p");
          // Without derivatives in u, p the sparse rows are assembled in a kept workspace
          // (the solves of every element, and FESD's Jacobian rows of an event): the same bits
          // as the assembly through Eigen's sparse expressions, which kAll uses. (d/dy: the
          // same values; kAll's evaluation may store explicit zeros that kStates' does not.)
          VelocityLevelEvaluation with_y, without;
          sparse.EvaluateVelocityLevel(y, z, roles, Derivatives::kStates, &with_y);
          sparse.EvaluateVelocityLevel(y, z, roles, Derivatives::kNone, &without);
          using V = VelocityLevelEvaluation;
          for (const auto& [name, values, d_v, d_y] :
               {std::tuple{"equations", &V::equations, &V::equations_v, &V::equations_y},
                std::tuple{"a", &V::a, &V::a_v, &V::a_y},
                std::tuple{"b", &V::b, &V::b_v, &V::b_y}}) {
            ExpectSameBits(vb.*values, with_y.*values, label + " velocity " + name);
            ExpectSameBits(vb.*d_v, with_y.*d_v, label + " velocity d/dv " + name);
            ExpectSameValues(vb.*d_y, with_y.*d_y, label + " velocity d/dy " + name);
            ExpectSameBits(vb.*values, without.*values, label + " velocity " + name);
            ExpectSameBits(vb.*d_v, without.*d_v, label + " velocity d/dv " + name);
          }
          IndicatorEvaluation ia, ib;
          bool stewart_like = false;  // Stewart blocks need an active mode per block
          for (const PairInfo& info : dense.pairs())
            stewart_like |= info.continuous == ContinuousSide::kB;
          if (stewart_like) std::fill(a_zero.begin(), a_zero.end(), false);
          dense.EvaluateEventIndicators(y, z, a_zero, Derivatives::kAll, &ia);
          sparse.EvaluateEventIndicators(y, z, a_zero, Derivatives::kAll, &ib);
          ExpectSame(ia.values, ib.values, label + " indicators");
          ExpectSame(ia.d_y, ib.d_y, label + " indicators d_y");
          ExpectSame(ia.d_v, ib.d_v, label + " indicators d_v");
          ExpectSame(ia.d_u, ib.d_u, label + " indicators d_u");
          ExpectSame(ia.d_p, ib.d_p, label + " indicators d_p");
          ++compared;
        }
      }
    }
  }
  EXPECT_GT(compared, 100);  // the catalog's effect scenes, both forms, two points each
}

// Values alone (Derivatives::kNone) are the values of an evaluation with derivatives, in both
// storages, with the multipliers zero (a moving set then evaluates its constraints' values
// without their gradient: no constraint pushes) and nonzero. G, A and B are equal as numbers
// (a skipped zero product may turn a -0 into +0, nothing more). F only to round-off: a model
// function's values alone run in doubles, with derivatives in dual numbers, and a dual
// quotient's value is a * (1 / b), not a / b (dual.hpp), an ulp apart: the crowd's, D3's and
// the circuits' fields differ by a few ulps of their terms (the rectifier's terms are three
// times their sum). With that quotient computed as a / b every scene's F is equal exactly
// (checked), but results move by round-off and two of the random scenes' fragile outcomes
// change, so the quotient is left as it is.
TEST(SparseStorage, ValuesAloneEqualTheValuesOfAnEvaluationWithDerivatives) {
  constexpr double kDualRoundOff = 32.0 * std::numeric_limits<double>::epsilon();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uniform(-0.5, 0.5);
  auto expect_equal = [](const Vector& a, const Vector& b, double tolerance,
                         const std::string& what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    const double scale = std::max(1.0, b.lpNorm<Eigen::Infinity>());
    const bool equal = tolerance == 0.0 ? (a.array() == b.array()).all()
                                        : (a - b).lpNorm<Eigen::Infinity>() <= tolerance * scale;
    EXPECT_TRUE(equal) << what << "\nvalues alone: " << a.transpose()
                       << "\nwith derivatives: " << b.transpose();
  };
  int with_zero_multipliers = 0;
  for (const Scene& scene : Scenes()) {
    Pair pair = Lower(scene, SwitchingForm::kStewart, RelayForm::kTimeFreezing);
    for (LoweredSystem* system : {&pair.dense, &pair.sparse}) {
      const std::string label = scene.name + (system->sparse() ? " sparse" : " dense");
      for (bool zero : {true, false}) {
        Vector y = system->InitialState();
        for (int i = 0; i < system->num_scene_states(); ++i) y[i] += uniform(rng);
        Vector z(system->num_algebraic());
        for (Eigen::Index i = 0; i < z.size(); ++i) z[i] = zero ? 0.0 : 0.5 + uniform(rng);
        PointEvaluation alone, with;
        system->Evaluate(y, z, Derivatives::kNone, &alone);
        system->Evaluate(y, z, Derivatives::kStates, &with);
        const std::string what = label + (zero ? " (z = 0)" : "");
        expect_equal(alone.F, with.F, kDualRoundOff, what + " F");
        expect_equal(alone.G, with.G, 0.0, what + " G");
        expect_equal(alone.A, with.A, 0.0, what + " A");
        expect_equal(alone.B, with.B, 0.0, what + " B");
        with_zero_multipliers += zero && system->num_pairs() > 0 ? 1 : 0;
      }
    }
  }
  EXPECT_GT(with_zero_multipliers, 20);  // the catalog's effect scenes, both storages
}

// The pattern of a sparse evaluation depends on the structure and on which moving-set
// multipliers are nonzero (the term sum_k lambda_k Hess c_k sums over pushing constraints only,
// docs/sparse-systems.md), not on the point: a sparse LU of a matrix assembled from it keeps
// its symbolic analysis from one evaluation to the next while no multiplier becomes zero or
// nonzero. (Zero multipliers are checked to give a pattern no larger.)
TEST(SparseStorage, PatternsDoNotDependOnThePoint) {
  for (const char* name : {"S3", "F1", "H1", "S5", "rectifier"}) {
    Pair pair = Lower(MakeScene(name), SwitchingForm::kStewart, RelayForm::kTimeFreezing);
    LoweredSystem& system = pair.sparse;
    Vector y0 = system.InitialState(), y1 = y0;
    y1.head(system.num_scene_states()).array() += 0.37;
    Vector z0 = Vector::Constant(system.num_algebraic(), 0.2);
    Vector z1 = Vector::Constant(system.num_algebraic(), 0.7);
    PointEvaluation a, b, zero;
    system.Evaluate(y0, z0, Derivatives::kStates, &a);
    system.Evaluate(y1, z1, Derivatives::kStates, &b);
    system.Evaluate(y1, Vector::Zero(system.num_algebraic()), Derivatives::kStates, &zero);
    EXPECT_LE(zero.F_y.NonZeros(), a.F_y.NonZeros()) << name;
    for (const auto& [m, n] : {std::pair{&a.F_y, &b.F_y}, std::pair{&a.F_z, &b.F_z},
                               std::pair{&a.A_y, &b.A_y}, std::pair{&a.G_y, &b.G_y}}) {
      const SparseMatrix& p = m->sparse();
      const SparseMatrix& q = n->sparse();
      ASSERT_EQ(p.nonZeros(), q.nonZeros()) << name;
      EXPECT_TRUE(
          std::equal(p.outerIndexPtr(), p.outerIndexPtr() + p.outerSize() + 1, q.outerIndexPtr()))
          << name;
      EXPECT_TRUE(
          std::equal(p.innerIndexPtr(), p.innerIndexPtr() + p.nonZeros(), q.innerIndexPtr()))
          << name;
    }
  }
}

TEST(SparseStorage, AutomaticStorageFollowsTheSize) {
  LoweredSystem small(MakeScene("S3"));
  EXPECT_FALSE(small.sparse());
  LoweringOptions sparse;
  sparse.storage = DerivativeStorage::kSparse;
  EXPECT_TRUE(LoweredSystem(MakeScene("S3"), sparse).sparse());
  // Hand-written sparse dynamics (the 2000-state heat equation) are always stored sparse,
  // and refuse dense storage with a message.
  EXPECT_TRUE(LoweredSystem(MakeScene("heat")).sparse());
  LoweringOptions dense;
  dense.storage = DerivativeStorage::kDense;
  try {
    LoweredSystem refused(MakeScene("heat"), dense);
    FAIL() << "dense storage of hand-written sparse dynamics was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("sparse derivative storage"), std::string::npos)
        << e.what();
  }
}

// Threads of the system in the enclosures: a moving set of 9000 constraints written block by
// block (above the enclosures' parallel threshold of 8192 blocks), its event indicators bounded
// (LoweredSystem::BoundEventIndicators) on a system with two threads. While armed, the calling
// thread's enclosure of block 0 (the first block of the first chunk, which the caller claims
// at once) waits for another thread to enclose a block: the pool's worker then claims a later
// chunk. If the enclosures ran without the system's threads (as they once did: the bounds'
// block context left them out), no other thread ever comes and the wait times out after
// kWaitSeconds, generous beside a worker's wake-up (microseconds) on a loaded machine.
std::atomic<bool> g_enclosure_wait_armed{false};
std::atomic<int> g_enclosures_off_caller{0};
std::thread::id g_enclosure_caller;

TEST(SparseStorage, EventIndicatorEnclosuresRunOnTheSystemsThreads) {
  constexpr int kConstraints = 9000;
  constexpr double kWaitSeconds = 20.0;
  Scene scene;
  scene.name = "threaded_enclosures";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{0.0, 0.0}};
  scene.final_time = 1.0;
  scene.dynamics = MakeSmoothFunction(
      "drift", 2, [](const auto&, const auto&, const auto&, const auto&, auto& out) {
        out[0] = 1.0;
        out[1] = 0.0;
      });
  MovingSet set;
  set.name = "floors";
  for (int b = 0; b < kConstraints; ++b) set.constraint_names.push_back("c" + std::to_string(b));
  // c_b = x1 + b + 1 >= 0.
  set.constraints = MakeBlockFunction(
      "floors.c", kConstraints, 1,
      [](int b, const auto& x, const auto&, const auto&, const auto&, auto& out) {
        using Scalar = std::decay_t<decltype(out[0])>;
        if constexpr (std::is_same_v<Scalar, Interval>) {
          if (g_enclosure_wait_armed.load()) {
            if (std::this_thread::get_id() != g_enclosure_caller) {
              ++g_enclosures_off_caller;
            } else if (b == 0) {
              const auto start = std::chrono::steady_clock::now();
              while (
                  g_enclosures_off_caller.load() == 0 &&
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() <
                      kWaitSeconds) {
                std::this_thread::yield();
              }
            }
          }
        }
        out[0] = x[0] + static_cast<double>(b + 1);
      });
  scene.effects.push_back(set);
  LoweringOptions options;
  options.storage = DerivativeStorage::kSparse;
  LoweredSystem system(scene, options);
  system.SetThreads(2);
  ASSERT_EQ(system.threads(), 2);
  ASSERT_EQ(system.num_pairs(), kConstraints);
  const int ny = system.num_states();
  const Vector y_lower = Vector::Constant(ny, -0.5), y_upper = Vector::Constant(ny, 0.25);
  const std::vector<bool> a_zero(static_cast<std::size_t>(kConstraints), false);  // all inactive
  Vector lower, upper;
  g_enclosure_caller = std::this_thread::get_id();
  g_enclosures_off_caller = 0;
  g_enclosure_wait_armed = true;
  system.BoundEventIndicators(y_lower, y_upper, a_zero, &lower, &upper);
  g_enclosure_wait_armed = false;
  EXPECT_GT(g_enclosures_off_caller.load(), 0) << "no enclosure ran on the system's worker";
  // And the enclosures are those of c_b over x1 in [-0.5, 0.25]: [b + 0.5, b + 1.25] (rounded
  // outward by at most an ulp of each end).
  ASSERT_EQ(lower.size(), kConstraints);
  int wrong = 0;
  for (int b = 0; b < kConstraints; ++b) {
    const double low = b + 0.5, high = b + 1.25;
    wrong += !(lower[b] <= low && lower[b] >= std::nextafter(low, -HUGE_VAL) && upper[b] >= high &&
               upper[b] <= std::nextafter(high, HUGE_VAL));
  }
  EXPECT_EQ(wrong, 0);
}

}  // namespace
}  // namespace moreau
