#include "check_command.hpp"

#include <cstdio>

#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau::tool {

Scene ResolveScene(const std::string& argument) {
  return IsSceneFile(argument) ? LoadScene(argument) : MakeScene(argument);
}

void CheckScene(const Scene& scene, int stages) {
  RequireArgument(stages >= 1 && stages <= 7, "--stages must be in [1, 7], got ", stages);
  ValidateScene(scene);
  const LoweredSystem lowered(scene);
  const int ny = lowered.num_states(), nz = lowered.num_algebraic();
  std::printf("scene       %s: valid\n", scene.name.c_str());
  std::printf("states      %d (x), %d inputs, %d parameters, %zu effects\n", scene.num_states(),
              scene.num_inputs(), scene.num_parameters(), scene.effects.size());
  for (const Effect& effect : scene.effects) {
    std::printf("  %s '%s'\n", EffectKind(effect).c_str(), EffectName(effect).c_str());
  }
  std::printf(
      "lowered     %d states y (x, relay memories, clock), %d algebraic z, %d equations "
      "G, %d complementarity pairs\n",
      ny, nz, lowered.num_equations(), lowered.num_pairs());
  std::printf(
      "fesd        %d unknowns per element (s = %d: s (n_y + n_z)); a group ending on a "
      "switch adds %d (velocity level and element length)\n",
      stages * (ny + nz), stages, nz + 1);
  std::string integrators;
  for (const std::string& name : IntegratorsSupporting(scene)) {
    integrators += (integrators.empty() ? "" : ", ") + name;
  }
  std::printf("integrators %s (auto: %s)\n", integrators.empty() ? "none" : integrators.c_str(),
              integrators.empty() ? "-" : AutomaticIntegrator(scene).c_str());
}

}  // namespace moreau::tool
