// The crowd-motion scene family (include/moreau/scenes/crowd.hpp, docs/crowd-motion.md): options
// and their errors, the start (feasible with its margin, deterministic), the neighbour search
// against brute force, the sparsity of every model function, the certificate of all pairs and
// walls, FESD runs that form contacts with certified elements, the scene file against the
// built-in scene, and the catalog and command-line names.
#include "moreau/scenes/crowd.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <sstream>

#include "../tools/run_cli.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

#ifndef MOREAU_EXAMPLES_DIR
#error "MOREAU_EXAMPLES_DIR must name examples/ (tests/CMakeLists.txt)"
#endif

namespace moreau {
namespace {

// Positions are sums of a few O(L) terms (L <= 200 here): their round-off is a few ulps of L,
// far below this slack on the start's gap margins and on gaps computed from positions.
constexpr double kPositionSlack = 1e-12;
// Desired velocities (O(1)) from positions O(100): a few ulps of the positions.
constexpr double kVelocityTolerance = 1e-13;
// The bounds for a crowd simulation: overlap (a gap, in length units; the constraints
// are scaled so that c = gap (1 + gap / 4r)) and complementarity residual at every element.
constexpr double kOverlapTolerance = 1e-9;
constexpr double kComplementarityTolerance = 1e-9;
// The scene file evaluates the compiled lambdas' operations in the same order: values and
// derivatives agree to round-off (measured: bit-identical), trajectories too.
constexpr double kDerivativeTolerance = 1e-14;
constexpr double kTrajectoryTolerance = 1e-12;

void ExpectInvalid(const std::function<void()>& action, const std::string& part) {
  try {
    action();
    ADD_FAILURE() << "no exception; expected one containing '" << part << "'";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find(part), std::string::npos) << error.what();
  }
}

CrowdOptions Options(int agents, std::uint64_t seed = 1) {
  CrowdOptions options;
  options.agents = agents;
  options.seed = seed;
  return options;
}

// ---- options -------------------------------------------------------------------------------

TEST(CrowdOptionsTest, BadOptionsAreRejectedWithTheirRange) {
  auto expect = [](auto mutate, const std::string& part) {
    CrowdOptions options;
    mutate(&options);
    ExpectInvalid([&] { options.Validate(); }, part);
    ExpectInvalid([&] { MakeCrowdScene(options); }, part);
  };
  expect([](CrowdOptions* o) { o->agents = 0; }, "N (agents) must be in [1, 1000000], got 0");
  expect([](CrowdOptions* o) { o->radius = -1.0; }, "radius must be finite and > 0, got -1");
  expect([](CrowdOptions* o) { o->speed = NAN; }, "speed must be finite and > 0, got nan");
  expect([](CrowdOptions* o) { o->spacing = 1.0; }, "spacing must be finite and > 2 radius = 1");
  expect([](CrowdOptions* o) { o->jitter = 1.0; }, "jitter must be in [0, 1), got 1");
  expect([](CrowdOptions* o) { o->cutoff = 0.5; }, "cutoff must be finite and > 2 radius = 1");
  expect([](CrowdOptions* o) { o->door = -2.0; }, "door must be finite and >= 0");
  expect([](CrowdOptions* o) { o->exit_distance = -1.0; }, "exit_distance must be finite and >= 0");
  expect([](CrowdOptions* o) { o->smoothing = 0.0; }, "smoothing must be finite and > 0, got 0");
  expect([](CrowdOptions* o) { o->final_time = INFINITY; }, "tf must be finite and > 0, got inf");
  // A door as wide as the room would not be a door.
  expect(
      [](CrowdOptions* o) {
        o->agents = 4;
        o->door = 5.0;
      },
      "door must be below the room height H = 2.5");
}

TEST(CrowdOptionsTest, ParsedFromTheSceneNameSyntax) {
  const CrowdOptions parsed = ParseCrowdOptions("N=1e3,seed=3,radius=0.4,tf=2.5");
  EXPECT_EQ(parsed.agents, 1000);
  EXPECT_EQ(parsed.seed, 3u);
  EXPECT_EQ(parsed.radius, 0.4);
  EXPECT_EQ(parsed.final_time, 2.5);
  EXPECT_EQ(parsed.spacing, CrowdOptions{}.spacing);
  EXPECT_EQ(CrowdSceneName(parsed), "crowd_N1000_radius0.4_seed3_tf2.5");
  EXPECT_EQ(CrowdSceneName(ParseCrowdOptions("")), "crowd");
  ExpectInvalid([] { ParseCrowdOptions("M=3"); }, "unknown crowd option 'M'; valid keys: N (");
  ExpectInvalid([] { ParseCrowdOptions("N=3,N=4"); }, "crowd option 'N' given twice");
  ExpectInvalid([] { ParseCrowdOptions("N"); }, "bad crowd option 'N': expected key=value");
  ExpectInvalid([] { ParseCrowdOptions("N=4,"); }, "bad crowd option '': expected key=value");
  ExpectInvalid([] { ParseCrowdOptions("N=2.5"); },
                "bad value '2.5' for crowd option N: expected an integer in [1, 1000000]");
  ExpectInvalid([] { ParseCrowdOptions("N=0"); }, "expected an integer in [1, 1000000]");
  ExpectInvalid([] { ParseCrowdOptions("radius=abc"); },
                "bad value 'abc' for crowd option radius: expected a number");
  ExpectInvalid([] { ParseCrowdOptions("seed=-1"); }, "bad value '-1' for crowd option seed");
  ExpectInvalid([] { ParseCrowdOptions("jitter=2"); }, "jitter must be in [0, 1), got 2");
}

TEST(CrowdCatalogTest, NamesReachTheFamily) {
  const Scene standard = MakeScene("crowd");
  EXPECT_EQ(standard.name, "crowd");
  EXPECT_EQ(standard.num_states(), 2 * CrowdOptions{}.agents);
  const Scene seven = MakeScene("crowd:N=7,seed=3");
  EXPECT_EQ(seven.name, "crowd_N7_seed3");
  EXPECT_EQ(seven.initial_state, MakeCrowdScene(Options(7, 3)).initial_state);
  EXPECT_EQ(MakeScene("crowd:").name, "crowd");
  ExpectInvalid([] { MakeScene("crowd:N=abc"); },
                "scene 'crowd:N=abc': bad value 'abc' for crowd option N");
  ExpectInvalid([] { MakeScene("S3:N=3"); }, "only the crowd family takes options");
  bool listed = false;
  for (const SceneDefinition& definition : SceneCatalog()) listed |= definition.name == "crowd";
  EXPECT_TRUE(listed);
}

// ---- the start -------------------------------------------------------------------------------

TEST(CrowdLayoutTest, StartIsFeasibleWithItsMarginAndDeterministic) {
  for (int agents : {1, 2, 7, 16, 100, 1000}) {
    for (double jitter : {0.0, 0.4, 0.999}) {
      CrowdOptions options = Options(agents, 11);
      options.jitter = jitter;
      const CrowdLayout layout = MakeCrowdLayout(options);
      const std::string what =
          "N = " + std::to_string(agents) + ", jitter " + std::to_string(jitter);
      const double a = options.spacing, r = options.radius;
      const double slack = kPositionSlack * std::max(1.0, layout.door_x);
      const CrowdCertificate start = CertifyCrowdState(layout, layout.initial_state);
      if (agents > 1) {
        EXPECT_GE(start.min_pair_gap, (1.0 - jitter) * (a - 2.0 * r) - slack) << what;
      }
      EXPECT_GE(start.min_wall_gap, (1.0 - jitter) * (0.5 * a - r) - slack) << what;
      // The jambs lie in x >= L0 + a/2: at least a - r - j from every agent.
      const double j = jitter * 0.5 * (a - 2.0 * r);
      for (int i = 0; i < agents; ++i) {
        for (CrowdWall jamb : {CrowdWall::kUpperJamb, CrowdWall::kLowerJamb}) {
          EXPECT_GE(layout.WallGap(layout.initial_state, i, jamb), a - r - j - slack) << what;
        }
      }
      EXPECT_TRUE(start.ListsSufficed()) << what << ": " << start.Summary();
      EXPECT_NO_THROW(ValidateScene(MakeCrowdScene(layout))) << what;
      EXPECT_EQ(
          layout.columns * layout.rows >= agents && layout.columns * (layout.rows - 1) < agents,
          true)
          << what;
    }
  }
  // The same options give the same start to the last bit; another seed another start.
  EXPECT_EQ(MakeCrowdLayout(Options(50, 4)).initial_state,
            MakeCrowdLayout(Options(50, 4)).initial_state);
  EXPECT_NE(MakeCrowdLayout(Options(50, 4)).initial_state,
            MakeCrowdLayout(Options(50, 5)).initial_state);
}

TEST(CrowdLayoutTest, DefaultCutoffKeepsTheTwentyNearestGridNeighbours) {
  const CrowdLayout layout = MakeCrowdLayout(CrowdOptions{});
  std::set<std::pair<int, int>> expected;
  for (int i = 0; i < layout.num_agents(); ++i) {
    for (int j = i + 1; j < layout.num_agents(); ++j) {
      const int dc = std::abs(i % layout.columns - j % layout.columns);
      const int dr = std::abs(i / layout.columns - j / layout.columns);
      if (dc * dc + dr * dr <= 5) expected.emplace(i, j);  // shells 1, sqrt 2, 2, sqrt 5
    }
  }
  const std::set<std::pair<int, int>> listed(layout.pairs.begin(), layout.pairs.end());
  EXPECT_EQ(listed, expected);
}

// ---- neighbour search ------------------------------------------------------------------------

std::vector<std::pair<int, int>> BruteForcePairs(const Vector& q, double distance) {
  std::vector<std::pair<int, int>> pairs;
  const int n = static_cast<int>(q.size() / 2);
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (std::hypot(q[2 * i] - q[2 * j], q[2 * i + 1] - q[2 * j + 1]) < distance) {
        pairs.emplace_back(i, j);
      }
    }
  }
  return pairs;
}

TEST(CrowdNeighbourTest, CellGridFindsExactlyTheBruteForcePairs) {
  std::mt19937_64 random(7);
  for (int agents : {1, 2, 5, 30, 200}) {
    // The layouts' lists.
    for (double cutoff : {1.1, 2.0, 3.25, 6.0}) {
      CrowdOptions options = Options(agents, static_cast<std::uint64_t>(agents));
      options.cutoff = cutoff;
      const CrowdLayout layout = MakeCrowdLayout(options);
      EXPECT_EQ(layout.pairs, BruteForcePairs(layout.initial_state, cutoff))
          << "N = " << agents << ", cutoff " << cutoff;
    }
    // Random points: dense clusters, points on cell boundaries (integers with distance 1) and
    // points spread so far that the grid coarsens its cells.
    for (double spread : {1.0, 10.0, 1e6}) {
      Vector q(2 * agents);
      std::uniform_real_distribution<double> uniform(-spread, spread);
      for (int k = 0; k < q.size(); ++k) {
        q[k] = spread == 10.0 ? std::round(uniform(random)) : uniform(random);
      }
      for (double distance : {0.5, 1.0, 3.0}) {
        EXPECT_EQ(FindCrowdPairs(q, distance), BruteForcePairs(q, distance))
            << "N = " << agents << ", spread " << spread << ", distance " << distance;
      }
    }
  }
  ExpectInvalid([] { FindCrowdPairs(Vector::Zero(3), 1.0); }, "2 entries per agent, got 3");
  ExpectInvalid([] { FindCrowdPairs(Vector::Zero(4), 0.0); }, "must be finite and > 0, got 0");
  ExpectInvalid([] { FindCrowdPairs(Vector::Constant(4, NAN), 1.0); }, "must be finite");
}

TEST(CrowdNeighbourTest, RelistedLayoutsFollowTheState) {
  const CrowdLayout layout = MakeCrowdLayout(Options(30));
  const CrowdLayout same = RelistCrowdLayout(layout, layout.initial_state);
  EXPECT_EQ(same.pairs, layout.pairs);
  EXPECT_EQ(same.walls.size(), layout.walls.size());
  // Squeeze the crowd toward its centre: more pairs within the cutoff.
  const Vector centre = layout.initial_state.reshaped(2, 30).rowwise().mean();
  Vector q = layout.initial_state;
  for (int i = 0; i < 30; ++i) q.segment(2 * i, 2) = centre + 0.8 * (q.segment(2 * i, 2) - centre);
  const CrowdLayout squeezed = RelistCrowdLayout(layout, q);
  EXPECT_EQ(squeezed.initial_state, q);
  EXPECT_EQ(squeezed.pairs, BruteForcePairs(q, layout.options.cutoff));
  EXPECT_GT(squeezed.pairs.size(), layout.pairs.size());
  ExpectInvalid([&] { RelistCrowdLayout(layout, Vector::Zero(5)); }, "2N = 60 entries, got 5");
}

// ---- model functions -------------------------------------------------------------------------

// The columns (x only) of row k of a sparse matrix.
std::vector<int> RowColumns(const SparseMatrix& matrix, int k) {
  std::vector<int> columns;
  for (int j = 0; j < matrix.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(matrix, j); it; ++it) {
      if (it.row() == k) columns.push_back(j);
    }
  }
  return columns;
}

TEST(CrowdModelTest, EveryOutputReadsOnlyItsOwnAgents) {
  const CrowdLayout layout = MakeCrowdLayout(Options(30));
  const Scene scene = MakeCrowdScene(layout);
  ASSERT_EQ(scene.effects.size(), 2u);
  const auto& contacts = std::get<MovingSet>(scene.effects[0]);
  const auto& walls = std::get<MovingSet>(scene.effects[1]);
  ASSERT_EQ(contacts.constraints.num_outputs(), static_cast<int>(layout.pairs.size()));
  ASSERT_EQ(walls.constraints.num_outputs(), static_cast<int>(layout.walls.size()));
  const Vector x = layout.initial_state, u, p = scene.ParameterValues();
  // The coordinates each output may read: its agents' x and y.
  auto agent = [](int i) { return std::vector<int>{2 * i, 2 * i + 1}; };
  auto check = [&](const SmoothFunction& f, int k, std::vector<int> expected, bool curved) {
    Vector value, weights = Vector::Zero(f.num_outputs());
    weights[k] = 1.0;
    SparseMatrix jac, hess;
    const std::vector<int> rows{k};
    f.SparseJacobian(x, u, 0.0, p, Wrt::X(), &value, &jac, &rows);
    f.SparseWeightedHessian(x, u, 0.0, p, Wrt::X(), weights, &hess, &rows);
    std::sort(expected.begin(), expected.end());
    EXPECT_LE(expected.size(), 4u);
    EXPECT_EQ(RowColumns(jac, k), expected) << f.name() << " output " << k;
    for (int j = 0; j < hess.outerSize(); ++j) {
      for (SparseMatrix::InnerIterator it(hess, j); it; ++it) {
        EXPECT_TRUE(std::binary_search(expected.begin(), expected.end(), j) &&
                    std::binary_search(expected.begin(), expected.end(), it.row()))
            << f.name() << " output " << k << ": Hessian entry (" << it.row() << ", " << j << ")";
      }
    }
    EXPECT_EQ(hess.nonZeros() > 0, curved) << f.name() << " output " << k;
  };
  for (int k = 0; k < contacts.constraints.num_outputs(); ++k) {
    const auto [i, j] = layout.pairs[static_cast<std::size_t>(k)];
    std::vector<int> columns = agent(i);
    for (int c : agent(j)) columns.push_back(c);
    check(contacts.constraints, k, columns, true);
  }
  for (int k = 0; k < walls.constraints.num_outputs(); ++k) {
    const CrowdWallConstraint& w = layout.walls[static_cast<std::size_t>(k)];
    switch (w.wall) {
      case CrowdWall::kLeft:
        check(walls.constraints, k, {2 * w.agent}, false);
        break;
      case CrowdWall::kBottom:
      case CrowdWall::kTop:
        check(walls.constraints, k, {2 * w.agent + 1}, false);
        break;
      default:
        check(walls.constraints, k, agent(w.agent), true);
    }
  }
  for (int k = 0; k < scene.num_states(); ++k) check(scene.dynamics, k, agent(k / 2), true);
  // No value-dependent branch: the pattern was detected once per function.
  for (const SmoothFunction* f : {&scene.dynamics, &contacts.constraints, &walls.constraints}) {
    EXPECT_EQ(f->sparse_derivative_stats().num_detections, 1) << f->name();
    EXPECT_FALSE(f->sparse_derivative_stats().point_dependent) << f->name();
  }
}

TEST(CrowdModelTest, ConstraintValuesAreScaledGaps) {
  const CrowdLayout layout = MakeCrowdLayout(Options(30));
  const Scene scene = MakeCrowdScene(layout);
  const Vector x = layout.initial_state, u, p = scene.ParameterValues();
  const double r = layout.options.radius;
  Vector c;
  std::get<MovingSet>(scene.effects[0]).constraints.Evaluate(x, u, 0.0, p, &c);
  for (std::size_t k = 0; k < layout.pairs.size(); ++k) {
    const auto [i, j] = layout.pairs[k];
    const double gap = std::hypot(x[2 * i] - x[2 * j], x[2 * i + 1] - x[2 * j + 1]) - 2.0 * r;
    EXPECT_NEAR(c[static_cast<int>(k)], gap * (1.0 + gap / (4.0 * r)), kPositionSlack);
  }
  std::get<MovingSet>(scene.effects[1]).constraints.Evaluate(x, u, 0.0, p, &c);
  const double jamb = layout.jamb_radius + r;
  for (std::size_t k = 0; k < layout.walls.size(); ++k) {
    const CrowdWallConstraint& w = layout.walls[k];
    const double gap = layout.WallGap(x, w.agent, w.wall);
    const bool straight =
        w.wall == CrowdWall::kLeft || w.wall == CrowdWall::kBottom || w.wall == CrowdWall::kTop;
    EXPECT_NEAR(c[static_cast<int>(k)], straight ? gap : gap * (1.0 + gap / (2.0 * jamb)),
                kPositionSlack * jamb)
        << ToString(w.wall);
  }
  // The desired velocity: speed s toward e, slowed within the smoothing length.
  Vector v;
  scene.dynamics.Evaluate(x, u, 0.0, p, &v);
  for (int i = 0; i < layout.num_agents(); ++i) {
    const double dx = layout.exit_x - x[2 * i], dy = -x[2 * i + 1];
    const double d = std::hypot(dx, dy), s = layout.options.speed, eps = layout.options.smoothing;
    EXPECT_NEAR(v.segment(2 * i, 2).norm(), s * d / std::sqrt(d * d + eps * eps),
                kVelocityTolerance);
    EXPECT_NEAR((v[2 * i] * dy - v[2 * i + 1] * dx) / d, 0.0, kVelocityTolerance);  // along e - q
  }
}

// ---- certificate -----------------------------------------------------------------------------

TEST(CrowdCertificateTest, CatchesInjectedOverlapsOfListedAndUnlistedPairsAndWalls) {
  const CrowdLayout layout = MakeCrowdLayout(Options(100));
  const double r = layout.options.radius;
  const CrowdCertificate start = CertifyCrowdState(layout, layout.initial_state);
  EXPECT_TRUE(start.Feasible(kOverlapTolerance));
  EXPECT_TRUE(start.ListsSufficed());
  // Agents 1 and 100 (0-based 0 and 99) are far apart and unlisted: put 100 onto 1.
  ASSERT_FALSE(std::binary_search(layout.pairs.begin(), layout.pairs.end(), std::make_pair(0, 99)));
  Vector q = layout.initial_state;
  q.segment(198, 2) = q.segment(0, 2) - Vector{{2.0 * r - 0.1, 0.0}};  // left of agent 1
  const CrowdCertificate unlisted = CertifyCrowdState(layout, q);
  EXPECT_FALSE(unlisted.Feasible(kOverlapTolerance));
  EXPECT_FALSE(unlisted.ListsSufficed());
  EXPECT_NEAR(unlisted.min_pair_gap, -0.1, kPositionSlack);
  EXPECT_NEAR(unlisted.min_unlisted_pair_gap, -0.1, kPositionSlack);
  EXPECT_EQ(std::make_pair(unlisted.unlisted_i, unlisted.unlisted_j), std::make_pair(0, 99));
  EXPECT_NE(unlisted.Summary().find("agents 1, 100"), std::string::npos) << unlisted.Summary();
  // A listed pair touching (gap 0) is fine; overlapping by 1e-6 is an overlap, but not a
  // failure of the list.
  const auto [i, j] = layout.pairs.front();
  for (double gap : {0.0, -1e-6}) {
    q = layout.initial_state;
    const Vector d = (q.segment(2 * j, 2) - q.segment(2 * i, 2)).normalized();
    q.segment(2 * j, 2) = q.segment(2 * i, 2) + (2.0 * r + gap) * d;
    const CrowdCertificate listed = CertifyCrowdState(layout, q);
    EXPECT_EQ(listed.Feasible(kOverlapTolerance), gap == 0.0);
    EXPECT_TRUE(listed.ListsSufficed());
    EXPECT_NEAR(listed.min_pair_gap, gap, kPositionSlack);
  }
  // An agent in the middle of the room (no straight-wall constraint) pushed through the top wall.
  const int middle = 55;
  ASSERT_TRUE(std::none_of(layout.walls.begin(), layout.walls.end(), [&](const auto& w) {
    return w.agent == middle && w.wall == CrowdWall::kTop;
  }));
  q = layout.initial_state;
  q[2 * middle + 1] = 0.5 * layout.room_height;
  const CrowdCertificate wall = CertifyCrowdState(layout, q);
  EXPECT_NEAR(wall.min_wall_gap, -r, kPositionSlack);
  EXPECT_EQ(wall.wall_agent, middle);
  EXPECT_EQ(wall.wall, CrowdWall::kTop);
  EXPECT_NEAR(wall.min_unlisted_wall_gap, -r, kPositionSlack);
  EXPECT_FALSE(wall.ListsSufficed());
  ExpectInvalid([&] { CertifyCrowdState(layout, Vector::Zero(4)); }, "2N = 200 entries, got 4");
}

// ---- simulation ------------------------------------------------------------------------------

// FESD on a small crowd: s = 2, H = 0.05 (the measurement settings), over the first
// contacts (walls from t = 1.25, pairs from t = 1.52 with N = 4).
FesdOptions SmallCrowdFesd() {
  FesdOptions options;
  options.stages = 2;
  options.step_size = 0.05;
  options.record_stages = true;
  return options;
}
constexpr double kSmallCrowdHorizon = 2.5;

TEST(CrowdSimulationTest, FesdFormsContactsWithCertifiedElements) {
  for (int agents : {4, 7}) {
    const CrowdLayout layout = MakeCrowdLayout(Options(agents));
    Scene scene = MakeCrowdScene(layout);
    scene.final_time = kSmallCrowdHorizon;
    const FesdResult result = SimulateFesd(scene, SmallCrowdFesd());
    const std::string what = "N = " + std::to_string(agents);
    ASSERT_EQ(result.status, FesdStatus::kSuccess) << what << ": " << result.message;
    int contacts = 0;
    for (const Event& event : result.events) {
      contacts += event.kind == EventKind::kEnter && event.what.rfind("contacts.", 0) == 0;
    }
    EXPECT_GE(contacts, 2) << what;
    for (const FesdElement& element : result.elements) {
      EXPECT_LE(element.complementarity, kComplementarityTolerance)
          << what << " t " << element.t_start;
      EXPECT_LE(element.cross_complementarity, kComplementarityTolerance)
          << what << " t " << element.t_start;
    }
    for (const Trajectory* trajectory : {&result.trajectory, &result.stage_trajectory}) {
      ASSERT_GT(trajectory->size(), 0u);
      for (std::size_t k = 0; k < trajectory->size(); ++k) {
        const CrowdCertificate c = CertifyCrowdState(layout, trajectory->x[k]);
        ASSERT_TRUE(c.Feasible(kOverlapTolerance))
            << what << " t " << trajectory->t[k] << ": " << c.Summary();
        ASSERT_TRUE(c.ListsSufficed()) << what << " t " << trajectory->t[k] << ": " << c.Summary();
      }
    }
  }
}

TEST(CrowdSimulationTest, SegmentsWithRelistedNeighboursContinueTheRun) {
  const CrowdLayout first = MakeCrowdLayout(Options(4));
  Scene scene = MakeCrowdScene(first);
  scene.final_time = 0.5 * kSmallCrowdHorizon;
  const FesdResult a = SimulateFesd(scene, SmallCrowdFesd());
  ASSERT_EQ(a.status, FesdStatus::kSuccess) << a.message;
  const CrowdLayout second = RelistCrowdLayout(first, a.final_state);
  scene = MakeCrowdScene(second);
  scene.initial_time = a.final_time;
  scene.final_time = kSmallCrowdHorizon;
  const FesdResult b = SimulateFesd(scene, SmallCrowdFesd());
  ASSERT_EQ(b.status, FesdStatus::kSuccess) << b.message;
  EXPECT_EQ(b.trajectory.x.front(), a.final_state);
  const CrowdCertificate end = CertifyCrowdState(second, b.final_state);
  EXPECT_TRUE(end.Feasible(kOverlapTolerance)) << end.Summary();
  EXPECT_TRUE(end.ListsSufficed()) << end.Summary();
}

// ---- scene file ------------------------------------------------------------------------------

std::string ExampleFile() { return std::string(MOREAU_EXAMPLES_DIR) + "/scenes/crowd_16.toml"; }

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

TEST(CrowdSceneFileTest, CommittedExampleIsTheGeneratorsOutput) {
  std::ostringstream generated;
  WriteCrowdSceneFile(Options(16), generated);
  EXPECT_EQ(ReadFile(ExampleFile()), generated.str())
      << "regenerate with: moreau crowd-file N=16 > examples/scenes/crowd_16.toml";
}

std::vector<const SmoothFunction*> Functions(const Scene& scene) {
  std::vector<const SmoothFunction*> functions{&scene.dynamics};
  for (const Effect& effect : scene.effects) {
    functions.push_back(&std::get<MovingSet>(effect).constraints);
  }
  return functions;
}

TEST(CrowdSceneFileTest, FileSceneEqualsTheBuiltInScene) {
  for (int agents : {1, 4, 16}) {
    std::ostringstream text;
    WriteCrowdSceneFile(Options(agents), text);
    const Scene file = ParseScene(text.str(), "crowd.toml");
    const Scene built_in = MakeCrowdScene(Options(agents));
    const std::string what = "N = " + std::to_string(agents);
    EXPECT_EQ(file.name, built_in.name);
    EXPECT_EQ(file.state_names, built_in.state_names);
    EXPECT_EQ(file.initial_state, built_in.initial_state) << what;
    EXPECT_EQ(file.final_time, built_in.final_time);
    ASSERT_EQ(file.num_parameters(), built_in.num_parameters());
    for (int k = 0; k < file.num_parameters(); ++k) {
      EXPECT_EQ(file.parameters[k].name, built_in.parameters[k].name);
      EXPECT_EQ(file.parameters[k].value, built_in.parameters[k].value);
    }
    ASSERT_EQ(file.effects.size(), built_in.effects.size()) << what;
    for (std::size_t e = 0; e < file.effects.size(); ++e) {
      EXPECT_EQ(std::get<MovingSet>(file.effects[e]).name,
                std::get<MovingSet>(built_in.effects[e]).name);
      EXPECT_EQ(std::get<MovingSet>(file.effects[e]).constraint_names,
                std::get<MovingSet>(built_in.effects[e]).constraint_names);
    }
    const LoweredSystem lowered_file(file), lowered_built_in(built_in);
    EXPECT_EQ(lowered_file.num_states(), lowered_built_in.num_states());
    EXPECT_EQ(lowered_file.num_algebraic(), lowered_built_in.num_algebraic());
    EXPECT_EQ(lowered_file.num_pairs(), lowered_built_in.num_pairs());
    // Values and exact derivatives at random points near the crowd (x, t and p).
    const auto fa = Functions(file), fb = Functions(built_in);
    std::mt19937 random(static_cast<unsigned>(agents));
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    for (int trial = 0; trial < 3; ++trial) {
      Vector x = built_in.initial_state, u, p = built_in.ParameterValues();
      for (int i = 0; i < x.size(); ++i) x[i] += 2.0 * uniform(random);
      for (int i = 0; i < p.size(); ++i) p[i] += 0.1 * uniform(random);
      for (std::size_t f = 0; f < fa.size(); ++f) {
        Vector va, vb;
        Matrix ja, jb, ha, hb;
        fa[f]->Jacobian(x, u, 0.3, p, Wrt::All(), &va, &ja);
        fb[f]->Jacobian(x, u, 0.3, p, Wrt::All(), &vb, &jb);
        const Vector weights =
            Vector::NullaryExpr(fb[f]->num_outputs(), [&] { return uniform(random); });
        fa[f]->WeightedHessian(x, u, 0.3, p, Wrt::All(), weights, &ha);
        fb[f]->WeightedHessian(x, u, 0.3, p, Wrt::All(), weights, &hb);
        const std::string name = what + " " + fb[f]->name();
        EXPECT_LE((va - vb).lpNorm<Eigen::Infinity>(),
                  kDerivativeTolerance * std::max(1.0, vb.lpNorm<Eigen::Infinity>()))
            << name;
        EXPECT_LE((ja - jb).lpNorm<Eigen::Infinity>(),
                  kDerivativeTolerance * std::max(1.0, jb.lpNorm<Eigen::Infinity>()))
            << name;
        EXPECT_LE((ha - hb).lpNorm<Eigen::Infinity>(),
                  kDerivativeTolerance * std::max(1.0, hb.lpNorm<Eigen::Infinity>()))
            << name;
      }
    }
  }
}

TEST(CrowdSceneFileTest, FileAndBuiltInFesdTrajectoriesAgree) {
  std::ostringstream text;
  WriteCrowdSceneFile(Options(4), text);
  Scene file = ParseScene(text.str(), "crowd.toml");
  Scene built_in = MakeCrowdScene(Options(4));
  file.final_time = built_in.final_time = kSmallCrowdHorizon;
  const FesdResult a = SimulateFesd(file, SmallCrowdFesd());
  const FesdResult b = SimulateFesd(built_in, SmallCrowdFesd());
  ASSERT_EQ(a.status, FesdStatus::kSuccess) << a.message;
  ASSERT_EQ(b.status, FesdStatus::kSuccess) << b.message;
  ASSERT_EQ(a.events.size(), b.events.size());
  EXPECT_GE(b.events.size(), 3u);  // contacts form in this horizon
  for (std::size_t k = 0; k < a.events.size(); ++k) {
    EXPECT_NEAR(a.events[k].t, b.events[k].t, kTrajectoryTolerance) << k;
    EXPECT_EQ(a.events[k].what, b.events[k].what) << k;
  }
  ASSERT_EQ(a.trajectory.size(), b.trajectory.size());
  for (std::size_t k = 0; k < a.trajectory.size(); ++k) {
    EXPECT_NEAR(a.trajectory.t[k], b.trajectory.t[k], kTrajectoryTolerance) << k;
    EXPECT_LE((a.trajectory.x[k] - b.trajectory.x[k]).lpNorm<Eigen::Infinity>(),
              kTrajectoryTolerance)
        << "point " << k;
  }
}

// ---- command line ----------------------------------------------------------------------------

TEST(CrowdCliTest, CrowdFileAndSceneNames) {
  const testing::CliOutcome file = testing::RunCli("crowd-file N=16");
  EXPECT_EQ(file.exit_code, 0) << file.output;
  EXPECT_EQ(file.output, ReadFile(ExampleFile()));
  const testing::CliOutcome bad = testing::RunCli("crowd-file N=16 jitter=1.5");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("jitter must be in [0, 1), got 1.5"), std::string::npos) << bad.output;
  const testing::CliOutcome check = testing::RunCli("check crowd:N=9,seed=2");
  EXPECT_EQ(check.exit_code, 0) << check.output;
  EXPECT_NE(check.output.find("scene       crowd_N9_seed2: valid"), std::string::npos)
      << check.output;
  const testing::CliOutcome from_file = testing::RunCli("check " + ExampleFile());
  EXPECT_EQ(from_file.exit_code, 0) << from_file.output;
  const testing::CliOutcome unknown = testing::RunCli("show crowd:M=1");
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_NE(unknown.output.find("unknown crowd option 'M'"), std::string::npos) << unknown.output;
}

}  // namespace
}  // namespace moreau
