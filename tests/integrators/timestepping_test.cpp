#include "moreau/integrators/timestepping.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "../problems/reference_problems.hpp"
#include "moreau/core/convergence.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

using testing::ReferenceProblem;

// Error against the known answers: the final state and every switch time. Time-stepping
// knows a switch only to the resolution of its step (the event is reported at the end of
// the step in which a pair changed status), so the switch-time error is O(h) for every s.
// The state error at T is O(h) for Filippov crossings (F1, F2) and higher for some
// sweeping processes (S1: the boundary fixes the state; S3: the tangential velocity is
// continuous at contact, giving O(h^2) for s >= 2), which is why the times are included.
double KnownAnswerError(const ReferenceProblem& problem, const TimeSteppingResult& result) {
  double error = (result.final_state - problem.FinalState()).lpNorm<Eigen::Infinity>();
  for (double t_switch : problem.switch_times) {
    double closest = std::numeric_limits<double>::infinity();
    for (const Event& event : result.events)
      closest = std::min(closest, std::fabs(event.t - t_switch));
    error = std::max(error, closest);
  }
  return error;
}

struct OrderCase {
  ReferenceProblem problem;
  int stages;
  int first_steps_to_switch;  // m0: h = t_switch / (m0 2^k + 1/2), k = 0..4
  SwitchingForm form = SwitchingForm::kStewart;
};
void PrintTo(const OrderCase& c, std::ostream* out) {
  *out << c.problem.scene << " s = " << c.stages << " " << ToString(c.form);
}

class TimeSteppingOrderTest : public ::testing::TestWithParam<OrderCase> {};

// Acceptance: observed order between 0.8 and 1.3 on S1, S3, F1, F2 for s = 1, 2, 3. The step
// sizes put the first switch at the middle of a step on every grid (h = t_s / (m + 1/2)), so
// that the O(h) switch error is not masked by the switch's varying position in its step.
TEST_P(TimeSteppingOrderTest, FirstOrderAcrossSwitches) {
  const OrderCase& c = GetParam();
  const Scene scene = c.problem.Make();
  std::vector<double> steps, errors;
  std::string table;
  for (int k = 0; k < 5; ++k) {
    TimeSteppingOptions options;
    options.stages = c.stages;
    options.switching_form = c.form;
    options.step_size = c.problem.switch_times[0] / (c.first_steps_to_switch * (1 << k) + 0.5);
    const TimeSteppingResult result = SimulateTimeStepping(scene, options);
    ASSERT_EQ(result.status, TimeSteppingStatus::kSuccess) << result.message;
    steps.push_back(options.step_size);
    errors.push_back(KnownAnswerError(c.problem, result));
    table += "h = " + std::to_string(options.step_size) +
             " error = " + std::to_string(errors.back()) + "\n";
  }
  const OrderFit fit = FitOrder(steps, errors, 0.0);
  EXPECT_GE(fit.order, 0.8) << table;
  EXPECT_LE(fit.order, 1.3) << table;
  EXPECT_LT(errors.back(), errors.front()) << "no convergence\n" << table;
}

std::vector<OrderCase> OrderCases() {
  std::vector<OrderCase> cases;
  for (int s : {1, 2, 3}) {
    cases.push_back({testing::S1(), s, 20});
    cases.push_back({testing::S3(), s, 20});
    // Implicit Euler (s = 1) damps the 2pi rotation of F1: finer grids for the asymptotic range.
    cases.push_back({testing::F1(), s, s == 1 ? 300 : 20});
    cases.push_back({testing::F2a(), s, 20});
    cases.push_back({testing::F2b(), s, 20});
    cases.push_back({testing::F2c(), s, 20});
    cases.push_back({testing::F1(), s, s == 1 ? 300 : 20, SwitchingForm::kHeaviside});
    cases.push_back({testing::F2a(), s, 20, SwitchingForm::kHeaviside});
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(ReferenceProblems, TimeSteppingOrderTest,
                         ::testing::ValuesIn(OrderCases()), [](const auto& test_info) {
                           return test_info.param.problem.scene + "_s" +
                                  std::to_string(test_info.param.stages) + "_" +
                                  ToString(test_info.param.form);
                         });

struct SlidingCase {
  ReferenceProblem problem;
  int stages;
  SwitchingForm form;
};
void PrintTo(const SlidingCase& c, std::ostream* out) {
  *out << c.problem.scene << " s = " << c.stages << " " << ToString(c.form);
}

class TimeSteppingSlidingTest : public ::testing::TestWithParam<SlidingCase> {};

// Acceptance: on F2b and F3 the state stays on the switching surface x = 0 to 1e-10 once it
// reaches it, and the stage complementarity residual is at most 1e-10 at every step.
TEST_P(TimeSteppingSlidingTest, StaysOnTheSurfaceWithComplementarityCertificates) {
  constexpr double kOnSurface = 1e-10;
  constexpr double kComplementarity = 1e-10;
  const SlidingCase& c = GetParam();
  for (double h : {0.03, 0.0123}) {  // switch inside a step, at different positions
    TimeSteppingOptions options;
    options.stages = c.stages;
    options.step_size = h;
    options.switching_form = c.form;
    const TimeSteppingResult result = SimulateTimeStepping(c.problem.Make(), options);
    ASSERT_EQ(result.status, TimeSteppingStatus::kSuccess) << result.message;
    const Trajectory& trajectory = result.trajectory;
    std::size_t reached = trajectory.size();
    for (std::size_t k = 0; k < trajectory.size(); ++k) {
      if (std::fabs(trajectory.x[k][0]) <= kOnSurface) {
        reached = k;
        break;
      }
    }
    ASSERT_LT(reached, trajectory.size()) << "never reached the surface, h = " << h;
    // Complementarity holds at the stages only, so the end of the step containing the switch
    // need not lie exactly on the surface (s >= 2); the next step lands on it.
    EXPECT_LE(trajectory.t[reached], c.problem.switch_times[0] + 2 * h + 1e-12)
        << "reached the surface more than one step after the step containing the switch";
    for (std::size_t k = reached; k < trajectory.size(); ++k) {
      EXPECT_LE(std::fabs(trajectory.x[k][0]), kOnSurface)
          << "left the surface at t = " << trajectory.t[k];
    }
    ASSERT_EQ(result.step_complementarity_residual.size(),
              static_cast<std::size_t>(result.stats.num_steps));
    for (std::size_t k = 0; k < result.step_complementarity_residual.size(); ++k) {
      EXPECT_LE(result.step_complementarity_residual[k], kComplementarity) << "step " << k;
    }
  }
}

std::vector<SlidingCase> SlidingCases() {
  std::vector<SlidingCase> cases;
  for (int s : {1, 2, 3}) {
    for (SwitchingForm form : {SwitchingForm::kStewart, SwitchingForm::kHeaviside}) {
      cases.push_back({testing::F2b(), s, form});
      cases.push_back({testing::F3(), s, form});
    }
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(SlidingProblems, TimeSteppingSlidingTest,
                         ::testing::ValuesIn(SlidingCases()), [](const auto& test_info) {
                           return test_info.param.problem.scene + "_s" +
                                  std::to_string(test_info.param.stages) + "_" +
                                  ToString(test_info.param.form);
                         });

TEST(TimeSteppingTest, ReportsEventsAtStepResolution) {
  TimeSteppingOptions options;
  options.stages = 2;
  options.step_size = 0.0123;
  const TimeSteppingResult result = SimulateTimeStepping(testing::S3().Make(), options);
  ASSERT_EQ(result.status, TimeSteppingStatus::kSuccess) << result.message;
  ASSERT_EQ(result.events.size(), 2u);
  EXPECT_EQ(result.events[0].kind, EventKind::kEnter);
  EXPECT_EQ(result.events[0].what, "floor.c");
  EXPECT_EQ(result.events[1].kind, EventKind::kLeave);
  const std::vector<double>& exact = testing::S3().switch_times;
  for (int k = 0; k < 2; ++k) {
    EXPECT_GE(result.events[k].t, exact[k] - 1e-12);
    EXPECT_LE(result.events[k].t, exact[k] + 2 * options.step_size);
  }
  // The constraint holds at every recorded state (to the Newton tolerance).
  for (const Vector& x : result.trajectory.x) EXPECT_GE(x[1] + 1.0, -1e-12);
}

// Sensitivities of the discrete map (implicit function theorem per step) against central
// differences, on the wave-rider S4 (a moving set riding the state, inputs on two control
// segments) and F4 (a Filippov crossing at t = 1/3). Steps chosen so that no pair is degenerate at
// the perturbed points: the map is smooth there.
// Also with smoothed complementarity (a b = mu^2 at every stage, the OCP layer's homotopy
// levels): then the step map is smooth and its sensitivities are classical derivatives.
TEST(TimeSteppingTest, SensitivitiesMatchCentralDifferences) {
  constexpr double kStep = 1e-6;
  // Central differences: truncation O(kStep^2) and Newton noise O(1e-13 / kStep).
  constexpr double kTolerance = 1e-6;
  for (const double smoothing : {0.0, 0.1}) {
    for (const char* name : {"S4", "F4"}) {
      for (int stages : {1, 2, 3}) {
        Scene scene = MakeScene(name);
        if (std::string(name) == "S4") {
          scene.inputs[0].signal = PiecewiseConstantSignal{{2.5}, {0.7, -0.4}};
        }
        TimeSteppingOptions options;
        options.stages = stages;
        options.step_size = std::string(name) == "S4" ? 0.05 : 0.02;
        options.sensitivities = true;
        options.newton.smoothing = smoothing;
        const TimeSteppingResult result = SimulateTimeStepping(scene, options);
        ASSERT_EQ(result.status, TimeSteppingStatus::kSuccess) << result.message;
        // Both cross a switch: S4 is pushed by its boundary, F4 crosses x = 0 at t = 1/3.
        if (std::string(name) == "S4") {
          if (smoothing == 0.0) {
            ASSERT_FALSE(result.events.empty()) << "the test needs a contact";
          }
        } else {
          ASSERT_GT(result.final_state[0], 0.0) << "the test needs the crossing";
        }
        const Vector y0 = [&] {
          Vector y(result.final_lowered_state.size());
          y << scene.initial_state, scene.initial_time;
          return y;
        }();
        const Eigen::Index ny = y0.size();
        const Eigen::Index nu = scene.num_inputs();
        const Eigen::Index np = result.sensitivities.cols() - ny -
                                nu * static_cast<Eigen::Index>(result.segment_starts.size());
        for (Eigen::Index j = 0; j < result.sensitivities.cols(); ++j) {
          TimeSteppingOptions plus = options, minus = options;
          plus.sensitivities = minus.sensitivities = false;
          Scene scene_plus = scene, scene_minus = scene;
          if (j < ny) {
            plus.initial_state = y0;
            minus.initial_state = y0;
            plus.initial_state[j] += kStep;
            minus.initial_state[j] -= kStep;
          } else if (j < ny + np) {
            scene_plus.parameters[static_cast<std::size_t>(j - ny)].value += kStep;
            scene_minus.parameters[static_cast<std::size_t>(j - ny)].value -= kStep;
          } else {
            const Eigen::Index segment = (j - ny - np) / nu;
            const Eigen::Index input = (j - ny - np) % nu;
            scene_plus.inputs[static_cast<std::size_t>(input)]
                .signal.values[static_cast<std::size_t>(segment)] += kStep;
            scene_minus.inputs[static_cast<std::size_t>(input)]
                .signal.values[static_cast<std::size_t>(segment)] -= kStep;
          }
          const TimeSteppingResult rp = SimulateTimeStepping(scene_plus, plus);
          const TimeSteppingResult rm = SimulateTimeStepping(scene_minus, minus);
          const Vector fd = (rp.final_lowered_state - rm.final_lowered_state) / (2.0 * kStep);
          EXPECT_LE((fd - result.sensitivities.col(j)).lpNorm<Eigen::Infinity>(),
                    kTolerance * std::max(1.0, fd.lpNorm<Eigen::Infinity>()))
              << name << " s = " << stages << " smoothing " << smoothing << " column " << j
              << "\nexact " << result.sensitivities.col(j).transpose() << "\nfd    "
              << fd.transpose();
        }
      }
    }
  }
}

TEST(TimeSteppingTest, RefusesUnsupportedEffectsAndBadOptions) {
  Scene scene = testing::F1().Make();
  HysteresisRelay relay;
  relay.name = "thermostat";
  scene.effects.push_back(relay);
  try {
    SimulateTimeStepping(scene, {});
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("hysteresis relay 'thermostat'"), std::string::npos)
        << error.what();
  }
  TimeSteppingOptions options;
  options.step_size = 0.0;
  EXPECT_THROW(SimulateTimeStepping(testing::F1().Make(), options), std::invalid_argument);
}

// Directional and adjoint sensitivities of time-stepping equal the products with its full
// matrices (the same dense step transfers, chained in another order: round-off only).
TEST(TimeSteppingTest, DirectionalAndAdjointEqualFullProducts) {
  constexpr double kProductTolerance = 1e-10;
  for (const char* name : {"S3", "F1", "rectifier"}) {
    Scene scene = MakeScene(name);
    scene.final_time = std::min(scene.final_time, scene.initial_time + 2.0);
    TimeSteppingOptions options;
    options.step_size = 0.01;
    options.sensitivities = true;
    const TimeSteppingResult full_run = SimulateTimeStepping(scene, options);
    ASSERT_EQ(full_run.status, TimeSteppingStatus::kSuccess) << name << ": " << full_run.message;
    const int nx = scene.num_states();
    const Eigen::Index ny = full_run.sensitivities.rows();
    const Eigen::Index n_theta = full_run.sensitivities.cols() - ny;
    Matrix full(nx, nx + n_theta);  // columns x0, p, u per segment
    full << full_run.sensitivities.topLeftCorner(nx, nx),
        full_run.sensitivities.topRightCorner(nx, n_theta);
    options.sensitivity_directions = Matrix::Random(nx + n_theta, 3);
    options.adjoint_weights = Matrix::Random(nx, 2);
    const TimeSteppingResult result = SimulateTimeStepping(scene, options);
    ASSERT_EQ(result.status, TimeSteppingStatus::kSuccess) << result.message;
    const Matrix directional = full * options.sensitivity_directions;
    const Matrix adjoint = options.adjoint_weights.transpose() * full;
    EXPECT_LE((result.directional - directional).lpNorm<Eigen::Infinity>(),
              kProductTolerance * std::max(1.0, directional.lpNorm<Eigen::Infinity>()))
        << name;
    EXPECT_LE((result.adjoint - adjoint).lpNorm<Eigen::Infinity>(),
              kProductTolerance * std::max(1.0, adjoint.lpNorm<Eigen::Infinity>()))
        << name;
  }
}

// Sample times and kept sweeps: a sample time is a step end (a stop time), the sample state is
// the state of a run stopped there, and the directional and adjoint sensitivities at the
// samples equal the products with the full matrices of the runs stopped there; a kept sweep,
// Simulate()'s sweep and a sweep over transfers kept in the file equal the in-run adjoint.
TEST(TimeSteppingTest, SampleTimesAndKeptSweeps) {
  // The same dense transfers chained in another order: round-off only.
  constexpr double kProductTolerance = 1e-10;
  for (const char* name : {"S3", "F1", "rectifier"}) {
    Scene scene = MakeScene(name);
    scene.final_time = std::min(scene.final_time, scene.initial_time + 2.0);
    const double span = scene.final_time - scene.initial_time;
    // The second sample time is not on the grid of h: it becomes a step end.
    const std::vector<double> samples = {scene.initial_time + 0.3 * span,
                                         scene.initial_time + 0.6173 * span};
    TimeSteppingOptions options;
    options.step_size = span / 40.0;
    options.stop_times = samples;  // the grid of the sampled run
    options.sensitivities = true;
    // The full matrices at T and at each sample time (runs stopped there).
    const TimeSteppingResult full_run = SimulateTimeStepping(scene, options);
    ASSERT_EQ(full_run.status, TimeSteppingStatus::kSuccess) << name << ": " << full_run.message;
    const int nx = scene.num_states();
    const Eigen::Index ny = full_run.sensitivities.rows();
    const Eigen::Index n_theta = full_run.sensitivities.cols() - ny;
    const auto scene_columns = [&](const Matrix& lowered) {
      Matrix full = Matrix::Zero(nx, nx + n_theta);  // x0, p, u per segment (later ones zero)
      full.leftCols(nx) = lowered.topLeftCorner(nx, nx);
      full.middleCols(nx, lowered.cols() - ny) = lowered.topRightCorner(nx, lowered.cols() - ny);
      return full;
    };
    std::vector<Matrix> at_sample;
    std::vector<Vector> sample_state;
    for (double t : samples) {
      Scene stopped = scene;
      stopped.final_time = t;
      const TimeSteppingResult part = SimulateTimeStepping(stopped, options);
      ASSERT_EQ(part.status, TimeSteppingStatus::kSuccess) << name << ": " << part.message;
      at_sample.push_back(scene_columns(part.sensitivities));
      sample_state.push_back(part.final_lowered_state);
    }
    TimeSteppingOptions sampled;
    sampled.step_size = options.step_size;
    sampled.sample_times = samples;
    sampled.sensitivity_directions = Matrix::Random(nx + n_theta, 3);
    sampled.adjoint_weights = Matrix::Random(nx, 2);
    sampled.adjoint_sample_weights = Matrix::Random(nx, 2 * 2);
    sampled.keep_adjoint = true;
    const TimeSteppingResult result = SimulateTimeStepping(scene, sampled);
    ASSERT_EQ(result.status, TimeSteppingStatus::kSuccess) << name << ": " << result.message;
    // The same steps as the runs with these stop times: the same values to the bit.
    EXPECT_EQ(result.final_lowered_state, full_run.final_lowered_state) << name;
    ASSERT_EQ(result.sample_states.size(), 2u);
    ASSERT_EQ(result.sample_directional.size(), 2u);
    Matrix adjoint = sampled.adjoint_weights.transpose() * scene_columns(full_run.sensitivities);
    for (std::size_t j = 0; j < samples.size(); ++j) {
      EXPECT_EQ(result.sample_states[j], sample_state[j]) << name << " sample " << j;
      const Matrix directional = at_sample[j] * sampled.sensitivity_directions;
      EXPECT_LE((result.sample_directional[j] - directional).lpNorm<Eigen::Infinity>(),
                kProductTolerance * std::max(1.0, directional.lpNorm<Eigen::Infinity>()))
          << name << " sample " << j;
      adjoint += sampled.adjoint_sample_weights.middleCols(2 * static_cast<Eigen::Index>(j), 2)
                     .transpose() *
                 at_sample[j];
    }
    EXPECT_LE((result.adjoint - adjoint).lpNorm<Eigen::Infinity>(),
              kProductTolerance * std::max(1.0, adjoint.lpNorm<Eigen::Infinity>()))
        << name;
    // The kept sweep is the in-run sweep: the same operations, the same bits.
    ASSERT_TRUE(result.adjoint_sweep != nullptr);
    EXPECT_EQ(
        result.adjoint_sweep->Sweep(sampled.adjoint_weights, sampled.adjoint_sample_weights).theta,
        result.adjoint)
        << name;
    EXPECT_GT(result.stats.adjoint_memory_bytes, 0.0);
    EXPECT_EQ(result.stats.adjoint_file_bytes, 0.0);
    // Transfers beyond a bound of 2 kB are written to the file and read back unchanged.
    TimeSteppingOptions bounded = sampled;
    bounded.adjoint_memory_limit_mb = 2.0 / 1024.0;
    const TimeSteppingResult spilled = SimulateTimeStepping(scene, bounded);
    ASSERT_EQ(spilled.status, TimeSteppingStatus::kSuccess) << name << ": " << spilled.message;
    EXPECT_GT(spilled.stats.adjoint_file_bytes, 0.0) << name;
    EXPECT_LE(spilled.stats.adjoint_memory_bytes, 2048.0) << name;
    EXPECT_EQ(spilled.adjoint, result.adjoint) << name;
    // Simulate(): options by name, the sample states and the kept sweep.
    SimulationSettings settings;
    settings.integrator = "timestepping";
    settings.options["h"] = options.step_size;
    settings.options["sample_times"] = samples;
    settings.options["keep_adjoint"] = true;
    const SimulationResult simulated = Simulate(scene, settings);
    ASSERT_TRUE(simulated.success) << simulated.message;
    ASSERT_EQ(simulated.sample_states.size(), 2u);
    EXPECT_EQ(simulated.sample_states[1], sample_state[1].head(nx)) << name;
    ASSERT_TRUE(simulated.adjoint != nullptr);
    const AdjointGradient gradient =
        simulated.adjoint->Gradient(sampled.adjoint_weights, sampled.adjoint_sample_weights);
    ASSERT_TRUE(gradient.success) << gradient.message;
    EXPECT_LE((gradient.theta - adjoint).lpNorm<Eigen::Infinity>(),
              kProductTolerance * std::max(1.0, adjoint.lpNorm<Eigen::Infinity>()))
        << name;
  }
}

// Bad sample times and adjoint weights are refused before any work, naming the problem.
TEST(TimeSteppingTest, RefusesBadSampleTimesAndWeights) {
  const Scene scene = testing::F1().Make();  // n_x = 2, t in [0, pi/2]
  const auto refuses = [&](const TimeSteppingOptions& options, const std::string& expected) {
    try {
      SimulateTimeStepping(scene, options);
      ADD_FAILURE() << "expected std::invalid_argument mentioning '" << expected << "'";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(expected), std::string::npos) << error.what();
    }
  };
  TimeSteppingOptions options;
  options.step_size = 0.05;
  options.keep_adjoint = true;
  options.sample_times = {0.5, 0.4};
  refuses(options, "increasing");
  options.sample_times = {5.0};
  refuses(options, "outside (t0, tf]");
  options.sample_times = {0.0};
  refuses(options, "outside (t0, tf]");
  options.sample_times = {0.5};
  options.adjoint_sample_weights = Matrix::Ones(2, 3);  // q = 3 per sample, but no final weights
  options.adjoint_weights = Matrix::Ones(2, 2);         // q = 2
  refuses(options, "adjoint sample weights");
  options.adjoint_sample_weights = Matrix::Ones(5, 1);
  refuses(options, "adjoint sample weights");
  options.adjoint_sample_weights = Matrix();
  options.adjoint_memory_limit_mb = -1.0;
  refuses(options, "memory limit");
  TimeSteppingOptions untracked;
  untracked.sample_times = {0.5};
  refuses(untracked, "sample_times need sensitivities");
  TimeSteppingOptions unsampled;
  unsampled.adjoint_sample_weights = Matrix::Ones(2, 1);
  refuses(unsampled, "need sample_times");
}

}  // namespace
}  // namespace moreau
