#include "check_command.hpp"

#include <cstdio>
#include <string>

#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/lowered_system.hpp"
#include "moreau/model/scene_file.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau::tool {

Scene ResolveScene(const std::string& argument) {
  return IsSceneFile(argument) ? LoadScene(argument) : MakeScene(argument);
}

namespace {

// "n_y + 1" style counts with their names, only for the parts that exist: "3 states y (2 x,
// clock)", "4 algebraic z, 4 complementarity pairs" (no "0 equations G").
std::string Count(int count, const std::string& singular, const std::string& plural) {
  return std::to_string(count) + " " + (count == 1 ? singular : plural);
}

std::string LoweredParts(const LoweredSystem& lowered) {
  const int nx = lowered.num_scene_states();
  const int memories = static_cast<int>(lowered.relay_names().size());
  // y = (x, relay memories, clock): the clock (physical time) is always the last state.
  std::string y = Count(nx, "x", "x");
  if (memories > 0) y += ", " + Count(memories, "relay memory", "relay memories");
  std::string text = Count(lowered.num_states(), "state y", "states y") + " (" + y + ", clock)";
  if (lowered.num_algebraic() == 0) return text + ", no algebraic unknowns (an ODE)";
  text += ", " + Count(lowered.num_algebraic(), "algebraic unknown z", "algebraic unknowns z");
  if (lowered.num_equations() > 0) {
    text += ", " + Count(lowered.num_equations(), "equation G", "equations G");
  }
  if (lowered.num_pairs() > 0) {
    text += ", " + Count(lowered.num_pairs(), "complementarity pair", "complementarity pairs");
  }
  return text;
}

}  // namespace

void CheckScene(const Scene& scene, int stages) {
  RequireArgument(stages >= 1 && stages <= 7, "--stages must be in [1, 7], got ", stages);
  ValidateScene(scene);
  const LoweredSystem lowered(scene);
  const int ny = lowered.num_states(), nz = lowered.num_algebraic();
  std::printf("scene       %s: valid\n", scene.name.c_str());
  std::string sizes = Count(scene.num_states(), "state x", "states x");
  if (scene.num_inputs() > 0) sizes += ", " + Count(scene.num_inputs(), "input", "inputs");
  if (scene.num_parameters() > 0) {
    sizes += ", " + Count(scene.num_parameters(), "parameter", "parameters");
  }
  sizes += scene.effects.empty()
               ? ", no effects (smooth dynamics)"
               : ", " + Count(static_cast<int>(scene.effects.size()), "effect", "effects");
  std::printf("states      %s\n", sizes.c_str());
  for (const Effect& effect : scene.effects) {
    std::printf("  %s '%s'\n", EffectKind(effect).c_str(), EffectName(effect).c_str());
  }
  std::printf("lowered     %s\n", LoweredParts(lowered).c_str());
  if (nz > 0) {
    std::printf(
        "fesd        %d unknowns per element (s = %d: s (n_y + n_z)); a group ending on a "
        "switch adds %d (velocity level and element length)\n",
        stages * (ny + nz), stages, nz + 1);
  } else {  // no switches to locate: FESD's elements are Radau IIA steps
    std::printf("fesd        %d unknowns per element (s = %d: s n_y)\n", stages * ny, stages);
  }
  std::string integrators;
  for (const std::string& name : IntegratorsSupporting(scene)) {
    integrators += (integrators.empty() ? "" : ", ") + name;
  }
  std::printf("integrators %s (auto: %s)\n", integrators.empty() ? "none" : integrators.c_str(),
              integrators.empty() ? "-" : AutomaticIntegrator(scene).c_str());
}

}  // namespace moreau::tool
