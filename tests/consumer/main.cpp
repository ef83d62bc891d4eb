// Simulates the Hopf scene and solves the Stewart-Anitescu OCP with the installed library, and
// checks both known answers, and that the installed headers carry the expected version.
#include <cmath>
#include <cstdio>
#include <cstring>

#include "moreau/integrators/radau.hpp"
#include "moreau/ocp/catalog.hpp"
#include "moreau/scenes/catalog.hpp"
#include "moreau/version.hpp"

int main() {
  std::printf("consumer: moreau/version.hpp says %s\n", MOREAU_VERSION);
  if (std::strcmp(MOREAU_VERSION, MOREAU_EXPECTED_VERSION) != 0 ||
      std::strcmp(moreau::kVersion, MOREAU_VERSION) != 0) {
    std::printf("consumer: expected version %s\n", MOREAU_EXPECTED_VERSION);
    return 1;
  }
  const moreau::Scene scene = moreau::MakeScene("hopf");
  moreau::RadauOptions options;
  options.stages = 3;
  options.step_size = 0.01;
  const moreau::RadauResult result = moreau::SimulateRadau(scene, options);
  // r(2)^2 = 1 / (1 + 3 e^{-4}) at angle 4 pi (see the scene's description).
  const double expected_x = std::sqrt(1.0 / (1.0 + 3.0 * std::exp(-4.0)));
  const double error = std::fabs(result.final_state[0] - expected_x);
  std::printf("consumer: status %s, x(2) error %.3e\n", moreau::ToString(result.status).c_str(),
              error);
  // x0* = (9 - sqrt(417)) / 8 (docs/ocp.md).
  const moreau::OcpResult ocp = moreau::SolveOcp(moreau::MakeOcpProblem("stewart_anitescu"));
  const double ocp_error = std::fabs(ocp.initial_state[0] - (9.0 - std::sqrt(417.0)) / 8.0);
  std::printf("consumer: ocp status %s, x0* error %.3e\n", moreau::ToString(ocp.status).c_str(),
              ocp_error);
  const bool ok = result.status == moreau::RadauStatus::kSuccess && error < 1e-8 &&
                  ocp.status == moreau::OcpStatus::kSolved && ocp_error < 1e-6;
  return ok ? 0 : 1;
}
