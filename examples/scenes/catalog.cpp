#include "moreau/scenes/catalog.hpp"

#include "moreau/core/error.hpp"
#include "scenes.hpp"

namespace moreau {

const std::vector<SceneDefinition>& SceneCatalog() {
  static const std::vector<SceneDefinition> catalog = {
      {"hopf", "Hopf normal form limit cycle, exact solution (smooth order test)",
       scenes::MakeHopf},
      {"vanderpol", "Van der Pol oscillator, stiff for large mu (smooth)", scenes::MakeVanDerPol},
      {"robertson", "Robertson stiff chemical kinetics on [0, 1e5] (smooth, stiff)",
       scenes::MakeRobertson},
      {"heat", "1-D heat equation with 2000 states and a sparse Jacobian (smooth, large)",
       scenes::MakeHeat},
  };
  return catalog;
}

Scene MakeScene(const std::string& name) {
  std::string available;
  for (const SceneDefinition& definition : SceneCatalog()) {
    if (definition.name == name) return definition.make();
    available += (available.empty() ? "" : ", ") + definition.name;
  }
  ThrowInvalidArgument("unknown scene '", name, "'; available scenes: ", available);
}

std::string DefaultSceneName() { return "vanderpol"; }

}  // namespace moreau
