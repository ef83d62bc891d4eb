// Optimal control by multiple/single shooting on FESD (docs/ocp.md): known optima, time-optimal
// hysteresis, terminal constraints verified by an IDA re-simulation, and the NLP's exact first
// derivatives against central finite differences.
#include "moreau/ocp/ocp.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "moreau/model/scene_file.hpp"
#include "moreau/ocp/catalog.hpp"

namespace moreau {
namespace {

// Stewart-Anitescu: J(x0) = int_0^2 x^2 dt + (x(2) - 5/3)^2 with x' = 3 until the switch at
// t_s = -x0/3 (x0 < 0), then x' = 1. Integrating, J(x0) = -x0^3/9 + (2 + x0/3)^3/3
// + (1/3 + x0/3)^2, whose stationary point (the minimum over x0 in (-6, 0)) solves
// 4 x0^2 - 9 x0 - 21 = 0: x0* = (9 - sqrt(417))/8 (docs/ocp.md).
double StewartAnitescuCost(double x0) {
  return -x0 * x0 * x0 / 9.0 + std::pow(2.0 + x0 / 3.0, 3) / 3.0 +
         std::pow(1.0 / 3.0 + x0 / 3.0, 2);
}
const double kStewartAnitescuOptimum = (9.0 - std::sqrt(417.0)) / 8.0;

// Acceptance bounds of the issue: x0* within 1e-6, the cost within 1e-8 (the FESD
// discretization is exact here: piecewise-linear dynamics with the switch on an element
// boundary, so only IPOPT's tolerance 1e-10 and the Newton tolerances remain).
constexpr double kOptimumTolerance = 1e-6;
constexpr double kCostTolerance = 1e-8;
// Terminal constraints of the re-simulated optimum (IDA, rtol 1e-12), from the issue.
constexpr double kResimulationTolerance = 1e-6;
// IPOPT iterations with the catalog's options (`moreau ocp <problem>`; docs/ocp.md, "Before
// and after"), all homotopy levels counted, guarded with a margin of about 30% for changes of
// the path at round-off level: stewart_anitescu 6, turbo_car 34, wave_rider 58 (the issue's
// bound is 100).
constexpr int kStewartAnitescuIterations = 8;
constexpr int kTurboCarIterations = 45;
// Mesh continuation N = 10 -> 20 (docs/ocp.md, "Scaling in N"): measured 42 over both meshes
// (124 for N = 20 solved directly), about 30% margin.
constexpr int kTurboCarMeshContinuationIterations = 55;
constexpr int kWaveRiderIterations = 75;
// The bound on the wave-rider's iterations from random starts.
constexpr int kWaveRiderRandomStartIterations = 100;

TEST(Ocp, StewartAnitescuFindsTheClosedFormOptimumBeyondTheSwitch) {
  const OcpResult result =
      SolveOcp(MakeOcpProblem("stewart_anitescu"), MakeOcpOptions("stewart_anitescu"));
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;  // a regular problem
  EXPECT_LE(result.stats.iterations, kStewartAnitescuIterations);
  EXPECT_NEAR(result.initial_state[0], kStewartAnitescuOptimum, kOptimumTolerance);
  EXPECT_NEAR(result.objective, StewartAnitescuCost(kStewartAnitescuOptimum), kCostTolerance);
  // The switch at -x0*/3 is where the cost's x0-dependence changes: it must be detected.
  ASSERT_EQ(result.events.size(), 1u);
  EXPECT_NEAR(result.events[0].t, -kStewartAnitescuOptimum / 3.0, kOptimumTolerance);
  ASSERT_TRUE(result.verified) << result.verification_message;
}

// The OCP layer takes scenes from files unchanged: F4 from examples/scenes/F4.toml gives the
// same optimum as the compiled F4.
TEST(Ocp, StewartAnitescuOnTheSceneFile) {
  OcpProblem problem = MakeOcpProblem("stewart_anitescu");
  problem.scene = LoadScene(std::string(MOREAU_EXAMPLES_DIR) + "/scenes/F4.toml");
  problem.scene.initial_state[0] = -1.0;  // the problem's initial guess of x0
  const OcpResult result = SolveOcp(problem);
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;
  EXPECT_NEAR(result.initial_state[0], kStewartAnitescuOptimum, kOptimumTolerance);
  EXPECT_NEAR(result.objective, StewartAnitescuCost(kStewartAnitescuOptimum), kCostTolerance);
}

TEST(Ocp, StewartAnitescuSingleShootingAgrees) {
  OcpOptions options;
  options.transcription = OcpTranscription::kSingleShooting;
  const OcpResult result = SolveOcp(MakeOcpProblem("stewart_anitescu"), options);
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;
  EXPECT_NEAR(result.initial_state[0], kStewartAnitescuOptimum, kOptimumTolerance);
  EXPECT_NEAR(result.objective, StewartAnitescuCost(kStewartAnitescuOptimum), kCostTolerance);
}

// A homotopy through smoothed Filippov dynamics (time-stepping with a b = mu^2) ends on the
// same exact optimum: the levels hand over primal-dual points, and the exact level is FESD.
TEST(Ocp, StewartAnitescuThroughSmoothedLevels) {
  OcpOptions options = MakeOcpOptions("stewart_anitescu");
  options.homotopy = {{0.3, 0.0, {}}, {0.03, 0.0, {}}};
  const OcpResult result = SolveOcp(MakeOcpProblem("stewart_anitescu"), options);
  ASSERT_EQ(result.levels.size(), 3u);
  for (const OcpLevelResult& level : result.levels) {
    EXPECT_EQ(level.status, OcpStatus::kSolved) << level.message;
  }
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;
  EXPECT_NEAR(result.initial_state[0], kStewartAnitescuOptimum, kOptimumTolerance);
  EXPECT_NEAR(result.objective, StewartAnitescuCost(kStewartAnitescuOptimum), kCostTolerance);
}

TEST(Ocp, TurboCarTimeOptimalWithHysteresis) {
  const OcpResult result = SolveOcp(MakeOcpProblem("turbo_car"), MakeOcpOptions("turbo_car"));
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;  // a regular problem
  EXPECT_LE(result.stats.iterations, kTurboCarIterations);
  // Between the continuous-time optimum and the seed's reported 10.26 (issue 10). The lower
  // bound is a true lower bound of every feasible control, so allow only IPOPT's tolerance.
  EXPECT_GE(result.final_time, 152.0 / 15.0 - 1e-8);
  EXPECT_LE(result.final_time, 10.26);
  ASSERT_TRUE(result.verified) << result.verification_message;
  EXPECT_LE(result.resimulated_terminal_error, kResimulationTolerance);
  // The turbo engages (v = 15) and disengages (v = 10) on the way: one jump each.
  ASSERT_EQ(result.relays.size(), 1u);
  EXPECT_EQ(result.relays[0].jump_times.size(), 2u);
}

// Mesh continuation: the catalog solves N = 10 first, prolongates its decisions to N = 20 and
// solves the exact problem there. The refined grid contains the coarse one and FESD integrates
// the piecewise-linear dynamics exactly, so the continuous-time optimum 152/15 is attainable at
// N = 20 as well: both bounds are IPOPT's tolerance.
TEST(Ocp, TurboCarMeshContinuationReachesTheContinuousOptimum) {
  OcpProblem problem = MakeOcpProblem("turbo_car");
  problem.intervals = 20;
  problem.initial_controls.resize(0, 0);  // the catalog's guess is for N = 10
  const OcpResult result = SolveOcp(problem, MakeOcpOptions("turbo_car"));
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;
  ASSERT_EQ(result.levels.size(), 2u);
  EXPECT_EQ(result.levels.front().intervals, 10);
  EXPECT_EQ(result.levels.back().intervals, 20);
  EXPECT_EQ(result.controls.rows(), 20);
  EXPECT_LE(result.stats.iterations, kTurboCarMeshContinuationIterations);
  EXPECT_GE(result.final_time, 152.0 / 15.0 - 1e-8);
  EXPECT_LE(result.final_time, 152.0 / 15.0 + kOptimumTolerance);
  ASSERT_TRUE(result.verified) << result.verification_message;
  EXPECT_LE(result.resimulated_terminal_error, kResimulationTolerance);
}

// The wave-rider's optimum in closed form (docs/ocp.md, "Wave-rider"). With phi = x2 - t the
// state flies free while the boundary is away (phi' = u - 1), rides it from phi = -phi0
// (contact) to phi = -pi (the crest, x1 = 1) with phi' = (u - 1)/(1 + sin^2 phi), and flies free
// again to phi(T) = x2(T) - T. Time per unit of phi is m(phi)/(1 - u) with m = 1 or 1 + sin^2,
// so min int u^2 dt = int u^2 m/(1 - u) dphi subject to int m/(1 - u) dphi = T gives a constant
// u* = 1 - I/T, I = int m dphi = 2 phi0 + (3/2)(pi - phi0) + sin(2 phi0)/4 - pi - phi(T), and
// J* = T u*^2. phi0 = x2(0) of the projected initial state.
struct WaveRiderOptimum {
  double control = 0.0;
  double cost = 0.0;
};
WaveRiderOptimum WaveRiderClosedForm(double phi0, double horizon, double x2_final) {
  const double phi_final = x2_final - horizon;
  const double integral =
      2.0 * phi0 + 1.5 * (M_PI - phi0) + std::sin(2.0 * phi0) / 4.0 - M_PI - phi_final;
  const double u = 1.0 - integral / horizon;
  return {u, horizon * u * u};
}
// The discretized optimum (N = 10, s = 3 FESD) against the closed form: measured 2.2e-8 in the
// cost; the bound allows the discretization error of s = 3 with three elements per interval
// (terminal errors of 5e-8, docs/ocp.md) two orders of margin.
constexpr double kWaveRiderCostTolerance = 1e-6;
constexpr double kWaveRiderControlTolerance = 1e-5;

void ExpectWaveRiderOptimum(const OcpProblem& problem, const OcpResult& result) {
  const WaveRiderOptimum optimum =
      WaveRiderClosedForm(problem.scene.initial_state[1], problem.scene.final_time, 4.0);
  ASSERT_EQ(result.status, OcpStatus::kSolved) << result.message;
  EXPECT_NEAR(result.objective, optimum.cost, kWaveRiderCostTolerance);
  for (Eigen::Index k = 0; k < result.controls.rows(); ++k) {
    EXPECT_NEAR(result.controls(k, 0), optimum.control, kWaveRiderControlTolerance) << "k " << k;
  }
  EXPECT_NEAR(result.final_state[0], 1.0, kResimulationTolerance);
  EXPECT_NEAR(result.final_state[1], 4.0, kResimulationTolerance);
}

TEST(Ocp, WaveRiderReachesTheClosedFormOptimum) {
  const OcpProblem problem = MakeOcpProblem("wave_rider");
  const OcpResult result = SolveOcp(problem, MakeOcpOptions("wave_rider"));
  ExpectWaveRiderOptimum(problem, result);
  EXPECT_LE(result.stats.iterations, kWaveRiderIterations);
  // Relaxed levels first (the degenerate x1(T) = 1, docs/ocp.md), then the exact problem.
  ASSERT_EQ(result.levels.size(), 3u);
  EXPECT_GT(result.levels[0].parameters.relaxation, 0.0);
  EXPECT_EQ(result.levels.back().parameters.relaxation, 0.0);
  ASSERT_TRUE(result.verified) << result.verification_message;
  EXPECT_LE(result.resimulated_terminal_error, kResimulationTolerance);
  EXPECT_FALSE(result.events.empty());  // the boundary does the work
}

// An optimum of a discretization too coarse for its own trajectory is not reported as solved:
// wave_rider on N = 2 intervals of one implicit-Euler element (s = 1) is a converged NLP whose
// controls, re-simulated by IDA and by FESD on a fine grid, end 0.57 away from its x(T)
// (measured), far above kOcpVerificationTolerance: status not_verified, the gap reported.
TEST(Ocp, CoarseOptimumWhoseResimulationDisagreesIsNotVerified) {
  OcpProblem problem = MakeOcpProblem("wave_rider");
  problem.intervals = 2;
  problem.initial_controls.resize(0, 0);  // as `moreau ocp wave_rider --N 2`
  OcpOptions options = MakeOcpOptions("wave_rider");
  options.stages = 1;
  options.finite_elements = 1;
  const OcpResult result = SolveOcp(problem, options);
  EXPECT_EQ(result.status, OcpStatus::kNotVerified) << result.message;
  EXPECT_EQ(ToString(result.status), "not_verified");
  const double allowed =
      kOcpVerificationTolerance * std::max(1.0, result.final_state.lpNorm<Eigen::Infinity>());
  EXPECT_GT(result.verification_gap, allowed);
  EXPECT_NE(result.message.find("re-simulated end"), std::string::npos) << result.message;
  // The regular discretization verifies (WaveRiderReachesTheClosedFormOptimum: solved).
}

// The acceptance: five seeded random starts (controls uniform in [-1, 1] per interval,
// node states from a forward simulation), each solved in at most 100 IPOPT iterations, all to
// the same optimum (docs/ocp.md lists the counts).
TEST(Ocp, WaveRiderFromRandomStarts) {
  const OcpOptions options = MakeOcpOptions("wave_rider");
  for (unsigned seed = 1; seed <= 5; ++seed) {
    OcpProblem problem = MakeOcpProblem("wave_rider");
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    problem.initial_controls.resize(problem.intervals, 1);
    for (Eigen::Index k = 0; k < problem.intervals; ++k) {
      problem.initial_controls(k, 0) = uniform(random);
    }
    const OcpResult result = SolveOcp(problem, options);
    SCOPED_TRACE("seed " + std::to_string(seed));
    ExpectWaveRiderOptimum(problem, result);
    EXPECT_LE(result.stats.iterations, kWaveRiderRandomStartIterations);
  }
}

// A primal-dual warm start from a solution is (nearly) converged already.
TEST(Ocp, WarmStartFromASolutionConvergesAtOnce) {
  const OcpProblem problem = MakeOcpProblem("turbo_car");
  OcpOptions options = MakeOcpOptions("turbo_car");
  options.verify = false;
  const OcpResult first = SolveOcp(problem, options);
  ASSERT_EQ(first.status, OcpStatus::kSolved) << first.message;
  options.warm_start = first.decision;
  options.warm_start_multipliers = first.multipliers;
  const OcpResult again = SolveOcp(problem, options);
  ASSERT_EQ(again.status, OcpStatus::kSolved) << again.message;
  // A converged point needs at most a couple of iterations for IPOPT's barrier to settle.
  constexpr int kWarmIterations = 3;
  EXPECT_LE(again.stats.iterations, kWarmIterations);
  EXPECT_NEAR(again.objective, first.objective, 1e-9);
}

// The doorway's initial guess pushes the slider through the doorway; the discretization is
// converged on it (FESD with 3 and 10 elements per interval agree), so the plan is a property
// of the dynamics, not of the discretization (docs/ocp.md, "Doorway").
TEST(Ocp, DoorwayPlanPushesTheSliderThrough) {
  const OcpProblem problem = MakeOcpProblem("doorway");
  Vector coarse, fine;
  for (int elements : {3, 10}) {
    OcpOptions options;  // FESD shooting's forward simulation of the plan
    options.finite_elements = elements;
    ShootingNlp nlp(problem, options);
    OcpResult described;
    nlp.Describe(nlp.InitialGuess(), &described);
    (elements == 3 ? coarse : fine) = described.final_state;
  }
  EXPECT_GT(coarse[1], 1.0) << "slider height at T";
  // Measured 1.6e-5: the coarse discretization's error on this trajectory.
  constexpr double kDiscretizationAgreement = 1e-4;
  EXPECT_LE((coarse - fine).lpNorm<Eigen::Infinity>(), kDiscretizationAgreement);
}

// Central differences with step kStep (relative to 1 + |z_i|): truncation O(kStep^2) and
// Newton noise O(1e-14 / kStep) both far below the acceptance tolerance.
constexpr double kStep = 1e-6;
// Agreement of the exact derivatives with central differences, relative to the size of the
// derivative column (issue 10: relative 1e-6).
constexpr double kGradientTolerance = 1e-6;

// One-sided differences with a smaller step (truncation O(step), Newton noise O(1e-14/step)).
constexpr double kOneSidedStep = 1e-8;
constexpr double kOneSidedTolerance = 1e-5;

struct Differences {
  double central_objective, forward_objective, backward_objective;
  Vector central_constraints, forward_constraints, backward_constraints;
};

Differences DifferencesAlong(ShootingNlp* nlp, const Vector& z, Eigen::Index i) {
  auto evaluate = [&](double offset, double* f, Vector* g) {
    Vector shifted = z;
    shifted[i] += offset;
    std::string message;
    EXPECT_TRUE(nlp->Evaluate(shifted, f, g, nullptr, nullptr, &message)) << message;
  };
  Differences d;
  double f0 = 0.0, f_plus = 0.0, f_minus = 0.0;
  Vector g0, g_plus, g_minus;
  const double step = kStep * (1.0 + std::abs(z[i]));
  evaluate(step, &f_plus, &g_plus);
  evaluate(-step, &f_minus, &g_minus);
  d.central_objective = (f_plus - f_minus) / (2.0 * step);
  d.central_constraints = (g_plus - g_minus) / (2.0 * step);
  const double small = kOneSidedStep * (1.0 + std::abs(z[i]));
  evaluate(0.0, &f0, &g0);
  evaluate(small, &f_plus, &g_plus);
  evaluate(-small, &f_minus, &g_minus);
  d.forward_objective = (f_plus - f0) / small;
  d.forward_constraints = (g_plus - g0) / small;
  d.backward_objective = (f0 - f_minus) / small;
  d.backward_constraints = (g0 - g_minus) / small;
  return d;
}

struct DerivativeCase {
  std::string problem;
  OcpTranscription transcription;
  // Random controls are drawn from this part of their bounds (fractions of [lower, upper]):
  // the turbo car must accelerate to v = 15 for its relay to switch.
  double control_from = 0.0, control_to = 1.0;
  // A smoothed homotopy level (time-stepping with a b = mu^2): a smooth map, so central
  // differences must match everywhere (no kinks, no switches required).
  double smoothing = 0.0;
};

// A random point with the problem's controls in their bounds; node states from a forward
// simulation with them (continuity holds: a feasible point of the dynamics).
Vector RandomPoint(OcpProblem problem, const OcpOptions& options, const DerivativeCase& param,
                   std::mt19937* random) {
  problem.initial_controls.resize(problem.intervals,
                                  static_cast<Eigen::Index>(problem.controls.size()));
  for (Eigen::Index k = 0; k < problem.initial_controls.rows(); ++k) {
    for (Eigen::Index j = 0; j < problem.initial_controls.cols(); ++j) {
      const InputSpec& input =
          problem.scene
              .inputs[static_cast<std::size_t>(problem.controls[static_cast<std::size_t>(j)])];
      const double width = input.upper - input.lower;
      std::uniform_real_distribution<double> uniform(input.lower + param.control_from * width,
                                                     input.lower + param.control_to * width);
      problem.initial_controls(k, j) = uniform(*random);
    }
  }
  if (problem.speed.enabled) {
    std::uniform_real_distribution<double> uniform(1.0, 3.0);
    problem.speed.initial_guess = uniform(*random);
  }
  // The only free initial state is Stewart-Anitescu's x0: negative values put its switch
  // (at -x0/3 in [1/6, 1]) inside the first two of the four intervals.
  for (OcpProblem::FreeInitialState& free : problem.free_initial_states) {
    std::uniform_real_distribution<double> uniform(std::max(free.lower, -3.0),
                                                   std::min(free.upper, -0.5));
    problem.scene.initial_state[free.state] = uniform(*random);
  }
  ShootingNlp nlp(problem, options);
  return nlp.InitialGuess();
}

class OcpDerivatives : public ::testing::TestWithParam<DerivativeCase> {};

TEST_P(OcpDerivatives, ExactFirstDerivativesMatchCentralDifferences) {
  const DerivativeCase& param = GetParam();
  OcpProblem problem = MakeOcpProblem(param.problem);
  problem.intervals = 4;
  problem.initial_controls.resize(0, 0);
  OcpOptions options;
  options.transcription = param.transcription;
  const bool smoothed = param.smoothing > 0.0;
  if (smoothed) options.homotopy = {{param.smoothing, 0.0, {}}};
  std::mt19937 random(20261121);
  int points_with_interior_switches = 0;
  int kinks = 0;
  for (int trial = 0; trial < 3; ++trial) {
    const Vector z = RandomPoint(problem, options, param, &random);
    ShootingNlp nlp(problem, options);
    if (smoothed) nlp.SetLevel(options.homotopy.front());
    double objective = 0.0;
    Vector constraints, gradient, values;
    std::string message;
    ASSERT_TRUE(nlp.Evaluate(z, &objective, &constraints, &gradient, &values, &message)) << message;
    const Matrix jacobian = Matrix(nlp.JacobianMatrix(values));
    // Switches strictly inside the control intervals (where the sensitivities must carry
    // the switch-time derivatives), away from the grid points by more than the FD step.
    OcpResult described;
    nlp.Describe(z, &described);
    bool interior = false;
    for (const Event& event : described.events) {
      double distance = 1e300;
      for (double t : described.grid) distance = std::min(distance, std::abs(event.t - t));
      if (distance > 1e-3) interior = true;
    }
    if (!interior && !smoothed) continue;
    ++points_with_interior_switches;
    for (Eigen::Index i = 0; i < z.size(); ++i) {
      const Differences d = DifferencesAlong(&nlp, z, i);
      const double scale =
          std::max({1.0, std::abs(gradient[i]), jacobian.col(i).lpNorm<Eigen::Infinity>()});
      const double central_error =
          std::max(std::abs(d.central_objective - gradient[i]),
                   (d.central_constraints - jacobian.col(i)).lpNorm<Eigen::Infinity>());
      if (central_error <= kGradientTolerance * scale) continue;
      // A multiple-shooting node state on the active boundary of a moving set is a kink of
      // the NLP (outward perturbations start infeasible and are projected; docs/ocp.md): there
      // the exact derivative must be one of the one-sided derivatives.
      const double forward_error =
          std::max(std::abs(d.forward_objective - gradient[i]),
                   (d.forward_constraints - jacobian.col(i)).lpNorm<Eigen::Infinity>());
      const double backward_error =
          std::max(std::abs(d.backward_objective - gradient[i]),
                   (d.backward_constraints - jacobian.col(i)).lpNorm<Eigen::Infinity>());
      const double one_sided = std::min(forward_error, backward_error);
      EXPECT_LE(one_sided, kOneSidedTolerance * scale)
          << "variable " << i << " at trial " << trial << ": central difference error "
          << central_error << ", one-sided errors " << forward_error << ", " << backward_error
          << "\nexact      " << jacobian.col(i).transpose() << "\ncentral    "
          << d.central_constraints.transpose();
      if (param.transcription == OcpTranscription::kSingleShooting || smoothed) {
        ADD_FAILURE() << "single shooting and smoothed levels have no kinks: variable " << i;
      }
      ++kinks;
    }
  }
  // The test is about switches inside intervals: it must have seen some.
  EXPECT_GE(points_with_interior_switches, 1);
  std::printf("%d points with interior switches; %d node-state kinks\n",
              points_with_interior_switches, kinks);
}

INSTANTIATE_TEST_SUITE_P(
    Problems, OcpDerivatives,
    ::testing::Values(
        DerivativeCase{"stewart_anitescu", OcpTranscription::kMultipleShooting},
        DerivativeCase{"stewart_anitescu", OcpTranscription::kSingleShooting},
        DerivativeCase{"turbo_car", OcpTranscription::kMultipleShooting, 0.7, 1.0},
        DerivativeCase{"turbo_car", OcpTranscription::kSingleShooting, 0.7, 1.0},
        DerivativeCase{"wave_rider", OcpTranscription::kMultipleShooting},
        DerivativeCase{"wave_rider", OcpTranscription::kSingleShooting},
        DerivativeCase{"wave_rider", OcpTranscription::kMultipleShooting, 0.0, 1.0, 0.1},
        DerivativeCase{"stewart_anitescu", OcpTranscription::kMultipleShooting, 0.0, 1.0, 0.1}),
    [](const ::testing::TestParamInfo<DerivativeCase>& case_info) {
      return case_info.param.problem + "_" + ToString(case_info.param.transcription) +
             (case_info.param.smoothing > 0.0 ? "_smoothed" : "");
    });

// Multiple shooting's derivatives are blocks per interval: the Jacobian's and the block
// Hessian's structural nonzeros grow linearly in N (the dense Jacobian they replace had
// m x n = O(N^2) entries).
TEST(Ocp, SparseDerivativesGrowLinearlyInTheIntervals) {
  for (const char* name : {"wave_rider", "turbo_car", "doorway"}) {
    OcpOptions options = MakeOcpOptions(name);
    options.transcription = OcpTranscription::kMultipleShooting;  // the doorway's is collocation
    options.hessian = OcpHessian::kBlockBfgs;
    std::vector<double> jacobian, hessian;
    for (int n : {100, 200, 400}) {
      OcpProblem problem = MakeOcpProblem(name);
      problem.intervals = n;
      problem.initial_controls.resize(0, 0);
      const ShootingNlp nlp(problem, options);
      jacobian.push_back(static_cast<double>(nlp.JacobianStructure().size()));
      hessian.push_back(static_cast<double>(nlp.HessianStructure().size()));
    }
    // Exactly linear, a + b N: the increments from N = 100 to 200 and from 200 to 400 are in
    // the ratio of the increments of N.
    for (const auto* counts : {&jacobian, &hessian}) {
      const auto& c = *counts;
      EXPECT_DOUBLE_EQ(c[2] - c[1], 2.0 * (c[1] - c[0])) << name;
    }
  }
}

// The block quasi-Newton approximation is the Hessian of the Lagrangian's smooth pieces: after
// enough symmetric rank-one updates along random small steps around a point, it predicts the
// change of the Lagrangian gradient along a new step to second order. Exercises the block
// structure (which variables each interval's curvature couples), the exact Hessians of the
// terminal and path functions, and the multipliers' signs.
TEST(Ocp, BlockSr1HessianPredictsTheLagrangianGradient) {
  // Steps of 1e-4: the prediction error is the third-order remainder, O(|s|) relative to the
  // gradient change (measured 1e-5 to 1e-4); a wrong block or sign gives O(1).
  constexpr double kStepSize = 1e-4;
  constexpr double kPredictionTolerance = 1e-3;
  constexpr int kUpdates = 60;  // more than the largest block's dimension (8)
  for (const char* name : {"stewart_anitescu", "wave_rider", "turbo_car"}) {
    OcpProblem problem = MakeOcpProblem(name);
    problem.intervals = 3;
    problem.initial_controls.resize(0, 0);
    OcpOptions options;
    options.hessian = OcpHessian::kBlockSr1;
    options.lbfgs_memory = kUpdates;
    ShootingNlp nlp(problem, options);
    const Vector z = nlp.InitialGuess();
    std::mt19937 random(20261122);
    std::normal_distribution<double> normal(0.0, 1.0);
    Vector lambda(nlp.num_constraints());
    for (auto& value : lambda) value = normal(random);
    Vector gradient, jacobian, hessian;
    auto lagrangian_gradient = [&](const Vector& point) {
      double f = 0.0;
      Vector c;
      std::string message;
      EXPECT_TRUE(nlp.Evaluate(point, &f, &c, &gradient, &jacobian, &message)) << message;
      return Vector(gradient + nlp.JacobianMatrix(jacobian).transpose() * lambda);
    };
    auto random_step = [&] {
      Vector s(z.size());
      for (auto& value : s) value = kStepSize * normal(random);
      return s;
    };
    for (int i = 0; i < kUpdates; ++i) {
      const Vector point = z + random_step();
      lagrangian_gradient(point);
      ASSERT_TRUE(nlp.HessianApproximation(point, 1.0, lambda, gradient, jacobian, &hessian));
    }
    const Vector g0 = lagrangian_gradient(z);
    ASSERT_TRUE(nlp.HessianApproximation(z, 1.0, lambda, gradient, jacobian, &hessian));
    Matrix dense = Matrix::Zero(z.size(), z.size());
    const auto& structure = nlp.HessianStructure();
    for (std::size_t k = 0; k < structure.size(); ++k) {
      const auto [row, column] = structure[k];
      dense(row, column) = hessian[static_cast<Eigen::Index>(k)];
      dense(column, row) = hessian[static_cast<Eigen::Index>(k)];
    }
    for (int trial = 0; trial < 3; ++trial) {
      const Vector s = random_step();
      const Vector change = lagrangian_gradient(z + s) - g0;
      EXPECT_LE((dense * s - change).norm(), kPredictionTolerance * change.norm())
          << name << " trial " << trial;
    }
  }
}

TEST(Ocp, InvalidProblemsAndOptionsAreNamed) {
  OcpProblem problem = MakeOcpProblem("wave_rider");
  problem.controls = {7};
  EXPECT_THROW(
      {
        try {
          ValidateOcp(problem);
        } catch (const std::invalid_argument& error) {
          EXPECT_NE(std::string(error.what()).find("control"), std::string::npos) << error.what();
          throw;
        }
      },
      std::invalid_argument);
  OcpOptions options;
  options.stages = 0;
  EXPECT_THROW(options.Validate(), std::invalid_argument);
  options = {};
  options.tolerance = -1.0;
  EXPECT_THROW(options.Validate(), std::invalid_argument);
  problem = MakeOcpProblem("wave_rider");
  problem.intervals = 0;
  EXPECT_THROW(SolveOcp(problem), std::invalid_argument);
  EXPECT_THROW(MakeOcpProblem("no_such_problem"), std::invalid_argument);
  EXPECT_THROW(MakeOcpOptions("no_such_problem"), std::invalid_argument);
  auto expect_message = [](const OcpProblem& bad, const OcpOptions& bad_options,
                           const std::string& part) {
    try {
      ShootingNlp nlp(bad, bad_options);
      ADD_FAILURE() << "expected std::invalid_argument naming '" << part << "'";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(part), std::string::npos) << error.what();
    }
  };
  options = {};
  options.homotopy = {{0.0, 0.0, {}}};
  expect_message(MakeOcpProblem("wave_rider"), options, "neither smooths");
  options.homotopy = {{-1.0, 0.0, {}}};
  expect_message(MakeOcpProblem("wave_rider"), options, "must be >= 0");
  options.homotopy = {{0.1, 0.0, {}}};  // smoothing needs the time-stepping scheme
  expect_message(MakeOcpProblem("turbo_car"), options, "speed of time");
  options.homotopy = {{0.0, 0.0, {{"no_such_parameter", 1.0}}}};
  expect_message(MakeOcpProblem("doorway"), options, "no_such_parameter");
  options = {};
  options.level_tolerance = 0.0;
  EXPECT_THROW(options.Validate(), std::invalid_argument);
}

}  // namespace
}  // namespace moreau
