#pragma once
// Private declarations of the example scene factories (namespace moreau::scenes).

#include "moreau/model/scene.hpp"

namespace moreau::scenes {

// Smooth test problems.
inline constexpr int kHeatPoints = 2000;
inline constexpr int kHeatMode = 1;
inline constexpr double kHeatDiffusivity = 1.0;
Scene MakeHopf();
Scene MakeVanDerPol();
Scene MakeRobertson();
Scene MakeHeat();

}  // namespace moreau::scenes
