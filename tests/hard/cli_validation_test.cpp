// Command-line input-validation matrix (issue 9): wrong values for every `moreau run` option
// (zero, negative, NaN, infinite, out of range, unknown), infeasible initial states and
// unknown names exit with code 2 and a message naming the problem.
#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "../tools/run_cli.hpp"

namespace {

using Outcome = moreau::testing::CliOutcome;
using moreau::testing::RunCli;

struct Case {
  const char* arguments;
  const char* fragment;
};

TEST(CliValidationMatrix, BadInputExitsWith2AndNamesTheProblem) {
  const Case cases[] = {
      // unknown names
      {"run hard_grazing --nope 1", "--nope"},
      {"run ''", "unknown scene ''"},
      {"run hard_grazing --integrator alpha2", "unknown integrator 'alpha2'"},
      {"run hard_zeno --switching nope",
       "bad value 'nope' for option 'switching': expected one of stewart, heaviside"},
      {"run hard_grazing --set x0.x3=1", "has no value named 'x0.x3'"},
      // NaN / infinite values
      {"run hard_grazing --set omega=nan", "must be finite"},
      {"run hard_grazing --set x0.x1=inf", "must be finite"},
      {"run hard_grazing --tf nan", "must be finite"},
      {"run hard_grazing --set floor=1e400", "bad value '1e400' for --set floor"},
      {"run hard_grazing --h nan --integrator fesd", "step size"},
      {"run hard_grazing --h inf --integrator timestepping", "step size"},
      // zero / negative step sizes and horizons
      {"run hard_grazing --h 0 --integrator fesd", "step size"},
      {"run hard_grazing --h -0.1 --integrator timestepping", "step size h must be positive"},
      {"run hard_grazing --tf 0", "horizon must be positive"},
      {"run hard_grazing --tf -5", "horizon must be positive"},
      {"run hard_grazing --integrator timestepping --tf 1e12 --h 1e-3", "fixed steps"},
      // out-of-range options
      {"run hard_grazing --integrator fesd --stages 8", "stages must be in [1, 7]"},
      {"run hard_grazing --integrator fesd --fe 0", "finite elements per step must be >= 1"},
      {"run hard_grazing --integrator ida --rtol -1", "relative tolerance must be positive"},
      {"run hard_grazing --integrator ida --atol nan", "absolute tolerance"},
      {"run hard_index3 --rho 1.5", "rho must be in [0, 1)"},
      {"run hard_index3 --rank-tol 2", "rank_tolerance must be in (0, 1)"},
      {"run hard_index3 --max-retries -1", "max_retries (MAXTRY) must be >= 0"},
      {"run hard_index3 --errtol 0", "error_tolerance (ERRTOL) must be positive"},
      // options that do not apply, effects an integrator cannot handle
      {"run hard_grazing --integrator ida --fe 2",
       "option 'fe' does not apply to integrator 'ida'"},
      {"run hard_zeno --integrator radau", "does not support the switching surfaces 'twisting'"},
      {"run hard_index3 --integrator fesd", "path constraints 'floor'"},
      // infeasible initial states (x0 outside C(t0)); FESD's handling is being changed on
      // main (projection onto C(t0)), so the integrators that refuse are named explicitly.
      {"run hard_simultaneous --integrator timestepping --set x0.x2=-0.5",
       "infeasible initial state: constraint 'c2' of moving set 'walls'"},
      {"run hard_simultaneous --integrator ida --set x0.x1=-1e-3",
       "infeasible initial state: constraint 'c1' of moving set 'walls'"},
      {"run hard_index3 --set x0.x1=-0.5", "floor"},
  };
  for (const Case& c : cases) {
    const Outcome outcome = RunCli(std::string(c.arguments) + " --quiet --no-plot --out " +
                                   std::string(::testing::TempDir()) + "moreau_cli_validation");
    EXPECT_EQ(outcome.exit_code, 2) << c.arguments << "\n" << outcome.output;
    EXPECT_NE(outcome.output.find(c.fragment), std::string::npos)
        << c.arguments << "\nexpected '" << c.fragment << "' in:\n"
        << outcome.output;
  }
}

// A numerical failure is exit code 1 with the status, time and reason, not a crash (fixed
// steps of 0.1 over switches every 1e-3; with no step given the run succeeds).
TEST(CliValidationMatrix, NumericalFailureIsAStatus) {
  const Outcome outcome =
      RunCli("run hard_fast_switching --integrator fesd --h 0.1 --quiet --no-plot --out " +
             std::string(::testing::TempDir()) + "moreau_cli_validation");
  EXPECT_EQ(outcome.exit_code, 1) << outcome.output;
  // The time (t = 0 or the first switch 0.001, see HardFastSwitching) and the reason.
  EXPECT_NE(outcome.output.find("event_location_failure at t = 0"), std::string::npos)
      << outcome.output;
  EXPECT_NE(outcome.output.find("no group of equal elements"), std::string::npos) << outcome.output;
}

}  // namespace
