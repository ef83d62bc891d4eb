// Sweeping processes and projected dynamical systems (reference problems S1-S3).
#include <cmath>
#include <limits>
#include <numbers>

#include "scenes.hpp"

namespace moreau::scenes {

Scene MakeS1() {
  Scene scene;
  scene.name = "S1";
  scene.description =
      "sweeping process x' in -1 - N_C(t)(x), C(t) = {x >= t}, x(0) = 2: x = 2 - t until the "
      "boundary is met at t = 1, then swept along, x = t (sweeping paper, Example 1)";
  scene.state_names = {"x"};
  scene.initial_state = Vector{{2.0}};
  scene.final_time = 2.0;
  const int drift = scene.AddParameter("drift", -1.0, "free velocity f");
  const int speed = scene.AddParameter("speed", 1.0, "velocity of the moving boundary");
  scene.dynamics = MakeSmoothFunction(
      "S1.f", 1, [drift](const auto&, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = p[drift];
      });
  MovingSet set;
  set.name = "wall";
  set.constraint_names = {"c"};
  set.constraints = MakeSmoothFunction(
      "S1.c", 1, [speed](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        out[0] = x[0] - p[speed] * t;
      });
  scene.effects.push_back(set);
  // A point on a line, and the wall x = speed t that sweeps it.
  scene.view.bodies = {{"x", "x", "", 0.06, false}};
  scene.view.obstacles = {
      {"wall", ViewObstacle::Shape::kSegment, {"speed*t", "-0.5", "speed*t", "0.5"}}};
  scene.view.window = {-0.2, 2.4, -0.7, 0.7};
  return scene;
}

Scene MakeS2() {
  Scene scene;
  scene.name = "S2";
  scene.description =
      "play operator: -x' in N_C(t)(x), C(t) = [sin t - r, sin t + r], r = 1/2, x(0) = 0; "
      "lower and upper bound alternate in activity (switches at pi/6, pi/2, pi, 3pi/2, then "
      "2pi-periodic)";
  scene.state_names = {"x"};
  scene.initial_state = Vector{{0.0}};
  scene.final_time = 4.0 * std::numbers::pi;
  const int r = scene.AddParameter("r", 0.5, "half-width of the moving interval");
  const int amplitude = scene.AddParameter("amplitude", 1.0, "amplitude of the interval's motion");
  MovingSet set;
  set.name = "interval";
  set.constraint_names = {"lower", "upper"};
  set.constraints = MakeSmoothFunction(
      "S2.c", 2,
      [r, amplitude](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = x[0] - p[amplitude] * sin(t) + p[r];
        out[1] = p[amplitude] * sin(t) + p[r] - x[0];
      });
  scene.effects.push_back(set);
  // The play: a point kept between the two ends of the moving interval.
  scene.view.bodies = {{"x", "x", "", 0.05, false}};
  scene.view.obstacles = {{"lower",
                           ViewObstacle::Shape::kSegment,
                           {"amplitude*sin(t) - r", "-0.3", "amplitude*sin(t) - r", "0.3"}},
                          {"upper",
                           ViewObstacle::Shape::kSegment,
                           {"amplitude*sin(t) + r", "-0.3", "amplitude*sin(t) + r", "0.3"}}};
  scene.view.window = {-1.8, 1.8, -0.6, 0.6};
  return scene;
}

Scene MakeS3() {
  Scene scene;
  scene.name = "S3";
  scene.description =
      "projected rotation x' in (x2, -x1) - N_C(x), C = {x2 + 1 >= 0}, x(0) = (sqrt2, sqrt2): "
      "contact at t = 5pi/12 at (sqrt3, -1), slides with x1' = -1, leaves at t = 5pi/12 + sqrt3 "
      "at (0, -1); x(11pi/12 + sqrt3) = (-1, 0)";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{std::sqrt(2.0), std::sqrt(2.0)}};
  scene.final_time = 11.0 * std::numbers::pi / 12.0 + std::sqrt(3.0);
  const int floor = scene.AddParameter("floor", -1.0, "height of the floor x2 >= floor");
  scene.dynamics = MakeSmoothFunction(
      "S3.f", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[1];
        out[1] = -x[0];
      });
  MovingSet set;
  set.name = "floor";
  set.constraint_names = {"c"};
  set.constraints = MakeSmoothFunction(
      "S3.c", 1, [floor](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = x[1] - p[floor];
      });
  scene.effects.push_back(set);
  // The state as a point in the plane with its path, above the floor x2 = floor.
  scene.view.bodies = {{"x", "x1", "x2", 0.05, true}};
  scene.view.obstacles = {{"floor", ViewObstacle::Shape::kSegment, {"-3", "floor", "3", "floor"}}};
  scene.view.window = {-2.2, 2.2, -1.5, 2.2};
  return scene;
}

Scene MakeS4() {
  Scene scene;
  scene.name = "S4";
  scene.description =
      "wave-rider: x' in (0, u) - N_C(t)(x), C(t) = {x1 + cos(x2 - t) >= 0}, constant control "
      "u = 2; the moving boundary pushes the unactuated x1 from 0.5 towards 1. The reference "
      "x0 = (0, 2) lies outside C(0) (cos 2 < 0), so x0 = (0.5, 2) is used";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{0.5, 2.0}};
  scene.final_time = 5.0;
  InputSpec control;
  control.name = "u";
  control.signal.values = {2.0};
  control.lower = -std::numeric_limits<double>::infinity();
  control.description = "velocity of x2 (piecewise constant)";
  scene.inputs.push_back(control);
  scene.dynamics = MakeSmoothFunction(
      "S4.f", 2, [](const auto&, const auto& u, const auto&, const auto&, auto& out) {
        out[0] = 0.0;
        out[1] = u[0];
      });
  MovingSet set;
  set.name = "wave";
  set.constraint_names = {"c"};
  set.constraints = MakeSmoothFunction(
      "S4.c", 1, [](const auto& x, const auto&, const auto& t, const auto&, auto& out) {
        using std::cos;
        out[0] = x[0] + cos(x[1] - t);
      });
  scene.effects.push_back(set);
  // The state with its path, and the moving boundary x1 = -cos(x2 - t) as a polyline.
  scene.view.bodies = {{"x", "x1", "x2", 0.08, true}};
  constexpr int kWaveSegments = 64;
  constexpr double kWaveTop = 14.0;
  auto node = [](int k) { return std::to_string(kWaveTop * k / kWaveSegments); };
  for (int k = 0; k < kWaveSegments; ++k) {
    scene.view.obstacles.push_back(
        {"wave_" + std::to_string(k),
         ViewObstacle::Shape::kSegment,
         {"-cos(" + node(k) + " - t)", node(k), "-cos(" + node(k + 1) + " - t)", node(k + 1)}});
  }
  scene.view.window = {-1.5, 2.0, 0.0, kWaveTop};
  return scene;
}

Scene MakeS5() {
  Scene scene;
  scene.name = "S5";
  scene.description =
      "moving doorway: a pusher (x3, x4) with velocity u and a passive slider (x1, x2), discs "
      "of radius 1, between two discs of radius 8 centred at (cos t +- 8, 0); x' in (0, 0, u) - "
      "N_C(t)(x) (paper: sweeping processes, Sec. VI-B). With the fixed control u = (0, 1) the "
      "pusher slides through the moving doorway; `moreau ocp doorway` pushes the slider";
  scene.state_names = {"x1", "x2", "x3", "x4"};
  scene.initial_state = Vector{{-1.0, -6.0, 1.0, -5.0}};
  scene.final_time = 12.0;
  const int contact = scene.AddParameter("contact", 2.0, "pusher-slider distance at contact");
  const int radius = scene.AddParameter("radius", 8.0, "radius of the doorway discs");
  const int gap = scene.AddParameter(
      "gap", 0.0, "width of the doorway at y = 0 (0: the discs touch, the paper's doorway)");
  for (const char* name : {"u1", "u2"}) {
    InputSpec u;
    u.name = name;
    u.signal.values = {std::string(name) == "u2" ? 1.0 : 0.0};
    u.lower = -5.0;
    u.upper = 5.0;
    u.description = "pusher velocity";
    scene.inputs.push_back(u);
  }
  scene.dynamics = MakeSmoothFunction(
      "S5.f", 4, [](const auto&, const auto& u, const auto&, const auto&, auto& out) {
        out[2] = u[0];
        out[3] = u[1];
      });
  MovingSet set;
  set.name = "doorway";
  set.constraint_names = {"pusher_slider", "slider_right", "slider_left", "pusher_right",
                          "pusher_left"};
  set.constraints = MakeSmoothFunction(
      "S5.c", 5,
      [contact, radius, gap](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        using std::cos;
        auto square = [](const auto& a) { return a * a; };
        const auto centre = cos(t);
        const auto offset = p[radius] + 0.5 * p[gap];  // disc centres at centre +- offset
        out[0] = square(x[0] - x[2]) + square(x[1] - x[3]) - square(p[contact]);
        out[1] = square(x[0] - (centre + offset)) + square(x[1]) - square(p[radius]);
        out[2] = square(x[0] - (centre - offset)) + square(x[1]) - square(p[radius]);
        out[3] = square(x[2] - (centre + offset)) + square(x[3]) - square(p[radius]);
        out[4] = square(x[2] - (centre - offset)) + square(x[3]) - square(p[radius]);
      });
  scene.effects.push_back(set);
  // Slider and pusher as discs of radius contact/2 = 1 (they touch at centre distance
  // `contact`). The doorway keeps their *centres* outside its discs of radius `radius`, so it
  // is drawn with radius - contact/2: the drawn discs touch exactly when a constraint is active.
  scene.view.bodies = {{"slider", "x1", "x2", 1.0, false}, {"pusher", "x3", "x4", 1.0, false}};
  scene.view.obstacles = {{"right",
                           ViewObstacle::Shape::kCircle,
                           {"cos(t) + radius + gap/2", "0", "radius - contact/2"}},
                          {"left",
                           ViewObstacle::Shape::kCircle,
                           {"cos(t) - radius - gap/2", "0", "radius - contact/2"}}};
  scene.view.window = {-12.0, 12.0, -9.0, 9.0};
  return scene;
}

}  // namespace moreau::scenes
