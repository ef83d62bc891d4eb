// Electrical circuits with ideal diodes as complementarity systems (docs/complementarity.md):
// a diode's current lambda >= 0 and reverse voltage w >= 0 are complementary.
// SI units throughout (V, A, s, ohm, F, H).

#include <cmath>
#include <numbers>
#include <string>

#include "scenes.hpp"

namespace moreau::scenes {

// Half-wave rectifier of Siconos' CircuitRLCD example: an LC oscillator (L, C) in parallel
// with a resistor R in series with an ideal diode. x = (v_C, i_L), the capacitor voltage and
// the inductor current; lambda = the diode current, w = its reverse voltage.
//   v_C' = -i_L / C - lambda / C,   i_L' = v_C / L,   w = -v_C + R lambda:  D = R (index 1).
// Conducting (w = 0): lambda = v_C / R, a damped parallel RLC; blocking (lambda = 0,
// v_C <= 0): an undamped LC. The switch times follow in closed form
// (tests/problems/reference_problems.hpp, docs/complementarity.md).
Scene MakeRectifier() {
  Scene scene;
  scene.name = "rectifier";
  scene.description =
      "half-wave rectifier (Siconos CircuitRLCD): LC oscillator with a resistor and an ideal "
      "diode in parallel; damped while the diode conducts (time in s)";
  scene.state_names = {"v_C", "i_L"};
  scene.initial_state = Vector{{10.0, 0.0}};
  scene.final_time = 2e-3;  // six diode switches in the first three periods (0.628 ms each)
  // Its scale (docs/accuracy.md): time in seconds, a period of 0.628 ms; the first step on
  // the microsecond scale, output every 10 us (63 points a period).
  scene.defaults.initial_step = 1e-6;
  scene.defaults.output_step = 1e-5;
  const int L = scene.AddParameter("L", 1e-2, "inductance [H]");
  const int C = scene.AddParameter("C", 1e-6, "capacitance [F]");
  const int R = scene.AddParameter("R", 1e3, "resistance in series with the diode [ohm]");
  scene.dynamics = MakeSmoothFunction(
      "rectifier.f", 2, [L, C](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = -x[1] / p[C];
        out[1] = x[0] / p[L];
      });
  Complementarity diode;
  diode.name = "diode";
  diode.pair_names = {"D"};
  diode.input_matrix = MakeSmoothFunction(
      "diode.B", 2, [C](const auto&, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = -1.0 / p[C];  // out[1] = 0: the diode current does not drive i_L
      });
  diode.output = MakeSmoothFunction(
      "diode.g", 1,
      [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = -x[0]; });
  diode.feedthrough = MakeSmoothFunction(
      "diode.D", 1,
      [R](const auto&, const auto&, const auto&, const auto& p, auto& out) { out[0] = p[R]; });
  scene.effects.push_back(diode);
  scene.view.units = {{"v_C", "V"}, {"i_L", "A"}, {"t", "s"}};
  scene.view.labels = {{"v_C", "capacitor voltage"}, {"i_L", "inductor current"}};
  // The phase plane (v_C, i_L): the state as a point with its path.
  scene.view.bodies = {{"state", "v_C", "i_L", 0.0, true}};
  return scene;
}

// Full-wave diode bridge: a sinusoidal source V(t) = V0 sin(2 pi f t) (a center-tapped
// winding: two halves V/2 with R_s/2 each, center m) feeds, through four diodes, a load
// capacitor C_L in parallel with R_L (two halves R_L/2, midpoint q). Nodes: a, b (source ends),
// p, n (load); D1: a -> p, D2: b -> p, D3: n -> a, D4: n -> b. The center tap is tied to the
// load's midpoint (the reference node m = q): the ideal bridge alone leaves the potentials of
// one side undetermined while all four diodes block (its diodes form a cut set), and the tie
// fixes them; it carries the current c . lambda, c = (1, 1, -1, -1), which vanishes whenever
// both diodes of a path conduct alike or none conducts. Each diode has an on-resistance R_on:
// the diodes also form a loop, and without it D would be singular (the circulating current
// (1, -1, 1, -1) around the ring). Eliminating the node potentials (docs/complementarity.md)
// leaves one state x = v_L and, lambda the diode currents and w their reverse voltages,
//   v_L' = (lambda_1 + ... + lambda_4) / (2 C_L) - v_L / (R_L C_L),
//   w = g + D lambda,  g = (v_L - V, v_L + V, v_L + V, v_L - V) / 2,
//   D = R_on I + (R_L / 4) c c^T + (R_s / 2) (e13 e13^T + e24 e24^T),
// e13 = (1, 0, -1, 0), e24 = (0, 1, 0, -1): symmetric positive definite, a P-matrix.
// D1 and D4 (and D2 and D3) switch together, by the bridge's symmetry.
Scene MakeDiodeBridge() {
  Scene scene;
  scene.name = "diode_bridge";
  scene.description =
      "full-wave diode bridge feeding an RC load from a sinusoidal source (4 diodes, switching "
      "in pairs; time in s)";
  scene.state_names = {"v_L"};
  scene.initial_state = Vector{{0.0}};
  scene.final_time = 0.04;  // two periods of the 50 Hz source
  // Its scale: a 20 ms source period; the first step 10 us, output every 0.2 ms, and steps of
  // at most 1 ms, below the 1.5 ms conduction intervals of a half period (without the bound
  // error control stepped over the one at 13.7 ms: the bridge's state forgets it, the events
  // do not).
  scene.defaults.initial_step = 1e-5;
  scene.defaults.max_step = 1e-3;
  scene.defaults.output_step = 2e-4;
  const int v0 = scene.AddParameter("V0", 10.0, "source amplitude [V]");
  const int freq = scene.AddParameter("f", 50.0, "source frequency [Hz]");
  const int rs = scene.AddParameter("R_s", 1.0, "source resistance [ohm]");
  const int ron = scene.AddParameter("R_on", 0.1, "diode on-resistance [ohm]");
  const int cl = scene.AddParameter("C_L", 1e-4, "load capacitance [F]");
  const int rl = scene.AddParameter("R_L", 1e3, "load resistance [ohm]");
  scene.dynamics = MakeSmoothFunction(
      "bridge.f", 1, [cl, rl](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = -x[0] / (p[rl] * p[cl]);
      });
  Complementarity bridge;
  bridge.name = "bridge";
  bridge.pair_names = {"D1", "D2", "D3", "D4"};
  bridge.input_matrix = MakeSmoothFunction(
      "bridge.B", 4, [cl](const auto&, const auto&, const auto&, const auto& p, auto& out) {
        for (int j = 0; j < 4; ++j) out[j] = 0.5 / p[cl];
      });
  bridge.output = MakeSmoothFunction(
      "bridge.g", 4,
      [v0, freq](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        using std::sin;
        const auto v = p[v0] * sin(2.0 * std::numbers::pi * p[freq] * t);
        out[0] = 0.5 * (x[0] - v);
        out[1] = 0.5 * (x[0] + v);
        out[2] = 0.5 * (x[0] + v);
        out[3] = 0.5 * (x[0] - v);
      });
  bridge.feedthrough = MakeSmoothFunction(
      "bridge.D", 16,
      [rs, ron, rl](const auto&, const auto&, const auto&, const auto& p, auto& out) {
        const double c[4] = {1.0, 1.0, -1.0, -1.0};
        const double e13[4] = {1.0, 0.0, -1.0, 0.0};
        const double e24[4] = {0.0, 1.0, 0.0, -1.0};
        for (int k = 0; k < 4; ++k) {
          for (int j = 0; j < 4; ++j) {
            out[k * 4 + j] =
                0.25 * p[rl] * c[k] * c[j] + 0.5 * p[rs] * (e13[k] * e13[j] + e24[k] * e24[j]);
            if (k == j) out[k * 4 + j] += p[ron];
          }
        }
      });
  scene.effects.push_back(bridge);
  return scene;
}

// Buck converter in discontinuous conduction, with its switch given as a PWM control signal
// u(t) in {0, 1} (period T_s, duty cycle 0.4). x = (i_L, v_C); the switch node x sits at V_in
// while the switch is closed. While it is open the freewheeling diode carries i_L and the
// switch-node voltage v_x >= 0 is complementary to i_L >= 0: the diode conducts (v_x = 0)
// while i_L > 0 and blocks when i_L falls to 0, v_x then holding i_L at zero. As a
// complementarity system (index 2, D = 0): lambda = v_x, w = i_L,
//   i_L' = (u V_in - v_C)/L + (1 - u) lambda / L,   v_C' = (i_L - v_C/R)/C.
// While the switch is closed lambda has no effect (B = 0) and i_L > 0 keeps the pair
// inactive.
Scene MakeBuckConverter() {
  Scene scene;
  scene.name = "buck";
  scene.description =
      "buck converter in discontinuous conduction: PWM switch as a control signal, "
      "freewheeling diode (index-2 complementarity; time in s)";
  scene.state_names = {"i_L", "v_C"};
  scene.initial_state = Vector{{0.0, 0.0}};
  constexpr double kPeriod = 2e-5;  // 50 kHz
  constexpr double kDuty = 0.4;
  constexpr int kPeriods = 20;
  scene.final_time = kPeriods * kPeriod;
  // Its scale: a PWM period of 20 us (the breakpoints bound the steps); output every 0.5 us.
  scene.defaults.initial_step = 1e-8;
  scene.defaults.output_step = 5e-7;
  const int vin = scene.AddParameter("V_in", 12.0, "input voltage [V]");
  const int L = scene.AddParameter("L", 5e-5, "inductance [H]");
  const int C = scene.AddParameter("C", 2e-5, "capacitance [F]");
  const int R = scene.AddParameter("R", 20.0, "load resistance [ohm]");
  InputSpec pwm;
  pwm.name = "u";
  pwm.description = "switch state (1 closed, 0 open), PWM 50 kHz, duty cycle 0.4";
  pwm.signal.values = {1.0};
  for (int k = 0; k < kPeriods; ++k) {
    pwm.signal.breakpoints.push_back((k + kDuty) * kPeriod);
    pwm.signal.values.push_back(0.0);
    if (k + 1 < kPeriods) {
      pwm.signal.breakpoints.push_back((k + 1) * kPeriod);
      pwm.signal.values.push_back(1.0);
    }
  }
  scene.inputs.push_back(pwm);
  scene.dynamics = MakeSmoothFunction(
      "buck.f", 2,
      [vin, L, C, R](const auto& x, const auto& u, const auto&, const auto& p, auto& out) {
        out[0] = (u[0] * p[vin] - x[1]) / p[L];
        out[1] = (x[0] - x[1] / p[R]) / p[C];
      });
  Complementarity diode;
  diode.name = "diode";
  diode.pair_names = {"D"};
  diode.input_matrix = MakeSmoothFunction(
      "diode.B", 2, [L](const auto&, const auto& u, const auto&, const auto& p, auto& out) {
        out[0] = (1.0 - u[0]) / p[L];  // out[1] = 0
      });
  diode.output = MakeSmoothFunction(
      "diode.g", 1,
      [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = x[0]; });
  scene.effects.push_back(diode);
  return scene;
}

}  // namespace moreau::scenes
