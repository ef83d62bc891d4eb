// Runs the `moreau` executable and checks exit codes, messages and output files.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "run_cli.hpp"

namespace {

using Outcome = moreau::testing::CliOutcome;
using moreau::testing::RunCli;

void ExpectUsageError(const std::string& arguments, const std::string& fragment) {
  const Outcome outcome = RunCli(arguments);
  EXPECT_EQ(outcome.exit_code, 2) << arguments << "\n" << outcome.output;
  EXPECT_NE(outcome.output.find(fragment), std::string::npos)
      << arguments << "\nexpected '" << fragment << "' in:\n"
      << outcome.output;
}

TEST(CliTest, BadInputGivesClearErrorsAndExitCode2) {
  ExpectUsageError("run nope", "unknown scene 'nope'; available scenes:");
  ExpectUsageError("run hopf --bogus", "--bogus");
  ExpectUsageError("run hopf --set omega=abc", "bad value 'abc' for --set omega");
  ExpectUsageError("run hopf --set nope=1", "has no value named 'nope'");
  ExpectUsageError("run hopf --set omega", "expected name=value");
  ExpectUsageError("run hopf --tf -1", "horizon must be positive");
  ExpectUsageError("run hopf --set x0.x=nan", "must be finite");
  ExpectUsageError("run hopf --integrator nope", "unknown integrator 'nope'");
  ExpectUsageError("run hopf --integrator radau --h 0.01 --h-max 0.1",
                   "'h_max' applies to error-controlled steps only");
  ExpectUsageError("run S3 --integrator radau", "does not support the moving set 'floor'");
  ExpectUsageError("run hopf --h 0", "step size h must be positive");
  ExpectUsageError("run hopf --stages 0", "stages must be in [1, 7]");
  ExpectUsageError(
      "run hopf --linear-solver qr",
      "bad value 'qr' for option 'linear_solver': expected one of auto, dense, sparse");
  ExpectUsageError("show nope", "unknown scene 'nope'");
}

TEST(CliTest, RunWritesTrajectorySummaryAndPlot) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_run";
  std::filesystem::remove_all(directory);
  const Outcome outcome =
      RunCli("run hopf --stages 2 --h 0.01 --set mu=2 --out " + directory.string());
  ASSERT_EQ(outcome.exit_code, 0) << outcome.output;
  EXPECT_NE(outcome.output.find("status      success"), std::string::npos) << outcome.output;
  // The summary names the options that differ from the defaults, not all of them (those are in
  // summary.json): stages = 2 is not radau's default, the linear solver is.
  EXPECT_NE(outcome.output.find("integrator  radau (stages = 2"), std::string::npos)
      << outcome.output;
  EXPECT_NE(outcome.output.find("other options at their defaults)"), std::string::npos)
      << outcome.output;
  EXPECT_EQ(outcome.output.find("linear_solver"), std::string::npos) << outcome.output;
  std::ifstream csv(directory / "trajectory.csv");
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header, "t,x,y,h");
  std::ifstream json_file(directory / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(json_file);
  for (const char* key :
       {"scene", "integrator", "options", "status", "t_final", "x_final", "events", "stats"}) {
    EXPECT_TRUE(summary.contains(key)) << key;
  }
  EXPECT_EQ(summary["scene"], "hopf");
  EXPECT_EQ(summary["status"], "success");
  EXPECT_DOUBLE_EQ(summary["t_final"].get<double>(), 2.0);
  EXPECT_TRUE(summary["x_final"].contains("x"));
  EXPECT_EQ(summary["stats"]["num_steps"], 200);
  EXPECT_TRUE(std::filesystem::exists(directory / "trajectory.png"));
  EXPECT_TRUE(summary["options"].contains("linear_solver"));  // every option is in the file
}

// --quiet prints nothing but errors; the files are written all the same.
TEST(CliTest, QuietRunsPrintOnlyErrors) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_quiet";
  std::filesystem::remove_all(directory);
  const Outcome quiet = RunCli("run hopf --quiet --no-plot --out " + directory.string());
  EXPECT_EQ(quiet.exit_code, 0) << quiet.output;
  EXPECT_EQ(quiet.output, "");
  EXPECT_TRUE(std::filesystem::exists(directory / "summary.json"));
  const Outcome plain = RunCli("run hopf --no-plot --out " + directory.string());
  EXPECT_NE(plain.output.find("integrator  radau (all options at their defaults)"),
            std::string::npos)
      << plain.output;
  const Outcome sweep = RunCli("sweep hopf --grid mu=1:2:2 --quiet --no-plot --out " +
                               (directory / "sweep").string());
  EXPECT_EQ(sweep.exit_code, 0) << sweep.output;
  EXPECT_EQ(sweep.output, "");
  EXPECT_TRUE(std::filesystem::exists(directory / "sweep" / "sweep.csv"));
}

// `moreau check` names the parts of the lowered system a scene has, and only those.
TEST(CliTest, CheckNamesOnlyTheLoweredPartsThatExist) {
  const Outcome smooth = RunCli("check hopf");
  EXPECT_EQ(smooth.exit_code, 0) << smooth.output;
  EXPECT_NE(smooth.output.find("lowered     3 states y (2 x, clock), no algebraic unknowns"),
            std::string::npos)
      << smooth.output;
  EXPECT_NE(smooth.output.find("no effects"), std::string::npos) << smooth.output;
  for (const char* absent : {"relay", "complementarity", "equations G", " 0 "}) {
    EXPECT_EQ(smooth.output.find(absent), std::string::npos) << absent << "\n" << smooth.output;
  }
  const Outcome relay = RunCli("check H1");
  EXPECT_EQ(relay.exit_code, 0) << relay.output;
  EXPECT_NE(relay.output.find("(1 x, 1 relay memory, clock)"), std::string::npos) << relay.output;
}

// Acceptance (issue 3): the scenes S1, S3, F1, F2 and F3 run from `moreau run`.
TEST(CliTest, NonsmoothScenesRunWithTimeStepping) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_nonsmooth";
  for (const char* scene : {"S1", "S3", "F1", "F2a", "F2b", "F2c", "F2d", "F3"}) {
    std::filesystem::remove_all(directory);
    const Outcome outcome = RunCli(std::string("run ") + scene +
                                   " --integrator timestepping --stages 2 --h 0.01 --quiet "
                                   "--no-plot --out " +
                                   directory.string());
    EXPECT_EQ(outcome.exit_code, 0) << scene << "\n" << outcome.output;
    std::ifstream json_file(directory / "summary.json");
    const nlohmann::json summary = nlohmann::json::parse(json_file);
    EXPECT_EQ(summary["status"], "success") << scene;
    // F2d starts on a repulsive surface and may stay on it; every other scene switches.
    if (std::string(scene) != "F2d") {
      EXPECT_FALSE(summary["events"].empty()) << scene;
    }
    std::ifstream csv(directory / "trajectory.csv");
    std::string header;
    std::getline(csv, header);
    EXPECT_NE(header.find(",h"), std::string::npos) << header;  // multipliers and h follow
  }
}

// Acceptance (issue 4): S1 to S4 and F1 to F4 run with FESD from the command line, writing the
// element table (lengths and certificates) and the stage trajectory.
TEST(CliTest, ReferenceScenesRunWithFesd) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_fesd";
  for (const char* scene : {"S1", "S2", "S3", "S4", "F1", "F2a", "F2b", "F2c", "F2d", "F3", "F4"}) {
    std::filesystem::remove_all(directory);
    const Outcome outcome = RunCli(std::string("run ") + scene +
                                   " --integrator fesd --stages 3 --h 0.1 --fe 2 --quiet "
                                   "--no-plot --out " +
                                   directory.string());
    EXPECT_EQ(outcome.exit_code, 0) << scene << "\n" << outcome.output;
    std::ifstream json_file(directory / "summary.json");
    const nlohmann::json summary = nlohmann::json::parse(json_file);
    EXPECT_EQ(summary["status"], "success") << scene;
    EXPECT_FALSE(summary["events"].empty()) << scene;  // F2d: the ambiguous start
    EXPECT_LE(summary["stats"]["max_cross_complementarity"].get<double>(), 1e-10) << scene;
    std::ifstream elements(directory / "elements.csv");
    std::string header;
    std::getline(elements, header);
    EXPECT_EQ(header,
              "t_start,physical_start,length,frozen,ends_at_switch,newton_iterations,"
              "newton_residual,complementarity,cross_complementarity");
    EXPECT_TRUE(std::filesystem::exists(directory / "stages.csv")) << scene;
    EXPECT_FALSE(std::filesystem::exists(directory / "relays.csv")) << scene;
  }
}

// --rtol/--atol with --integrator fesd switch adaptive steps on (issue 16); --output-dt gives
// the trajectory at those times; the accepted steps are in summary.json.
TEST(CliTest, FesdRtolSwitchesAdaptiveStepsOn) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_fesd_adaptive";
  std::filesystem::remove_all(directory);
  const Outcome outcome = RunCli(
      "run F1 --integrator fesd --rtol 1e-8 --atol 1e-10 --output-dt 0.25 --quiet --no-plot "
      "--out " +
      directory.string());
  EXPECT_EQ(outcome.exit_code, 0) << outcome.output;
  std::ifstream json_file(directory / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(json_file);
  EXPECT_EQ(summary["status"], "success");
  EXPECT_EQ(summary["options"]["adaptive"], true);
  EXPECT_EQ(summary["options"]["rtol"], 1e-8);
  EXPECT_EQ(summary["options"]["h"], 0.0);  // automatic first step
  EXPECT_FALSE(summary["step_sequence"].empty());
  EXPECT_EQ(summary["stats"]["num_steps"].get<long>(),
            static_cast<long>(summary["step_sequence"].size()));
  // t0, 0.25, ..., 1.5, and the final time pi/2.
  std::ifstream trajectory(directory / "trajectory.csv");
  std::string line;
  std::getline(trajectory, line);
  std::vector<double> times;
  while (std::getline(trajectory, line)) times.push_back(std::stod(line.substr(0, line.find(','))));
  ASSERT_EQ(times.size(), 8u) << outcome.output;
  for (int k = 0; k < 7; ++k) EXPECT_DOUBLE_EQ(times[static_cast<std::size_t>(k)], 0.25 * k);
  ExpectUsageError("run F1 --integrator fesd --h 0.1 --h-min 1e-6",
                   "'h_min' applies to error-controlled steps only");
  ExpectUsageError("run F1 --integrator fesd --rtol 1e-8 --output-times 0.5,9",
                   "output time 9 is outside [t0, tf]");
}

TEST(CliTest, IdaRunsWithTolerances) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_ida";
  for (const char* scene : {"S3", "F1", "H1"}) {
    std::filesystem::remove_all(directory);
    const Outcome outcome = RunCli(std::string("run ") + scene +
                                   " --integrator ida --rtol 1e-10 --atol 1e-12 --quiet "
                                   "--no-plot --out " +
                                   directory.string());
    EXPECT_EQ(outcome.exit_code, 0) << scene << "\n" << outcome.output;
    std::ifstream json_file(directory / "summary.json");
    const nlohmann::json summary = nlohmann::json::parse(json_file);
    EXPECT_EQ(summary["status"], "success") << scene;
    EXPECT_EQ(summary["options"]["rtol"], 1e-10) << scene;
    EXPECT_FALSE(summary["events"].empty()) << scene;
  }
  ExpectUsageError("run S3 --integrator ida --stages 3",
                   "option 'stages' does not apply to integrator 'ida'");
  ExpectUsageError("run S3 --integrator ida --rtol 0", "relative tolerance must be positive");
}

TEST(CliTest, HysteresisScenesReportPhysicalTimeAndRelaySignals) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_hysteresis";
  for (const char* scene : {"H1", "H2", "H3"}) {
    std::filesystem::remove_all(directory);
    const Outcome outcome =
        RunCli(std::string("run ") + scene + " --no-plot --out " + directory.string());
    EXPECT_EQ(outcome.exit_code, 0) << scene << "\n" << outcome.output;
    EXPECT_NE(outcome.output.find("integrator  fesd"), std::string::npos) << outcome.output;
    EXPECT_NE(outcome.output.find("relay_switch"), std::string::npos) << outcome.output;
    std::ifstream json_file(directory / "summary.json");
    const nlohmann::json summary = nlohmann::json::parse(json_file);
    EXPECT_EQ(summary["status"], "success") << scene;
    ASSERT_FALSE(summary["relays"].empty()) << scene;
    EXPECT_FALSE(summary["relays"][0]["jumps"].empty()) << scene;
    // Physical time: strictly increasing, ending at the horizon.
    std::ifstream csv(directory / "trajectory.csv");
    std::string line;
    std::getline(csv, line);
    double previous = -1.0, t = 0.0;
    while (std::getline(csv, line)) {
      t = std::stod(line.substr(0, line.find(',')));
      EXPECT_GT(t, previous) << scene;
      previous = t;
    }
    EXPECT_DOUBLE_EQ(t, summary["t_final"].get<double>());
    EXPECT_TRUE(std::filesystem::exists(directory / "relays.csv")) << scene;
    EXPECT_TRUE(std::filesystem::exists(directory / "numerical.csv")) << scene;
  }
  std::filesystem::remove_all(directory);
  const Outcome numerical =
      RunCli("run H1 --numerical-time --quiet --no-plot --out " + directory.string());
  EXPECT_EQ(numerical.exit_code, 0) << numerical.output;
  std::ifstream csv(directory / "trajectory.csv");
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header.rfind("t,x,thermostat.w,clock,", 0), 0u) << header;
  ExpectUsageError("run S3 --numerical-time", "applies to scenes with hysteresis relays");
  ExpectUsageError("run H1 --integrator ida --numerical-time", "simulated by the fesd integrator");
  ExpectUsageError("run H1 --integrator timestepping", "hysteresis relay 'thermostat'");
}

// Acceptance (issue 6): D2 and D3 run with the alpha-method stepper from the command line (auto
// picks it for path constraints); the path constraints hold to TOL at every step and the
// per-step certificates are written to elements.csv.
TEST(CliTest, DaiScenesRunWithAlpha) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_alpha";
  constexpr double kTol = 1e-8;  // AlphaDaiOptions::constraint_tolerance (TOL)
  // The paper's fixed steps (h = 0.1); without h the steps are error-controlled (D3 then
  // succeeds, D2 ends with a status at its wave: docs/accuracy.md).
  for (const char* arguments :
       {"D2 --integrator alpha --h 0.1", "D3 --integrator alpha --rho 0.99 --h 0.1",
        "D2 --rho 0 --objective least-change --h 0.1"}) {
    std::filesystem::remove_all(directory);
    const Outcome outcome =
        RunCli(std::string("run ") + arguments + " --quiet --no-plot --out " + directory.string());
    EXPECT_EQ(outcome.exit_code, 0) << arguments << "\n" << outcome.output;
    std::ifstream json_file(directory / "summary.json");
    const nlohmann::json summary = nlohmann::json::parse(json_file);
    EXPECT_EQ(summary["integrator"], "alpha") << arguments;
    EXPECT_EQ(summary["status"], "success") << arguments;
    EXPECT_LE(summary["stats"]["max_constraint_violation"].get<double>(), kTol) << arguments;
    EXPECT_FALSE(summary["events"].empty()) << arguments << ": no constraint became active";
    std::ifstream elements(directory / "elements.csv");
    std::string header;
    std::getline(elements, header);
    EXPECT_EQ(header.rfind("t,h,h_rule,rho,tries,sqp_iterations,constraint_violation", 0), 0u)
        << header;
  }
  // A failure is a numerical status with time and reason (exit code 1), not a crash.
  const Outcome failed =
      RunCli("run D2 --rho 0.99 --h 0.1 --quiet --no-plot --out " + directory.string());
  EXPECT_EQ(failed.exit_code, 1) << failed.output;
  EXPECT_NE(failed.output.find("regularization_failed at t = "), std::string::npos)
      << failed.output;
  ExpectUsageError("run D2 --integrator alpha --stages 3",
                   "option 'stages' does not apply to integrator 'alpha'");
  ExpectUsageError("run S3 --integrator fesd --rho 0.5",
                   "option 'rho' does not apply to integrator 'fesd'");
  ExpectUsageError("run D2 --objective nope",
                   "bad value 'nope' for option 'objective': expected one of feasibility, "
                   "least-change, reference");
  ExpectUsageError("run D2 --rho 1", "rho must be in [0, 1)");
  ExpectUsageError("run S3 --integrator alpha", "does not support the moving set 'floor'");
}

TEST(CliTest, ListAndShowDescribeScenes) {
  const Outcome list = RunCli("list");
  EXPECT_EQ(list.exit_code, 0);
  EXPECT_NE(list.output.find("hopf"), std::string::npos);
  EXPECT_NE(list.output.find("radau"), std::string::npos);
  const Outcome show = RunCli("show hopf");
  EXPECT_EQ(show.exit_code, 0);
  EXPECT_NE(show.output.find("omega"), std::string::npos) << show.output;
  EXPECT_NE(show.output.find("x0 = 0.5"), std::string::npos) << show.output;
}

TEST(CliTest, OcpSolvesWritesItsFilesAndNamesBadInput) {
  ExpectUsageError("ocp nope", "unknown optimal control problem 'nope'; available:");
  ExpectUsageError("ocp wave_rider --N 0", "--N must be at least 1");
  ExpectUsageError("ocp wave_rider --stages 9", "stages must be in [1, ");
  ExpectUsageError("ocp wave_rider --tol -1", "tolerance must be positive");
  ExpectUsageError("ocp wave_rider --integrator rk4", "unknown OCP integrator 'rk4'");
  ExpectUsageError("ocp turbo_car --integrator timestepping", "does not support a free final time");
  ExpectUsageError("ocp doorway --homotopy 0.1",
                   "--homotopy: expected MU:EPS[:SIGMA][:NAME=VALUE...]");
  ExpectUsageError("ocp doorway --homotopy 0:0:radius", "--homotopy: expected MU:EPS");
  ExpectUsageError("ocp doorway --homotopy 0:0:1e-3:width=1", "homotopy parameter 'width'");
  ExpectUsageError("ocp doorway --homotopy 0:0.1", "needs a complementarity relaxation > 0");
  ExpectUsageError("ocp doorway --mesh-continuation 10,x", "--mesh-continuation: expected");
  ExpectUsageError("ocp doorway --refine-stages 3",
                   "collocation refinement stages must be 0 (no refinement) or in [stages + 1");
  ExpectUsageError("ocp doorway --stages 5",
                   "collocation refinement stages must be 0 (no refinement) or in [stages + 1");
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_ocp";
  std::filesystem::remove_all(directory);
  const Outcome outcome =
      RunCli("ocp stewart_anitescu --quiet --no-plot --out " + directory.string());
  ASSERT_EQ(outcome.exit_code, 0) << outcome.output;
  for (const char* file : {"trajectory.csv", "controls.csv", "iterations.csv", "summary.json"}) {
    EXPECT_TRUE(std::filesystem::exists(directory / file)) << file;
  }
  std::ifstream in(directory / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(in);
  EXPECT_EQ(summary["status"], "solved");
  // x0* = (9 - sqrt 417)/8 (docs/ocp.md), to the tolerance of the OCP tests.
  EXPECT_NEAR(summary["initial_state"]["x"].get<double>(), -1.4275722320827673, 1e-6);
  EXPECT_TRUE(summary["verification"]["done"].get<bool>());
  std::filesystem::remove_all(directory);
}

}  // namespace

namespace {

// Scene files wherever scene names go: run (with --set, exactly as on built-in scenes), show,
// check (lowered sizes, no simulation), sweep; bad files exit 2 with file:line:column.
TEST(CliTest, SceneFilesRunShowCheckAndSweep) {
  const std::string s3 = std::string(MOREAU_EXAMPLES_DIR) + "/scenes/S3.toml";
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / "moreau_cli_test_files";
  std::filesystem::remove_all(directory);
  const Outcome file = RunCli("run " + s3 + " --set floor=-0.5 --no-plot --quiet --out " +
                              (directory / "file").string());
  const Outcome builtin =
      RunCli("run S3 --set floor=-0.5 --no-plot --quiet --out " + (directory / "builtin").string());
  ASSERT_EQ(file.exit_code, 0) << file.output;
  ASSERT_EQ(builtin.exit_code, 0) << builtin.output;
  std::ifstream a(directory / "file" / "summary.json"), b(directory / "builtin" / "summary.json");
  const nlohmann::json sa = nlohmann::json::parse(a), sb = nlohmann::json::parse(b);
  EXPECT_EQ(sa["x_final"], sb["x_final"]);
  EXPECT_EQ(sa["events"], sb["events"]);

  const Outcome show = RunCli("show " + s3);
  EXPECT_EQ(show.exit_code, 0) << show.output;
  EXPECT_NE(show.output.find("moving set 'floor'"), std::string::npos) << show.output;

  const Outcome check = RunCli("check " + s3 + " --stages 2");
  EXPECT_EQ(check.exit_code, 0) << check.output;
  // S3: y = (x1, x2, clock), z = (lambda): s (n_y + n_z) = 2 * 4 unknowns per element.
  EXPECT_NE(check.output.find("3 states y (2 x, clock), 1 algebraic unknown z, 1 "
                              "complementarity pair\n"),
            std::string::npos)
      << check.output;
  EXPECT_NE(check.output.find("8 unknowns per element (s = 2"), std::string::npos) << check.output;

  const Outcome sweep = RunCli("sweep " + s3 + " --grid floor=-1:-0.5:3 --no-plot --out " +
                               (directory / "sweep").string());
  EXPECT_EQ(sweep.exit_code, 0) << sweep.output;
  EXPECT_NE(sweep.output.find("runs        3"), std::string::npos) << sweep.output;

  const std::filesystem::path bad = directory / "bad.toml";
  std::ofstream(bad) << "name = \"bad\"\nstates = [\"x\"]\nx0 = [1.0]\ntf = 1.0\n"
                        "dynamics = [\"-k*x\"]\n";
  ExpectUsageError("check " + bad.string(),
                   bad.string() + ":5:15 (dynamics[0]): unknown name 'k' in '-k*x'");
  ExpectUsageError("run " + bad.string(), "unknown name 'k'");
  ExpectUsageError("check nope.toml", "cannot read scene file 'nope.toml'");
}

}  // namespace
