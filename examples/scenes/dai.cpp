// Differential-algebraic inequalities (alpha-method DAI stepper): the paper's robot (D2) and
// re-entry (D3) examples, and small test problems. docs/alpha-method.md documents the choices.
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <type_traits>

#include "scenes.hpp"

namespace moreau::scenes {

namespace {

InputSpec Algebraic(const std::string& name, double guess, const std::string& description) {
  InputSpec input;
  input.name = name;
  input.kind = InputSpec::Kind::kAlgebraic;
  input.initial_guess = guess;
  input.description = description;
  return input;
}

}  // namespace

Scene MakeDaiIndex2() {
  Scene scene;
  scene.name = "dai_index2";
  scene.description =
      "index-2 DAI: x1' = 1, x2' = u, x3' = -x3 + u, x2 >= sin(x1), u algebraic with user "
      "input w = 0; x1(0) = 4, x2(0) = sin 4, x3(0) = 0, tf = 2 pi - 4. The solution depends "
      "on the objective (a DAI's solution is not unique). Default (reference, u = w = 0 unless "
      "the floor needs u): the floor falls away (cos 4 < 0), x2 = sin 4 and x3 = 0 until "
      "t1 = 3 pi - 8, where sin x1 climbs back to x2; then x2 = sin x1, u = cos x1, x3 = "
      "(cos x1 + sin x1)/2 + ((cos 4 - sin 4)/2) e^{-(t - t1)}, x3(T) = 1/2 + ((cos 4 - sin "
      "4)/2) e^{-(4 - pi)} = 0.52186. Least change (u continuous): the floor is active "
      "throughout (sin is convex on [pi, 2 pi]): x2 = sin x1, u = cos x1, x3 = (cos x1 + sin "
      "x1)/2 + (x3(0) - (cos 4 + sin 4)/2) e^{-t}";
  scene.state_names = {"x1", "x2", "x3"};
  constexpr double kStart = 4.0;
  scene.initial_state = Vector{{kStart, std::sin(kStart), 0.0}};
  scene.final_time = 2.0 * std::numbers::pi - kStart;
  scene.inputs.push_back(Algebraic("u", std::cos(kStart), "slope of x2 (algebraic)"));
  scene.dynamics = MakeSmoothFunction(
      "dai_index2.f", 3, [](const auto& x, const auto& u, const auto&, const auto&, auto& out) {
        out[0] = 1.0;
        out[1] = u[0];
        out[2] = -x[2] + u[0];
      });
  PathConstraints floor;
  floor.name = "floor";
  floor.constraint_names = {"sin"};
  floor.constraints = MakeSmoothFunction(
      "dai_index2.phi", 1, [](const auto& x, const auto&, const auto&, const auto&, auto& out) {
        using std::sin;
        out[0] = sin(x[0]) - x[1];
      });
  scene.effects.push_back(floor);
  return scene;
}

Scene MakeD2() {
  Scene scene;
  scene.name = "D2";
  scene.description =
      "robot among obstacles (alpha-method paper, Sec. 8.2): x' = V cos(theta), y' = V "
      "sin(theta), theta' = V (alpha - k_y y - k_theta theta), V' = u + mu_d V_c + k_v (V_c - "
      "V) - mu_d V (onboard lane keeping and cruise control; alpha, u are the avoidance "
      "commands with user input w = 0); obstacles (r_v + r_i) - |(x, y) - c_i| <= 0 (index 3), "
      "traveling wave W t + wave_start - x <= 0, |alpha| <= steer_max, |u| <= accel_max, 0 <= V "
      "<= speed_max, |theta| <= heading_max (docs/alpha-method.md); k_y = k_theta = k_v = V_c = "
      "0 gives the paper's model";
  scene.state_names = {"x", "y", "theta", "V"};
  scene.initial_state = Vector{{0.0, 0.0, 0.0, 1.0}};
  scene.final_time = 14.0;
  const int mu_d = scene.AddParameter("mu_d", 0.1, "dynamic friction coefficient (1/s)");
  const int k_y =
      scene.AddParameter("k_y", 1.0, "lane keeping: curvature per lateral offset (1/m^2)");
  const int k_theta =
      scene.AddParameter("k_theta", 2.0, "lane keeping: curvature per heading (1/m)");
  const int cruise = scene.AddParameter("V_c", 1.0, "cruise speed (m/s)");
  const int k_v = scene.AddParameter("k_v", 0.5, "cruise control gain (1/s)");
  const int r_v = scene.AddParameter("r_v", 0.25, "vehicle radius (m)");
  const int wave_speed = scene.AddParameter("W", 1.1, "speed of the traveling wave (m/s)");
  const int wave_start = scene.AddParameter("wave_start", -0.6, "wave position at t0 (m)");
  struct Obstacle {
    const char* name;
    double x, y, r;
  };
  // Each obstacle reaches 0.02 to 0.05 m into the lane y = 0 (grazing contacts: a
  // position constraint met head-on needs more steering in one step than steer_max allows).
  constexpr Obstacle kObstacles[] = {
      {"obs1", 3.0, 0.73, 0.5}, {"obs2", 7.0, -0.8, 0.6}, {"obs3", 11.0, 0.6, 0.4}};
  constexpr int kNumObstacles = 3;
  int obstacle[kNumObstacles][3];
  for (int i = 0; i < kNumObstacles; ++i) {
    const std::string name = kObstacles[i].name;
    obstacle[i][0] = scene.AddParameter(name + "_x", kObstacles[i].x, "obstacle centroid x (m)");
    obstacle[i][1] = scene.AddParameter(name + "_y", kObstacles[i].y, "obstacle centroid y (m)");
    obstacle[i][2] = scene.AddParameter(name + "_r", kObstacles[i].r, "obstacle circumradius (m)");
  }
  const int steer_max = scene.AddParameter("steer_max", 20.0, "|alpha| <= steer_max (1/m)");
  const int accel_max = scene.AddParameter("accel_max", 4.0, "|u| <= accel_max (m/s^2)");
  const int speed_max = scene.AddParameter("speed_max", 2.5, "0 <= V <= speed_max (m/s)");
  const int heading_max = scene.AddParameter("heading_max", 1.2, "|theta| <= heading_max (rad)");
  scene.inputs.push_back(Algebraic("alpha", 0.0, "avoidance steering curvature (1/m)"));
  scene.inputs.push_back(Algebraic("u", 0.0, "avoidance acceleration (m/s^2)"));
  scene.dynamics = MakeSmoothFunction(
      "D2.f", 4, [=](const auto& x, const auto& u, const auto&, const auto& p, auto& out) {
        using std::cos;
        using std::sin;
        out[0] = x[3] * cos(x[2]);
        out[1] = x[3] * sin(x[2]);
        out[2] = x[3] * (u[0] - p[k_y] * x[1] - p[k_theta] * x[2]);
        out[3] = u[1] + p[mu_d] * p[cruise] + p[k_v] * (p[cruise] - x[3]) - p[mu_d] * x[3];
      });
  PathConstraints dai;
  dai.name = "D2";
  dai.constraint_names = {"obs1",      "obs2",      "obs3",        "wave",
                          "steer_max", "steer_min", "accel_max",   "accel_min",
                          "speed_max", "speed_min", "heading_max", "heading_min"};
  dai.constraints = MakeSmoothFunction(
      "D2.phi", 12, [=](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::sqrt;
        for (int i = 0; i < kNumObstacles; ++i) {
          const auto dx = x[0] - p[obstacle[i][0]];
          const auto dy = x[1] - p[obstacle[i][1]];
          out[i] = p[r_v] + p[obstacle[i][2]] - sqrt(dx * dx + dy * dy);
        }
        out[3] = p[wave_speed] * t + p[wave_start] - x[0];
        out[4] = u[0] - p[steer_max];
        out[5] = -u[0] - p[steer_max];
        out[6] = u[1] - p[accel_max];
        out[7] = -u[1] - p[accel_max];
        out[8] = x[3] - p[speed_max];
        out[9] = -x[3];
        out[10] = x[2] - p[heading_max];
        out[11] = -x[2] - p[heading_max];
      });
  scene.effects.push_back(dai);
  return scene;
}

Scene MakeD3() {
  Scene scene;
  scene.name = "D3";
  scene.description =
      "re-entry (alpha-method paper, Sec. 8.1) in scaled units (km, km/s, rad, s): h' = V sin "
      "gamma, V' = -D/m - g sin gamma, gamma' = L/(m V) + cos gamma (V/r - g/V), exponential "
      "atmosphere, C_L = CL_alpha alpha, C_D = CD0 + K C_L^2; heat flux C_H sqrt(rho) V^3.05 <= "
      "heat_max (W/cm^2), dynamic pressure rho V^2/2 <= q_max (kPa), load factor (L cos alpha + "
      "D sin alpha)/(m g0) <= n_max; alpha in [alpha_min, alpha_max] (docs/alpha-method.md)";
  scene.state_names = {"h", "V", "gamma"};
  scene.initial_state = Vector{{70.0, 2.0, -0.05}};
  scene.final_time = 200.0;
  const int rho0 = scene.AddParameter("rho0", 1.225, "sea-level density (kg/m^3)");
  const int scale_height = scene.AddParameter("H", 7.2, "density scale height (km)");
  const int radius = scene.AddParameter("r_e", 6371.0, "Earth radius (km)");
  const int g0 = scene.AddParameter("g0", 9.80665, "surface gravity (m/s^2)");
  const int mass = scene.AddParameter("mass", 1750.0, "vehicle mass (kg)");
  const int area = scene.AddParameter("S", 6.4, "reference area (m^2)");
  const int cl_alpha = scene.AddParameter("CL_alpha", 1.2, "lift slope (1/rad)");
  const int cd0 = scene.AddParameter("CD0", 0.05, "zero-lift drag coefficient");
  const int induced = scene.AddParameter("K", 1.0, "induced drag factor");
  const int c_h = scene.AddParameter(
      "C_H", 1.8e-8, "heat-flux constant, W/cm^2 for rho in kg/m^3 and V in m/s (Chapman)");
  const int heat_max = scene.AddParameter("heat_max", 18.5, "heat-flux limit (W/cm^2)");
  const int q_max = scene.AddParameter("q_max", 25.0, "dynamic-pressure limit (kPa)");
  const int n_max = scene.AddParameter("n_max", 5.0, "load-factor limit (g)");
  const int alpha_min = scene.AddParameter("alpha_min", 0.0, "smallest angle of attack (rad)");
  const int alpha_max = scene.AddParameter("alpha_max", 0.7, "largest angle of attack (rad)");
  // Nominal angle of attack: the initial guess and the user input w(t) that alpha follows
  // while no constraint needs it (alpha stepper, reference objective).
  constexpr double kNominalAlpha = 0.35;
  scene.inputs.push_back(Algebraic("alpha", kNominalAlpha, "angle of attack (rad)"));
  scene.inputs.back().signal.values = {kNominalAlpha};
  // Shared aerodynamics: density (kg/m^3), speed (m/s), lift and drag accelerations (m/s^2).
  auto aero = [=](const auto& x, const auto& u, const auto& p, auto* density, auto* speed,
                  auto* lift, auto* drag) {
    using std::exp;
    *density = p[rho0] * exp(-x[0] / p[scale_height]);
    *speed = 1000.0 * x[1];
    const auto cl = p[cl_alpha] * u[0];
    const auto cd = p[cd0] + p[induced] * cl * cl;
    const auto pressure = 0.5 * (*density) * (*speed) * (*speed);
    *lift = pressure * p[area] * cl / p[mass];
    *drag = pressure * p[area] * cd / p[mass];
  };
  scene.dynamics = MakeSmoothFunction(
      "D3.f", 3, [=](const auto& x, const auto& u, const auto&, const auto& p, auto& out) {
        using std::cos;
        using std::sin;
        using T = std::decay_t<decltype(x[0])>;
        T density, speed, lift, drag;
        aero(x, u, p, &density, &speed, &lift, &drag);
        const auto r = p[radius] + x[0];
        const auto g = 1e-3 * p[g0] * (p[radius] / r) * (p[radius] / r);  // km/s^2
        out[0] = x[1] * sin(x[2]);
        out[1] = -1e-3 * drag - g * sin(x[2]);
        out[2] = lift / speed + cos(x[2]) * (x[1] / r - g / x[1]);
      });
  PathConstraints dai;
  dai.name = "D3";
  dai.constraint_names = {"heat_flux", "dynamic_pressure", "load_factor", "alpha_max", "alpha_min"};
  dai.constraints = MakeSmoothFunction(
      "D3.phi", 5, [=](const auto& x, const auto& u, const auto&, const auto& p, auto& out) {
        using std::cos;
        using std::pow;
        using std::sin;
        using std::sqrt;
        using T = std::decay_t<decltype(x[0])>;
        T density, speed, lift, drag;
        aero(x, u, p, &density, &speed, &lift, &drag);
        out[0] = p[c_h] * sqrt(density) * pow(speed, 3.05) - p[heat_max];
        out[1] = 0.5e-3 * density * speed * speed - p[q_max];
        out[2] = (lift * cos(u[0]) + drag * sin(u[0])) / p[g0] - p[n_max];
        out[3] = u[0] - p[alpha_max];
        out[4] = p[alpha_min] - u[0];
      });
  scene.effects.push_back(dai);
  return scene;
}

}  // namespace moreau::scenes
