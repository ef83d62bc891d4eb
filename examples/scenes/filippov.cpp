// Filippov / piecewise-smooth switching systems (reference problems F1-F4).
#include <cmath>
#include <numbers>

#include "scenes.hpp"

namespace moreau::scenes {

Scene MakeF1() {
  Scene scene;
  scene.name = "F1";
  scene.description =
      "oscillator with a state-dependent switch: x' = A1 x outside the unit circle, A2 x inside, "
      "A1 = [[1, w], [-w, 1]], A2 = [[1, -w], [w, 1]], w = 2pi, x(0) = (1/e, 0); switch at t = 1 "
      "at (1, 0), x(pi/2) = e^{pi/2 - 1} (cos 2pi(pi/2 - 1), -sin 2pi(pi/2 - 1))";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{std::exp(-1.0), 0.0}};
  scene.final_time = std::numbers::pi / 2.0;
  const int omega = scene.AddParameter("omega", 2.0 * std::numbers::pi, "angular frequency");
  SwitchingSurfaces switching;
  switching.name = "circle";
  switching.surface_names = {"c"};
  switching.surfaces = MakeSmoothFunction(
      "F1.c", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0] * x[0] + x[1] * x[1] - 1.0;
      });
  switching.mode_names = {"inside", "outside"};
  switching.modes = {MakeSmoothFunction("F1.inside", 2,
                                        [omega](const auto& x, const auto&, const auto&,
                                                const auto& p, auto& out) {
                                          out[0] = x[0] - p[omega] * x[1];  // A2 x
                                          out[1] = p[omega] * x[0] + x[1];
                                        }),
                     MakeSmoothFunction("F1.outside", 2,
                                        [omega](const auto& x, const auto&, const auto&,
                                                const auto& p, auto& out) {
                                          out[0] = x[0] + p[omega] * x[1];  // A1 x
                                          out[1] = -p[omega] * x[0] + x[1];
                                        })};
  scene.effects.push_back(switching);
  return scene;
}

// x' = below + slope t for x < 0 and above + slope t for x > 0 (the F2 family and F3, F4).
Scene MakeScalarSwitch(const std::string& name, const std::string& description, double below,
                       double above, double slope, double x0, double tf) {
  Scene scene;
  scene.name = name;
  scene.description = description;
  scene.state_names = {"x"};
  scene.initial_state = Vector{{x0}};
  scene.final_time = tf;
  const int b = scene.AddParameter("below", below, "x' for x < 0 (at t = 0)");
  const int a = scene.AddParameter("above", above, "x' for x > 0 (at t = 0)");
  const int k = scene.AddParameter("slope", slope, "time rate added to both fields");
  SwitchingSurfaces switching;
  switching.name = "sign";
  switching.surface_names = {"x"};
  switching.surfaces = MakeSmoothFunction(
      name + ".c", 1,
      [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = x[0]; });
  switching.mode_names = {"below", "above"};
  switching.modes = {
      MakeSmoothFunction(name + ".below", 1,
                         [b, k](const auto&, const auto&, const auto& t, const auto& p, auto& out) {
                           out[0] = p[b] + p[k] * t;
                         }),
      MakeSmoothFunction(name + ".above", 1,
                         [a, k](const auto&, const auto&, const auto& t, const auto& p, auto& out) {
                           out[0] = p[a] + p[k] * t;
                         })};
  scene.effects.push_back(switching);
  return scene;
}

Scene MakeF2a() {
  return MakeScalarSwitch("F2a",
                          "crossing: x' = 2 (x < 0), 0.2 (x > 0), x(0) = -1: switch at t = 0.5, "
                          "x(1.5) = 0.2",
                          2.0, 0.2, 0.0, -1.0, 1.5);
}
Scene MakeF2b() {
  return MakeScalarSwitch("F2b",
                          "sliding: x' = 1 (x < 0), -1 (x > 0), x(0) = -0.5: reaches 0 at t = 0.5 "
                          "and slides there",
                          1.0, -1.0, 0.0, -0.5, 1.5);
}
Scene MakeF2c() {
  return MakeScalarSwitch("F2c",
                          "leaving a sliding mode: x' = 1 + t (x < 0), -1 + t (x > 0), x(0) = 0: "
                          "slides until t = 1, then x = (t - 1)^2 / 2, x(1.5) = 0.125",
                          1.0, -1.0, 1.0, 0.0, 1.5);
}
Scene MakeF2d() {
  return MakeScalarSwitch("F2d",
                          "spontaneous switch: x' = -1 (x < 0), +1 (x > 0), x(0) = 0: the "
                          "solution is not unique (repulsive surface)",
                          -1.0, 1.0, 0.0, 0.0, 1.5);
}
Scene MakeF3() {
  return MakeScalarSwitch("F3",
                          "sliding to the origin: x' in -sign(x), x(0) = -sqrt2: reaches 0 at "
                          "t = sqrt2 and stays",
                          1.0, -1.0, 0.0, -std::sqrt(2.0), 2.0);
}
Scene MakeF4() {
  return MakeScalarSwitch("F4",
                          "Stewart-Anitescu IVP: x' in 2 - sign(x), x(0) = -1: switch at t = 1/3, "
                          "then x' = 1, x(2) = 2 + x0/3",
                          3.0, 1.0, 0.0, -1.0, 2.0);
}

}  // namespace moreau::scenes
