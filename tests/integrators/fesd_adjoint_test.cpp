// Directional and adjoint sensitivities of FESD (docs/sensitivities.md): against the products
// with the full matrices on every catalog scene FESD runs with sensitivities (switches,
// sliding, relays by time-freezing, complementarity pairs), fixed steps and the replay of an
// adaptive run; sample times; kept reverse sweeps; central differences where the map is
// smooth; bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Directional and adjoint results against the products with the full matrix: the same
// implicit-function-theorem solves with the same factorizations, chained in another order,
// so they agree to round-off amplified by the chain (relative to the products' size).
constexpr double kProductTolerance = 1e-10;

// Relative distance of `value` from `expected`, in units of expected's largest entry (at least
// one: entries that are zero up to round-off compare absolutely).
double RelativeError(const Matrix& value, const Matrix& expected) {
  EXPECT_EQ(value.rows(), expected.rows());
  EXPECT_EQ(value.cols(), expected.cols());
  if (value.rows() != expected.rows() || value.cols() != expected.cols()) return INFINITY;
  return (value - expected).lpNorm<Eigen::Infinity>() /
         std::max(1.0, expected.lpNorm<Eigen::Infinity>());
}

Matrix Random(Eigen::Index rows, Eigen::Index cols, unsigned seed) {
  std::mt19937 generator(seed);
  std::normal_distribution<double> normal;
  Matrix m(rows, cols);
  for (Eigen::Index j = 0; j < cols; ++j) {
    for (Eigen::Index i = 0; i < rows; ++i) m(i, j) = normal(generator);
  }
  return m;
}

// The full matrix dx(T)/dtheta, theta = (x0, p, u per segment).
Matrix Full(const FesdSensitivities& s) {
  Matrix full(s.initial_state.rows(),
              s.initial_state.cols() + s.parameters.cols() + s.inputs.cols());
  full << s.initial_state, s.parameters, s.inputs;
  return full;
}

struct Comparison {
  double directional = 0.0, adjoint = 0.0, directional_lowered = 0.0, adjoint_lowered = 0.0;
};

// One run with full, directional (3 directions) and adjoint (2 weights) sensitivities.
Comparison Compare(const Scene& scene, FesdOptions options, FesdResult* out = nullptr) {
  options.sensitivities = true;
  const int nx = scene.num_states();
  FesdResult probe;
  {
    FesdOptions full_only = options;
    probe = SimulateFesd(scene, full_only);
  }
  EXPECT_EQ(probe.status, FesdStatus::kSuccess) << scene.name << ": " << probe.message;
  const Matrix full = Full(probe.sensitivities);
  const Matrix& lowered = probe.sensitivities.lowered;
  const auto n_theta = full.cols();
  options.sensitivity_directions = Random(n_theta, 3, 11);
  options.adjoint_weights = Random(nx, 2, 12);
  const FesdResult result = SimulateFesd(scene, options);
  EXPECT_EQ(result.status, FesdStatus::kSuccess) << scene.name << ": " << result.message;
  // The full matrices of a run with directions and adjoint weights are those of a plain one:
  // tracking them changes nothing in the run.
  EXPECT_EQ(Full(result.sensitivities), full) << scene.name;
  Comparison c;
  c.directional =
      RelativeError(result.sensitivities.directional, full * options.sensitivity_directions);
  c.adjoint =
      RelativeError(result.sensitivities.adjoint, options.adjoint_weights.transpose() * full);
  // Over the lowered theta_L = (y0, p, u): lowered directions and weights of y(T).
  const auto ny = lowered.rows();
  FesdOptions lowered_options = options;
  lowered_options.sensitivity_directions = Random(lowered.cols(), 2, 13);
  lowered_options.adjoint_weights = Random(ny, 2, 14);
  const FesdResult lowered_result = SimulateFesd(scene, lowered_options);
  EXPECT_EQ(lowered_result.status, FesdStatus::kSuccess) << lowered_result.message;
  c.directional_lowered = RelativeError(lowered_result.sensitivities.directional_lowered,
                                        lowered * lowered_options.sensitivity_directions);
  c.adjoint_lowered = RelativeError(lowered_result.sensitivities.adjoint_lowered,
                                    lowered_options.adjoint_weights.transpose() * lowered);
  if (out != nullptr) *out = result;
  return c;
}

void ExpectAgreement(const Comparison& c, const std::string& what) {
  EXPECT_LE(c.directional, kProductTolerance) << what << ": directional";
  EXPECT_LE(c.adjoint, kProductTolerance) << what << ": adjoint";
  EXPECT_LE(c.directional_lowered, kProductTolerance) << what << ": directional (lowered)";
  EXPECT_LE(c.adjoint_lowered, kProductTolerance) << what << ": adjoint (lowered)";
}

bool FesdRunsWithSensitivities(const Scene& scene) {
  const std::vector<std::string> supporting = IntegratorsSupporting(scene);
  return std::find(supporting.begin(), supporting.end(), "fesd") != supporting.end() &&
         !scene.dynamics.has_sparse_state_jacobian();
}

// Every catalog scene FESD simulates with sensitivities, fixed steps. The horizon is cut to
// keep the suite fast, still past the first switches of every scene with effects.
TEST(FesdAdjointTest, DirectionalAndAdjointEqualFullProductsOnTheCatalog) {
  int compared = 0;
  for (const SceneDefinition& definition : SceneCatalog()) {
    Scene scene = definition.make();
    if (!FesdRunsWithSensitivities(scene)) continue;
    if (definition.name == "crowd") continue;  // its own test below (N = 16)
    scene.final_time = std::min(scene.final_time, scene.initial_time + 3.0);
    FesdOptions options;
    options.step_size = std::min(0.05, (scene.final_time - scene.initial_time) / 20);
    FesdResult result;
    const Comparison c = Compare(scene, options, &result);
    if (result.status != FesdStatus::kSuccess) continue;  // reported by Compare
    ExpectAgreement(c, definition.name);
    ++compared;
    RecordProperty(definition.name, std::to_string(result.stats.num_switches) + " switches");
  }
  EXPECT_GE(compared, 10);
}

TEST(FesdAdjointTest, DirectionalAndAdjointOnTheCrowd) {
  Scene scene = MakeScene("crowd:N=16");
  scene.final_time = 2.0;
  FesdOptions options;
  options.step_size = 0.1;
  FesdResult result;
  ExpectAgreement(Compare(scene, options, &result), "crowd:N=16");
}

// The replay of an adaptive run (step_sequence) and the adaptive run itself: their derivatives
// are those of the accepted step sequence with the step sizes held fixed.
TEST(FesdAdjointTest, DirectionalAndAdjointOfAdaptiveRunsAndReplays) {
  for (const char* name : {"F1", "H1", "S3", "rectifier"}) {
    Scene scene = MakeScene(name);
    scene.final_time = std::min(scene.final_time, scene.initial_time + 3.0);
    FesdOptions adaptive;
    adaptive.adaptive = true;
    adaptive.step_size = 0.0;
    adaptive.relative_tolerance = 1e-6;
    FesdResult run;
    ExpectAgreement(Compare(scene, adaptive, &run), std::string(name) + " adaptive");
    FesdOptions replay;
    replay.step_sequence = run.step_sequence;
    ExpectAgreement(Compare(scene, replay), std::string(name) + " replay");
  }
}

// Sample times: the directions at a sample time equal the full matrix of the run stopped
// there (same grid), and the adjoint of the sample weights its product; a kept sweep gives
// the in-run adjoint again.
TEST(FesdAdjointTest, SampleTimesAndKeptSweeps) {
  const Scene scene = MakeScene("F1");  // switches at t = 1
  FesdOptions options;
  options.step_size = 0.05;
  options.sample_times = {0.5, 1.2};
  const int nx = scene.num_states();
  const Eigen::Index n_theta = nx + scene.num_parameters();
  options.sensitivity_directions = Random(n_theta, 2, 21);
  options.adjoint_weights = Random(nx, 1, 22);
  options.adjoint_sample_weights = Random(nx, 2, 23);  // one column per sample time
  options.keep_adjoint = true;
  const FesdResult result = SimulateFesd(scene, options);
  ASSERT_EQ(result.status, FesdStatus::kSuccess) << result.message;
  ASSERT_EQ(result.sample_states.size(), 2u);
  ASSERT_EQ(result.sensitivities.sample_directional.size(), 2u);
  Matrix expected_adjoint = Matrix::Zero(1, n_theta);
  for (std::size_t j = 0; j < 2; ++j) {
    Scene stopped = scene;
    stopped.final_time = options.sample_times[j];
    FesdOptions full;
    full.step_size = options.step_size;
    full.sensitivities = true;
    const FesdResult part = SimulateFesd(stopped, full);
    ASSERT_EQ(part.status, FesdStatus::kSuccess) << part.message;
    EXPECT_LE((result.sample_states[j].head(nx) - part.final_state).lpNorm<Eigen::Infinity>(),
              1e-14);
    const Matrix f = Full(part.sensitivities);
    EXPECT_LE(RelativeError(result.sensitivities.sample_directional[j],
                            f * options.sensitivity_directions),
              kProductTolerance)
        << "sample " << j;
    expected_adjoint +=
        options.adjoint_sample_weights.col(static_cast<Eigen::Index>(j)).transpose() * f;
  }
  FesdOptions full;
  full.step_size = options.step_size;
  full.sensitivities = true;
  const Matrix f = Full(SimulateFesd(scene, full).sensitivities);
  expected_adjoint += options.adjoint_weights.transpose() * f;
  EXPECT_LE(RelativeError(result.sensitivities.adjoint, expected_adjoint), kProductTolerance);
  // The kept sweep with the same weights gives the same gradient, and other weights theirs.
  ASSERT_NE(result.adjoint, nullptr);
  const FesdGradient again =
      result.adjoint->Sweep(options.adjoint_weights, options.adjoint_sample_weights);
  ASSERT_TRUE(again.success) << again.message;
  EXPECT_EQ(again.theta, result.sensitivities.adjoint);
  const Matrix other = Random(nx, 3, 24);
  const FesdGradient swept = result.adjoint->Sweep(other);
  EXPECT_LE(RelativeError(swept.theta, other.transpose() * f), kProductTolerance);
}

// The memory bound: checkpoints beyond adjoint_memory_limit_mb go to a file and come back
// bit for bit, so the gradient is the in-memory one exactly.
TEST(FesdAdjointTest, CheckpointsBeyondTheMemoryBoundGoToAFile) {
  Scene scene = MakeScene("crowd:N=16");
  scene.final_time = 1.0;
  FesdOptions options;
  options.step_size = 0.1;
  options.adjoint_weights = Random(scene.num_states(), 2, 51);
  const FesdResult in_memory = SimulateFesd(scene, options);
  ASSERT_EQ(in_memory.status, FesdStatus::kSuccess) << in_memory.message;
  EXPECT_EQ(in_memory.stats.adjoint_file_bytes, 0.0);
  options.adjoint_memory_limit_mb = 0.25 * in_memory.stats.adjoint_memory_bytes / (1024 * 1024);
  const FesdResult bounded = SimulateFesd(scene, options);
  ASSERT_EQ(bounded.status, FesdStatus::kSuccess) << bounded.message;
  EXPECT_GT(bounded.stats.adjoint_file_bytes, 0.0);
  // What stays in memory: the checkpoints up to the bound and every group's bookkeeping
  // (statuses, lengths: a few hundred bytes a group).
  EXPECT_LT(bounded.stats.adjoint_memory_bytes, 0.5 * in_memory.stats.adjoint_memory_bytes);
  EXPECT_EQ(bounded.sensitivities.adjoint, in_memory.sensitivities.adjoint);
}

// Kept sweeps through FesdIntegrator (a shared lowered system): a later run with other values
// does not change an earlier run's sweep.
TEST(FesdAdjointTest, KeptSweepsOfAnIntegratorStayValid) {
  Scene scene = MakeScene("F1");
  FesdOptions options;
  options.step_size = 0.05;
  options.keep_adjoint = true;
  FesdIntegrator integrator(scene, options);
  const FesdResult first = integrator.Simulate(scene);
  Scene other = scene;
  other.parameters[0].value *= 1.1;
  other.initial_state[0] *= 0.9;
  const FesdResult second = integrator.Simulate(other);
  ASSERT_EQ(first.status, FesdStatus::kSuccess) << first.message;
  ASSERT_EQ(second.status, FesdStatus::kSuccess) << second.message;
  FesdOptions full = options;
  full.keep_adjoint = false;
  full.sensitivities = true;
  const Matrix f = Full(SimulateFesd(scene, full).sensitivities);
  const Matrix w = Random(2, 2, 31);
  EXPECT_LE(RelativeError(first.adjoint->Sweep(w).theta, w.transpose() * f), kProductTolerance);
}

// Where the map is smooth (no switch moves across a step boundary), the adjoint gradient of a
// scalar objective against central differences of whole runs: the crowd (contacts, sparse
// products) with respect to the desired speed and smoothing length and some coordinates.
TEST(FesdAdjointTest, CrowdGradientAgainstCentralDifferences) {
  Scene scene = MakeScene("crowd:N=9");
  scene.final_time = 1.5;
  FesdOptions options;
  options.step_size = 0.1;
  const int nx = scene.num_states();
  const Vector target = Random(nx, 1, 41);
  // f = 1/2 |x(T) - target|^2: W = x(T) - target, known after the run (kept sweep).
  options.keep_adjoint = true;
  const FesdResult result = SimulateFesd(scene, options);
  ASSERT_EQ(result.status, FesdStatus::kSuccess) << result.message;
  const Vector residual = result.final_state - target;
  const FesdGradient gradient = result.adjoint->Sweep(residual);
  ASSERT_TRUE(gradient.success) << gradient.message;
  FesdOptions plain;
  plain.step_size = options.step_size;
  auto objective = [&](const Scene& s) {
    const FesdResult r = SimulateFesd(s, plain);
    EXPECT_EQ(r.status, FesdStatus::kSuccess) << r.message;
    return 0.5 * (r.final_state - target).squaredNorm();
  };
  constexpr double kStep = 1e-6;      // central differences: O(kStep^2) truncation
  constexpr double kRelative = 1e-6;  // acceptance
  auto expect = [&](double derivative, Scene plus, Scene minus, const std::string& what) {
    const double fd = (objective(plus) - objective(minus)) / (2 * kStep);
    EXPECT_NEAR(derivative, fd, kRelative * std::max(1.0, std::fabs(fd))) << what;
  };
  for (int j : {0, 1, 7, nx - 1}) {
    Scene plus = scene, minus = scene;
    plus.initial_state[j] += kStep;
    minus.initial_state[j] -= kStep;
    expect(gradient.theta(0, j), plus, minus, "x0_" + std::to_string(j));
  }
  for (int k = 0; k < scene.num_parameters(); ++k) {
    Scene plus = scene, minus = scene;
    plus.parameters[static_cast<std::size_t>(k)].value += kStep;
    minus.parameters[static_cast<std::size_t>(k)].value -= kStep;
    expect(gradient.theta(0, nx + k), plus, minus,
           scene.parameters[static_cast<std::size_t>(k)].name);
  }
}

TEST(FesdAdjointTest, BadInputIsRefusedWithAClearMessage) {
  const Scene scene = MakeScene("F1");
  FesdOptions options;
  options.step_size = 0.05;
  // n_theta = 3 (x0, omega): 3 rows, or 4 over the lowered (x1, x2, clock, omega); 5 fits none.
  options.sensitivity_directions = Matrix::Ones(5, 1);
  EXPECT_THROW(
      {
        try {
          SimulateFesd(scene, options);
        } catch (const std::invalid_argument& e) {
          EXPECT_NE(std::string(e.what()).find("sensitivity directions"), std::string::npos)
              << e.what();
          throw;
        }
      },
      std::invalid_argument);
  options.sensitivity_directions = Matrix();
  options.sample_times = {0.33};  // not a multiple of h = 0.05
  options.keep_adjoint = true;
  EXPECT_THROW(SimulateFesd(scene, options), std::invalid_argument);
  options.sample_times = {0.5, 0.4};
  EXPECT_THROW(SimulateFesd(scene, options), std::invalid_argument);
  options.sample_times = {5.0};  // beyond tf = pi/2
  EXPECT_THROW(SimulateFesd(scene, options), std::invalid_argument);
  options.sample_times = {0.5};
  const FesdResult kept = SimulateFesd(scene, options);
  ASSERT_EQ(kept.status, FesdStatus::kSuccess) << kept.message;
  EXPECT_THROW(kept.adjoint->Sweep(Matrix::Ones(5, 1)), std::invalid_argument);  // n_x 2, n_y 3
  EXPECT_THROW(kept.adjoint->Sweep(Matrix::Ones(2, 1), Matrix::Ones(2, 3)), std::invalid_argument);
  EXPECT_THROW(kept.adjoint->Sweep(Matrix()), std::invalid_argument);
}

// Through Simulate (the declared options): lists column by column, results in
// SimulationResult, the kept sweep as AdjointSweep.
TEST(FesdAdjointTest, SimulateOptionsAndResults) {
  const Scene scene = MakeScene("F1");
  SimulationSettings settings;
  settings.integrator = "fesd";
  settings.options["h"] = 0.05;
  settings.options["sensitivities"] = true;
  settings.options["directions"] = std::vector<double>{1, 0, 0, 0, 0, 1};  // e_x1, e_omega
  settings.options["adjoint_weights"] = std::vector<double>{0, 1};         // x2(T)
  settings.options["sample_times"] = std::vector<double>{1.0};
  settings.options["keep_adjoint"] = true;
  const SimulationResult result = Simulate(scene, settings);
  ASSERT_TRUE(result.success) << result.message;
  ASSERT_TRUE(result.sensitivities.has_value());
  const SimulationSensitivities& s = *result.sensitivities;
  Matrix full(2, 3);
  full << s.initial_state, s.parameters;
  EXPECT_LE(RelativeError(s.directional.col(0), full.col(0)), kProductTolerance);
  EXPECT_LE(RelativeError(s.directional.col(1), full.col(2)), kProductTolerance);
  EXPECT_LE(RelativeError(s.adjoint, full.row(1)), kProductTolerance);
  ASSERT_EQ(result.sample_states.size(), 1u);
  ASSERT_NE(result.adjoint, nullptr);
  const AdjointGradient gradient = result.adjoint->Gradient(Matrix::Identity(2, 2), Matrix());
  ASSERT_TRUE(gradient.success) << gradient.message;
  EXPECT_LE(RelativeError(gradient.theta, full), kProductTolerance);
  EXPECT_GT(result.Stat("adjoint_memory_bytes"), 0.0);
}

}  // namespace
}  // namespace moreau
