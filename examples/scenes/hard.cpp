// Hard cases (issue 9): degenerate contacts, ill-conditioned corners, widely separated time
// scales, Zeno-like switching, an active index-3 DAI constraint and a long horizon. Each has
// a closed-form answer stated in its description; tests/hard/ checks every integrator that
// supports its effects against it. Every number is a named parameter or an overridable
// initial value.
#include <cmath>
#include <numbers>

#include "scenes.hpp"

namespace moreau::scenes {

Scene MakeHardGrazing() {
  Scene scene;
  scene.name = "hard_grazing";
  scene.description =
      "grazing contact: x' = omega (x2, -x1), C = {x2 - floor >= 0}, floor = -1, x(0) = (0, 1): "
      "the circle x = (sin omega t, cos omega t) touches the floor tangentially at t = pi/omega "
      "(c = 0 and lambda = 0 at once, c'' > 0) and leaves it unchanged; x(2 pi) = (0, 1)";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{0.0, 1.0}};
  scene.final_time = 2.0 * std::numbers::pi;
  const int omega = scene.AddParameter("omega", 1.0, "angular velocity of the rotation");
  const int floor = scene.AddParameter("floor", -1.0, "height of the floor x2 >= floor");
  scene.dynamics = MakeSmoothFunction(
      "hard_grazing.f", 2,
      [omega](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = p[omega] * x[1];
        out[1] = -p[omega] * x[0];
      });
  MovingSet set;
  set.name = "floor";
  set.constraint_names = {"c"};
  set.constraints =
      MakeSmoothFunction("hard_grazing.c", 1,
                         [floor](const auto& x, const auto&, const auto&, const auto& p,
                                 auto& out) { out[0] = x[1] - p[floor]; });
  scene.effects.push_back(set);
  return scene;
}

Scene MakeHardSimultaneous() {
  Scene scene;
  scene.name = "hard_simultaneous";
  scene.description =
      "two constraints activating at the same instant: x' = (v1, v2) = (-1, -2), C = {x1 >= 0, "
      "x2 >= 0}, x(0) = (1, 2): both walls are reached at t = 1, then x = (0, 0) with "
      "lambda = (1, 2)";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{1.0, 2.0}};
  scene.final_time = 2.0;
  const int v1 = scene.AddParameter("v1", -1.0, "free velocity of x1");
  const int v2 = scene.AddParameter("v2", -2.0, "free velocity of x2");
  scene.dynamics =
      MakeSmoothFunction("hard_simultaneous.f", 2,
                         [v1, v2](const auto&, const auto&, const auto&, const auto& p, auto& out) {
                           out[0] = p[v1];
                           out[1] = p[v2];
                         });
  MovingSet set;
  set.name = "walls";
  set.constraint_names = {"c1", "c2"};
  set.constraints =
      MakeSmoothFunction("hard_simultaneous.c", 2,
                         [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
                           out[0] = x[0];
                           out[1] = x[1];
                         });
  scene.effects.push_back(set);
  return scene;
}

Scene MakeHardCorner() {
  Scene scene;
  scene.name = "hard_corner";
  scene.description =
      "corner with nearly parallel constraint gradients: c1 = sin(a/2) x1 + cos(a/2) x2 >= 0, "
      "c2 = -sin(a/2) x1 + cos(a/2) x2 >= 0, angle a = 1e-6 between the gradients (Gram "
      "matrix condition ~ 4/a^2); x' = (lateral, -1) = (0, -1), x(0) = (0, 1): x falls into the "
      "corner at t = 1 and stays, lambda1 = lambda2 = 1/(2 cos(a/2)); x(2) = (0, 0)";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{0.0, 1.0}};
  scene.final_time = 2.0;
  const int angle = scene.AddParameter("angle", 1e-6, "angle between the constraint gradients");
  const int lateral = scene.AddParameter("lateral", 0.0, "free velocity of x1");
  const int fall = scene.AddParameter("fall", -1.0, "free velocity of x2");
  scene.dynamics = MakeSmoothFunction(
      "hard_corner.f", 2,
      [lateral, fall](const auto&, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = p[lateral];
        out[1] = p[fall];
      });
  MovingSet set;
  set.name = "corner";
  set.constraint_names = {"c1", "c2"};
  set.constraints = MakeSmoothFunction(
      "hard_corner.c", 2,
      [angle](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        using std::cos;
        using std::sin;
        const auto half = 0.5 * p[angle];
        out[0] = sin(half) * x[0] + cos(half) * x[1];
        out[1] = -sin(half) * x[0] + cos(half) * x[1];
      });
  scene.effects.push_back(set);
  return scene;
}

Scene MakeHardFastWall() {
  Scene scene;
  scene.name = "hard_fast_wall";
  scene.description =
      "a set moving 1e3 times faster than the free dynamics: x' in drift - N_C(t)(x), drift = "
      "-1, C(t) = {x >= speed t}, speed = 1e3, x(0) = 2: contact at t = 2/(1 + speed), then "
      "x = speed t with lambda = speed - drift; x(1) = 1000";
  scene.state_names = {"x"};
  scene.initial_state = Vector{{2.0}};
  scene.final_time = 1.0;
  const int drift = scene.AddParameter("drift", -1.0, "free velocity");
  const int speed = scene.AddParameter("speed", 1e3, "velocity of the wall");
  scene.dynamics = MakeSmoothFunction("hard_fast_wall.f", 1,
                                      [drift](const auto&, const auto&, const auto&, const auto& p,
                                              auto& out) { out[0] = p[drift]; });
  MovingSet set;
  set.name = "wall";
  set.constraint_names = {"c"};
  set.constraints =
      MakeSmoothFunction("hard_fast_wall.c", 1,
                         [speed](const auto& x, const auto&, const auto& t, const auto& p,
                                 auto& out) { out[0] = x[0] - p[speed] * t; });
  scene.effects.push_back(set);
  return scene;
}

Scene MakeHardStiffSet() {
  Scene scene;
  scene.name = "hard_stiff_set";
  scene.description =
      "stiff dynamics in a moving set: x' = -k x (eigenvalues -k = -1e6), C(t) = {x1 + x2 >= "
      "speed t - offset}, speed = 1, offset = 0.5, x(0) = (1, -0.5): x decays to 0 within "
      "microseconds, the wall reaches it at t = 0.5 and then x1 = x2 = (speed t - offset)/2 "
      "with lambda = (speed + k (speed t - offset))/2 (up to 2.5e5); x(1) = (0.25, 0.25)";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{1.0, -0.5}};
  scene.final_time = 1.0;
  const int k = scene.AddParameter("k", 1e6, "decay rate (minus the eigenvalues)");
  const int speed = scene.AddParameter("speed", 1.0, "velocity of the wall");
  const int offset = scene.AddParameter("offset", 0.5, "wall position at t0 is -offset");
  scene.dynamics =
      MakeSmoothFunction("hard_stiff_set.f", 2,
                         [k](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
                           out[0] = -p[k] * x[0];
                           out[1] = -p[k] * x[1];
                         });
  MovingSet set;
  set.name = "wall";
  set.constraint_names = {"c"};
  set.constraints = MakeSmoothFunction(
      "hard_stiff_set.c", 1,
      [speed, offset](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        out[0] = x[0] + x[1] - (p[speed] * t - p[offset]);
      });
  scene.effects.push_back(set);
  return scene;
}

Scene MakeHardZeno() {
  Scene scene;
  scene.name = "hard_zeno";
  scene.description =
      "Zeno-like accumulation of switches (twisting): x1' = x2, x2' = -a sign(x1) - b sign(x2), "
      "a = 2 > b = 1, x(0) = (1, 0): the amplitude shrinks by q = (a-b)/(a+b) every half "
      "cycle, infinitely many switches accumulate at T_z = tau0/(1 - sqrt q), tau0 = 2a "
      "sqrt(2 x1(0))/(sqrt(a-b)(a+b)) (4.4614 for the defaults); x = (0, 0) afterwards";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{1.0, 0.0}};
  scene.final_time = 6.0;
  const int a = scene.AddParameter("a", 2.0, "gain of sign(x1) (a > b > 0)");
  const int b = scene.AddParameter("b", 1.0, "gain of sign(x2)");
  SwitchingSurfaces switching;
  switching.name = "twisting";
  switching.surface_names = {"x1", "x2"};
  switching.surfaces = MakeSmoothFunction(
      "hard_zeno.c", 2, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        out[0] = x[0];
        out[1] = x[1];
      });
  // Mode k = [x1 > 0] + 2 [x2 > 0]: x2' = -a sign(x1) - b sign(x2).
  switching.mode_names = {"neg_neg", "pos_neg", "neg_pos", "pos_pos"};
  for (int mode = 0; mode < 4; ++mode) {
    const double s1 = (mode & 1) ? 1.0 : -1.0;
    const double s2 = (mode & 2) ? 1.0 : -1.0;
    switching.modes.push_back(MakeSmoothFunction(
        "hard_zeno." + switching.mode_names[static_cast<std::size_t>(mode)], 2,
        [a, b, s1, s2](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
          out[0] = x[1];
          out[1] = -p[a] * s1 - p[b] * s2;
        }));
  }
  scene.effects.push_back(switching);
  return scene;
}

Scene MakeHardFastSwitching() {
  Scene scene;
  scene.name = "hard_fast_switching";
  scene.description =
      "switches far denser than the default steps: x' = v sign(sin(omega t)), v = 1, omega = "
      "1000 pi (a switch every 1e-3, period P = 2e-3), x(0) = 0: x is the triangle wave "
      "v min(t mod P, P - t mod P); x(0.1005) = 5e-4 v";
  scene.state_names = {"x"};
  scene.initial_state = Vector{{0.0}};
  scene.final_time = 0.1005;
  const int v = scene.AddParameter("v", 1.0, "speed");
  const int omega = scene.AddParameter("omega", 1000.0 * std::numbers::pi,
                                       "angular frequency of the switching function");
  SwitchingSurfaces switching;
  switching.name = "clock";
  switching.surface_names = {"sin"};
  switching.surfaces = MakeSmoothFunction(
      "hard_fast_switching.c", 1,
      [omega](const auto&, const auto&, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = sin(p[omega] * t);
      });
  switching.mode_names = {"down", "up"};
  switching.modes = {MakeSmoothFunction("hard_fast_switching.down", 1,
                                        [v](const auto&, const auto&, const auto&, const auto& p,
                                            auto& out) { out[0] = -p[v]; }),
                     MakeSmoothFunction("hard_fast_switching.up", 1,
                                        [v](const auto&, const auto&, const auto&, const auto& p,
                                            auto& out) { out[0] = p[v]; })};
  scene.effects.push_back(switching);
  return scene;
}

Scene MakeHardIndex3() {
  Scene scene;
  scene.name = "hard_index3";
  scene.description =
      "active index-3 DAI constraint: x1' = x2, x2' = u (algebraic, reference w = push = -2), "
      "phi = A sin(omega t) - x1 <= 0 with A = 1, omega = 1, x(0) = (0, A omega): the reference "
      "would leave the floor (push < -A omega^2), so phi = 0 throughout: x1 = A sin(omega t), "
      "x2 = A omega cos(omega t), u = -A omega^2 sin(omega t); tf = 3";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{0.0, 1.0}};
  scene.final_time = 3.0;
  const int amplitude = scene.AddParameter("A", 1.0, "amplitude of the floor");
  const int omega = scene.AddParameter("omega", 1.0, "angular frequency of the floor");
  InputSpec push;
  push.name = "u";
  push.kind = InputSpec::Kind::kAlgebraic;
  push.signal.values = {-2.0};  // the user input function w(t): push towards the floor
  push.initial_guess = 0.0;
  push.description = "acceleration (algebraic); follows w = -2 unless the floor needs it";
  scene.inputs.push_back(push);
  scene.dynamics = MakeSmoothFunction(
      "hard_index3.f", 2, [](const auto& x, const auto& u, const auto&, const auto&, auto& out) {
        out[0] = x[1];
        out[1] = u[0];
      });
  PathConstraints floor;
  floor.name = "floor";
  floor.constraint_names = {"phi"};
  floor.constraints = MakeSmoothFunction(
      "hard_index3.phi", 1,
      [amplitude, omega](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = p[amplitude] * sin(p[omega] * t) - x[0];
      });
  scene.effects.push_back(floor);
  return scene;
}

Scene MakeHardLongOrbit() {
  Scene scene;
  scene.name = "hard_long_orbit";
  scene.description =
      "long horizon on a curved active constraint: x' = omega (x2, -x1) + push x, C = {r^2 - "
      "|x|^2 >= 0}, omega = 1, push = 1, r = 1, x(0) = (1, 0): x = r (cos omega t, -sin omega t) "
      "on the circle with lambda = push/2; tf = 5000 (1e5 elements of the default FESD step), "
      "for drift of |x| off the circle";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{1.0, 0.0}};
  scene.final_time = 5000.0;
  const int omega = scene.AddParameter("omega", 1.0, "angular velocity");
  const int push = scene.AddParameter("push", 1.0, "outward growth rate");
  const int radius = scene.AddParameter("r", 1.0, "radius of the disc");
  scene.dynamics = MakeSmoothFunction(
      "hard_long_orbit.f", 2,
      [omega, push](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = p[omega] * x[1] + p[push] * x[0];
        out[1] = -p[omega] * x[0] + p[push] * x[1];
      });
  MovingSet set;
  set.name = "disc";
  set.constraint_names = {"c"};
  set.constraints = MakeSmoothFunction(
      "hard_long_orbit.c", 1,
      [radius](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = p[radius] * p[radius] - x[0] * x[0] - x[1] * x[1];
      });
  scene.effects.push_back(set);
  return scene;
}

}  // namespace moreau::scenes
