// Simulates the Hopf scene with the installed library and checks the known answer.
#include <cmath>
#include <cstdio>

#include "moreau/integrators/radau.hpp"
#include "moreau/scenes/catalog.hpp"

int main() {
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
  return result.status == moreau::RadauStatus::kSuccess && error < 1e-8 ? 0 : 1;
}
