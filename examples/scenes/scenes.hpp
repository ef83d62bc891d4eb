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

// Sweeping processes (sweeping.cpp).
Scene MakeS1();
Scene MakeS2();
Scene MakeS3();
Scene MakeS4();
Scene MakeS5();

// Filippov systems (filippov.cpp).
Scene MakeF1();
Scene MakeF2a();
Scene MakeF2b();
Scene MakeF2c();
Scene MakeF2d();
Scene MakeF3();
Scene MakeF4();

// Hybrid systems with hysteresis (hysteresis.cpp).
Scene MakeH1();
Scene MakeH2();
Scene MakeTwoThermostats();

// Differential-algebraic inequalities (dai.cpp).
Scene MakeDaiIndex2();
Scene MakeD2();
Scene MakeD3();

// Circuits with ideal diodes: complementarity systems (circuits.cpp).
Scene MakeRectifier();
Scene MakeDiodeBridge();
Scene MakeBuckConverter();

// Hard cases: degenerate contacts, separated time scales, Zeno-like switching (hard.cpp).
Scene MakeHardGrazing();
Scene MakeHardSimultaneous();
Scene MakeHardCorner();
Scene MakeHardFastWall();
Scene MakeHardStiffSet();
Scene MakeHardZeno();
Scene MakeHardFastSwitching();
Scene MakeHardIndex3();
Scene MakeHardLongOrbit();

}  // namespace moreau::scenes
