#include "moreau/scenes/catalog.hpp"

#include <exception>

#include "moreau/core/error.hpp"
#include "moreau/scenes/crowd.hpp"
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
      {"S1", "sweeping by a moving wall, contact at t = 1 (time-varying set)", scenes::MakeS1},
      {"S2", "play operator: interval [sin t - 1/2, sin t + 1/2] sweeps the state", scenes::MakeS2},
      {"S3", "rotation projected on a floor: contact, sliding, leaving", scenes::MakeS3},
      {"S4", "wave-rider: a moving boundary pushes an unactuated state (fixed control)",
       scenes::MakeS4},
      {"S5", "moving doorway: a pusher drives a slider between two moving discs", scenes::MakeS5},
      {"crowd",
       "crowd motion (Maury-Venel): 100 discs pushed through a door; crowd:N=1000,seed=3 for "
       "others (docs/crowd-motion.md)",
       [] { return MakeCrowdScene(CrowdOptions{}); }},
      {"F1", "oscillator switching at the unit circle (FESD order benchmark)", scenes::MakeF1},
      {"F2a", "crossing a switching surface", scenes::MakeF2a},
      {"F2b", "entering a sliding mode", scenes::MakeF2b},
      {"F2c", "leaving a sliding mode", scenes::MakeF2c},
      {"F2d", "spontaneous switch (non-unique solution)", scenes::MakeF2d},
      {"F3", "sliding to the origin, x' in -sign(x)", scenes::MakeF3},
      {"F4", "Stewart-Anitescu IVP, x' in 2 - sign(x)", scenes::MakeF4},
      {"H1", "thermostat with hysteresis (time-freezing)", scenes::MakeH1},
      {"H2", "turbo car with a hysteresis turbo and a given control (time-freezing)",
       scenes::MakeH2},
      {"H3", "two rooms with their own thermostats: interleaved relay switches",
       scenes::MakeTwoThermostats},
      {"D2", "robot among obstacles pushed by a traveling wave (DAI, index-3 constraints)",
       scenes::MakeD2},
      {"D3", "re-entry with heat-flux, dynamic-pressure and load-factor limits (DAI)",
       scenes::MakeD3},
      {"dai_index2", "index-2 DAI x2 >= sin(x1) with a known solution (alpha-method test)",
       scenes::MakeDaiIndex2},
      {"rectifier",
       "half-wave rectifier (Siconos CircuitRLCD): LC oscillator, resistor and ideal diode",
       scenes::MakeRectifier},
      {"diode_bridge", "full-wave diode bridge feeding an RC load (4 diodes, index 1)",
       scenes::MakeDiodeBridge},
      {"buck", "buck converter in discontinuous conduction, PWM switch as a control (index 2)",
       scenes::MakeBuckConverter},
      {"hard_grazing", "grazing contact: a circle touches a floor tangentially (c = lambda = 0)",
       scenes::MakeHardGrazing},
      {"hard_simultaneous", "two walls reached at the same instant", scenes::MakeHardSimultaneous},
      {"hard_corner", "corner whose constraint gradients are 1e-6 apart", scenes::MakeHardCorner},
      {"hard_fast_wall", "a wall moving 1e3 times faster than the free dynamics",
       scenes::MakeHardFastWall},
      {"hard_stiff_set", "stiff decay (eigenvalues -1e6) swept by a moving wall",
       scenes::MakeHardStiffSet},
      {"hard_zeno", "twisting: switches accumulating at a finite time (Zeno-like)",
       scenes::MakeHardZeno},
      {"hard_fast_switching", "a switch every 1e-3, far denser than the default steps",
       scenes::MakeHardFastSwitching},
      {"hard_index3", "active index-3 DAI constraint with a closed-form solution (alpha)",
       scenes::MakeHardIndex3},
      {"hard_long_orbit", "1e5 elements sliding on a circle: drift in constraint satisfaction",
       scenes::MakeHardLongOrbit},
  };
  return catalog;
}

Scene MakeScene(const std::string& name) {
  // Scene families with structural options: "crowd:N=1000,seed=3".
  const std::size_t colon = name.find(':');
  if (colon != std::string::npos) {
    const std::string family = name.substr(0, colon);
    RequireArgument(family == "crowd", "scene '", name, "': only the crowd family takes options ",
                    "after a colon (crowd:N=1000,seed=3), not '", family, "'");
    try {
      return MakeCrowdScene(ParseCrowdOptions(name.substr(colon + 1)));
    } catch (const std::invalid_argument& error) {
      ThrowInvalidArgument("scene '", name, "': ", error.what());
    }
  }
  std::string available;
  for (const SceneDefinition& definition : SceneCatalog()) {
    if (definition.name == name) return definition.make();
    available += (available.empty() ? "" : ", ") + definition.name;
  }
  ThrowInvalidArgument("unknown scene '", name, "'; available scenes: ", available);
}

std::string DefaultSceneName() { return "S3"; }

}  // namespace moreau
