#pragma once
// Scenes of contacts that the velocity-level values do not show at first order: a contact that
// a control breakpoint ends, a contact that begins and ends inside one long step, and the
// doorway's optimal controls, where both happen (tests of IDA and of adaptive FESD).

#include <cstddef>

#include "moreau/model/scene.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau::testing {

// x' = u against the wall x >= 0 from x = 1: u = -1 until t = 2, then u = +1. The wall is
// reached at t = 1 and left at the breakpoint t = 2 (the push becomes a pull), x(3) = 1.
inline Scene WallScene() {
  Scene scene;
  scene.name = "wall";
  scene.state_names = {"x"};
  scene.initial_state = Vector{{1.0}};
  scene.final_time = 3.0;
  InputSpec u;
  u.name = "u";
  u.signal = PiecewiseConstantSignal{{2.0}, {-1.0, 1.0}};
  scene.inputs.push_back(u);
  scene.dynamics = MakeSmoothFunction(
      "wall.f", 1, [](const auto&, const auto& input, const auto&, const auto&, auto& out) {
        out[0] = input[0];
      });
  MovingSet wall;
  wall.name = "wall";
  wall.constraint_names = {"c"};
  wall.constraints = MakeSmoothFunction(
      "wall.c", 1,
      [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = x[0]; });
  scene.effects.push_back(wall);
  return scene;
}

// S5 with its two inputs piecewise constant on the 20 control intervals of 0.6.
inline Scene S5WithControls(const double (&controls)[20][2]) {
  Scene scene = MakeScene("S5");
  for (int j = 0; j < 2; ++j) {
    PiecewiseConstantSignal& signal = scene.inputs[static_cast<std::size_t>(j)].signal;
    signal.breakpoints.clear();
    signal.values.clear();
    for (int k = 0; k < 20; ++k) {
      if (k > 0) signal.breakpoints.push_back(0.6 * k);
      signal.values.push_back(controls[k][j]);
    }
  }
  return scene;
}

// The doorway as solved by `moreau ocp doorway` (collocation, N = 20): its optimal controls,
// piecewise constant on intervals of 0.6, as inputs of S5.
inline Scene DoorwayOptimumScene() {
  const double controls[20][2] = {
      {0.1676530446276647, -2.1794299467309544},  {-0.8742518583665925, -1.647438947409691},
      {-2.3008400692503286, 0.37811115664874995}, {-1.4891512487163974, 1.9510540922861717},
      {-0.5966242215388278, 2.4302831166683365},  {-0.10110631832557485, 2.512727713498518},
      {0.26460132261420816, 2.3262971864616913},  {0.46910247502488106, 2.2766478914791515},
      {1.0939199014383618, 1.8525761780282728},   {0.935297055933438, 1.815967172549068},
      {0.608608051031823, 1.859058840348385},     {0.05892853682005426, 1.999985721893435},
      {-0.09678597937436269, 1.9845048532743208}, {-0.35206224464209124, 1.8314550804312453},
      {0.3212912708824081, -3.1234541409752103},  {1.2242254606599956, -2.5259000035636996},
      {2.2583795977502588, -1.9529963465576619},  {2.685256160101231, -1.4508291217745304},
      {2.9812589476233904, -1.082226483658619},   {3.089673714845338, -0.724065200453324}};
  return S5WithControls(controls);
}

// A point flying at unit speed along x2 = 0.9 towards the fixed unit disc at the origin:
// contact at x1 = -sqrt(1 - 0.81), slide over the disc (angle phi from phi0 = pi - asin 0.9,
// phi' = -sin phi) to its top, where the multiplier vanishes, after
// tau = ln tan(phi0 / 2); then free flight along x2 = 1. x0 = (x0, 0.9), tf = 5 - x0.
inline Scene DiscInTheWayScene(double x0) {
  Scene scene;
  scene.name = "disc_in_the_way";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{x0, 0.9}};
  scene.final_time = 5.0 - x0;
  scene.dynamics = MakeSmoothFunction(
      "disc_in_the_way.f", 2, [](const auto&, const auto&, const auto&, const auto&, auto& out) {
        out[0] = 1.0;
        out[1] = 0.0;
      });
  MovingSet disc;
  disc.name = "disc";
  disc.constraint_names = {"c"};
  disc.constraints = MakeSmoothFunction(
      "disc_in_the_way.c", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0] * x[0] + x[1] * x[1] - 1.0;
      });
  scene.effects.push_back(disc);
  return scene;
}

}  // namespace moreau::testing
