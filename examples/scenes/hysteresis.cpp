// Hybrid systems with hysteresis (reference problems H1, H2 and two thermostats).
#include <string>

#include "scenes.hpp"

namespace moreau::scenes {
namespace {

// A room heated by a thermostat: x' = -decay x + heat (heater on, mode A, w = 0) or
// -decay x (off, mode B, w = 1); off when x reaches x_off, on when it falls to x_on.
// Parameters are named "<prefix>decay", "<prefix>heat", "<prefix>x_on", "<prefix>x_off".
void AddThermostat(Scene* scene, int state, const std::string& relay_name,
                   const std::string& prefix, double decay, double heat, double x_on, double x_off,
                   int initial_memory) {
  const int k = scene->AddParameter(prefix + "decay", decay, "heat loss rate");
  const int q = scene->AddParameter(prefix + "heat", heat, "heating power (heater on)");
  const int on = scene->AddParameter(prefix + "x_on", x_on, "heater switches on at");
  const int off = scene->AddParameter(prefix + "x_off", x_off, "heater switches off at");
  HysteresisRelay relay;
  relay.name = relay_name;
  relay.input = MakeSmoothFunction(relay_name + ".input", 1,
                                   [state](const auto& x, const auto&, const auto&, const auto&,
                                           auto& out) { out[0] = x[state]; });
  relay.lower_threshold = on;
  relay.upper_threshold = off;
  const int n = scene->num_states();
  relay.mode_a =
      MakeSmoothFunction(relay_name + ".heater_on", n,
                         [state, k, q](const auto& x, const auto&, const auto&, const auto& p,
                                       auto& out) { out[state] = -p[k] * x[state] + p[q]; });
  relay.mode_b =
      MakeSmoothFunction(relay_name + ".heater_off", n,
                         [state, k](const auto& x, const auto&, const auto&, const auto& p,
                                    auto& out) { out[state] = -p[k] * x[state]; });
  relay.initial_memory = initial_memory;
  scene->effects.push_back(relay);
}

}  // namespace

Scene MakeH1() {
  Scene scene;
  scene.name = "H1";
  scene.description =
      "thermostat with hysteresis: x' = -0.2 x + 5 (heater on, w = 0), -0.2 x (off, w = 1); "
      "off at x = 20, on at x = 18; x(0) = 15, w(0) = 0. Switches at t1 = 5 ln 2, "
      "t2 = t1 + 5 ln(10/9), t3 = t2 + 5 ln(7/5), then periodic";
  scene.state_names = {"x"};
  scene.initial_state = Vector{{15.0}};
  scene.final_time = 15.0;
  AddThermostat(&scene, 0, "thermostat", "", 0.2, 5.0, 18.0, 20.0, 0);
  scene.view.units = {{"x", "°C"}};
  scene.view.labels = {{"x", "temperature"}};
  return scene;
}

Scene MakeH2() {
  Scene scene;
  scene.name = "H2";
  scene.description =
      "turbo car: q' = v, v' = u (turbo off, w = 0) or 3 u (turbo on, w = 1); the turbo engages "
      "when v rises to 15 and disengages when v falls to 10. Given control u = 3 on [0, 6), "
      "-2 on [6, 12]: turbo on at t = 5, off at t = 25/3, q(12) = 1079/9, v(12) = 8/3";
  scene.state_names = {"q", "v"};
  scene.initial_state = Vector{{0.0, 0.0}};
  scene.final_time = 12.0;
  const int boost = scene.AddParameter("boost", 3.0, "acceleration factor with the turbo on");
  const int v_off = scene.AddParameter("v_off", 10.0, "turbo disengages at this speed");
  const int v_on = scene.AddParameter("v_on", 15.0, "turbo engages at this speed");
  InputSpec acceleration;
  acceleration.name = "u";
  acceleration.signal.breakpoints = {6.0};
  acceleration.signal.values = {3.0, -2.0};
  acceleration.description = "nominal acceleration (|u| <= 5)";
  scene.inputs.push_back(acceleration);
  scene.dynamics = MakeSmoothFunction(
      "H2.f", 2,
      [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = x[1]; });
  HysteresisRelay turbo;
  turbo.name = "turbo";
  turbo.input = MakeSmoothFunction(
      "turbo.input", 1,
      [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = x[1]; });
  turbo.lower_threshold = v_off;
  turbo.upper_threshold = v_on;
  turbo.mode_a = MakeSmoothFunction(
      "turbo.off", 2,
      [](const auto&, const auto& u, const auto&, const auto&, auto& out) { out[1] = u[0]; });
  turbo.mode_b = MakeSmoothFunction(
      "turbo.on", 2, [boost](const auto&, const auto& u, const auto&, const auto& p, auto& out) {
        out[1] = p[boost] * u[0];
      });
  scene.effects.push_back(turbo);
  return scene;
}

Scene MakeTwoThermostats() {
  Scene scene;
  scene.name = "H3";
  scene.description =
      "two rooms with their own thermostats (interleaved switches): room a as H1; room b: "
      "x' = -0.3 x + 7 (on) or -0.3 x (off), off at 21, on at 19, x(0) = 22 with the heater off";
  scene.state_names = {"xa", "xb"};
  scene.initial_state = Vector{{15.0, 22.0}};
  scene.final_time = 15.0;
  AddThermostat(&scene, 0, "thermostat_a", "a.", 0.2, 5.0, 18.0, 20.0, 0);
  AddThermostat(&scene, 1, "thermostat_b", "b.", 0.3, 7.0, 19.0, 21.0, 1);
  return scene;
}

}  // namespace moreau::scenes
