#pragma once
// Reference problems with known answers (../shared/reference-problems.md), for the scenes of
// the same name in examples/scenes: exact switch times, exact solution and x(T).

#include <cmath>
#include <functional>
#include <numbers>
#include <string>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau::testing {

struct ReferenceProblem {
  std::string scene;
  std::vector<double> switch_times;        // every switch in (t0, tf], in order
  std::function<Vector(double)> solution;  // exact x(t)
  // Exact algebraic inputs u(t) (InputSpec::Kind::kAlgebraic, DAI scenes); empty if none.
  std::function<Vector(double)> algebraic_inputs = {};
  Scene Make() const { return MakeScene(scene); }
  Vector FinalState() const { return solution(Make().final_time); }
};

// Hopf normal form (smooth, no switches), default parameters: r^2(t) = mu / (1 + (mu / r0^2 -
// 1) e^{-2 mu t}), angle theta0 + omega t (the scene's description).
inline ReferenceProblem Hopf() {
  const Scene scene = MakeScene("hopf");
  auto parameter = [&scene](const char* name) {
    return scene.parameters[static_cast<std::size_t>(scene.FindParameter(name))].value;
  };
  const double mu = parameter("mu"), omega = parameter("omega");
  const double r0 = scene.initial_state.norm();
  const double theta0 = std::atan2(scene.initial_state[1], scene.initial_state[0]);
  return {"hopf", {}, [mu, omega, r0, theta0](double t) {
            const double r =
                std::sqrt(mu / (1.0 + (mu / (r0 * r0) - 1.0) * std::exp(-2.0 * mu * t)));
            return Vector{{r * std::cos(theta0 + omega * t), r * std::sin(theta0 + omega * t)}};
          }};
}

// dai_index2: x1' = 1, x2' = u, x3' = -x3 + u with x2 >= sin(x1) active throughout (with the
// least-change objective): x1 = x1(0) + t, x2 = sin x1, u = cos x1,
// x3 = (cos x1 + sin x1)/2 + (x3(0) - (cos x1(0) + sin x1(0))/2) e^{-t}.
inline ReferenceProblem DaiIndex2() {
  const Scene scene = MakeScene("dai_index2");
  const double x10 = scene.initial_state[0];
  const double c0 = scene.initial_state[2] - 0.5 * (std::cos(x10) + std::sin(x10));
  return {"dai_index2",
          {},
          [x10, c0](double t) {
            const double s = x10 + t;
            return Vector{{s, std::sin(s), 0.5 * (std::cos(s) + std::sin(s)) + c0 * std::exp(-t)}};
          },
          [x10](double t) { return Vector{{std::cos(x10 + t)}}; }};
}

inline ReferenceProblem S1() {
  return {"S1", {1.0}, [](double t) { return Vector{{t < 1.0 ? 2.0 - t : t}}; }};
}

// Play operator: events pi/6, pi/2, pi, 3pi/2, 2pi, 5pi/2, 3pi, 7pi/2, 4pi (the last at tf).
inline ReferenceProblem S2() {
  const double pi = std::numbers::pi;
  return {"S2",
          {pi / 6, pi / 2, pi, 3 * pi / 2, 2 * pi, 5 * pi / 2, 3 * pi, 7 * pi / 2, 4 * pi},
          [pi](double t) {
            if (t <= pi / 6) return Vector{{0.0}};
            const double tau = t < 3 * pi / 2 ? t : std::fmod(t - 3 * pi / 2, 2 * pi) + 3 * pi / 2;
            if (tau <= pi / 2) return Vector{{std::sin(tau) - 0.5}};
            if (tau <= pi) return Vector{{0.5}};
            if (tau <= 3 * pi / 2) return Vector{{std::sin(tau) + 0.5}};
            if (tau <= 2 * pi) return Vector{{-0.5}};
            if (tau <= 5 * pi / 2) return Vector{{std::sin(tau) - 0.5}};
            return Vector{{0.5}};
          }};
}

// Contact at 5pi/12 at (sqrt3, -1), slides with x1' = -1, leaves at 5pi/12 + sqrt3.
inline ReferenceProblem S3() {
  const double t1 = 5 * std::numbers::pi / 12, t2 = t1 + std::sqrt(3.0);
  return {"S3", {t1, t2}, [t1, t2](double t) {
            if (t <= t1) {
              const double angle = std::numbers::pi / 4 - t;
              return Vector{{2 * std::cos(angle), 2 * std::sin(angle)}};
            }
            if (t <= t2) return Vector{{std::sqrt(3.0) - (t - t1), -1.0}};
            return Vector{{-std::sin(t - t2), -std::cos(t - t2)}};
          }};
}

// S4 with its fixed control u = 2 and x0 = (1/2, 2) (derived; the IDA and FESD tests check it).
// Free until cos(x2 - t) = -1/2: t1 = 2 pi/3 - 2. In contact, c = x1 + cos(phi) = 0 with
// phi = x2 - t: c' = 0 gives lambda = sin phi / (1 + sin^2 phi) and phi' = 1 / (1 + sin^2 phi),
// so t - t1 = 3/2 (phi - phi1) - (sin 2 phi - sin 2 phi1) / 4 with phi1 = 2 pi/3, and
// x = (-cos phi, phi + t). lambda reaches 0 at phi = pi: the state leaves at
// t2 = t1 + pi/2 - sqrt(3)/8 from (1, pi + t2) and moves freely, x = (1, pi + t2 + 2 (t - t2)).
inline ReferenceProblem S4() {
  const double pi = std::numbers::pi;
  const double t1 = 2 * pi / 3 - 2, phi1 = 2 * pi / 3;
  const double t2 = t1 + pi / 2 - std::sqrt(3.0) / 8;
  return {"S4", {t1, t2}, [=](double t) {
            if (t <= t1) return Vector{{0.5, 2 + 2 * t}};
            if (t >= t2) return Vector{{1.0, pi + t2 + 2 * (t - t2)}};
            // Newton on the monotone relation t(phi) (slope 1 + sin^2 phi in [1, 2]).
            double phi = phi1 + (t - t1) / 1.5;
            for (int k = 0; k < 50; ++k) {
              const double residual =
                  1.5 * (phi - phi1) - (std::sin(2 * phi) - std::sin(2 * phi1)) / 4 - (t - t1);
              const double step = residual / (1 + std::sin(phi) * std::sin(phi));
              phi -= step;
              if (std::fabs(step) <= 1e-16 * phi) break;
            }
            return Vector{{-std::cos(phi), phi + t}};
          }};
}

inline ReferenceProblem F1() {
  const double omega = 2 * std::numbers::pi;
  return {"F1", {1.0}, [omega](double t) {
            const double r = std::exp(t - 1.0);
            if (t <= 1.0) return Vector{{r * std::cos(omega * t), r * std::sin(omega * t)}};
            return Vector{{r * std::cos(omega * (t - 1.0)), -r * std::sin(omega * (t - 1.0))}};
          }};
}

inline ReferenceProblem F2a() {
  return {"F2a", {0.5}, [](double t) { return Vector{{t < 0.5 ? -1 + 2 * t : 0.2 * (t - 0.5)}}; }};
}
inline ReferenceProblem F2b() {
  return {"F2b", {0.5}, [](double t) { return Vector{{t < 0.5 ? -0.5 + t : 0.0}}; }};
}
inline ReferenceProblem F2c() {
  return {"F2c", {1.0}, [](double t) { return Vector{{t < 1.0 ? 0.0 : 0.5 * (t - 1) * (t - 1)}}; }};
}
inline ReferenceProblem F3() {
  const double ts = std::sqrt(2.0);
  return {"F3", {ts}, [ts](double t) { return Vector{{t < ts ? -ts + t : 0.0}}; }};
}
// x0 = -1: switch at t = 1/3, then x' = 1.
inline ReferenceProblem F4() {
  return {
      "F4", {1.0 / 3}, [](double t) { return Vector{{t < 1.0 / 3 ? -1 + 3 * t : t - 1.0 / 3}}; }};
}

// A room with a thermostat (H1 and H3): x' = -k x + q with the heater on (w = 0), -k x with
// it off (w = 1); off when x reaches x_off, on when it falls to x_on. The closed form follows
// the exponentials phase by phase: heating from a to b takes (1/k) ln((q/k - a)/(q/k - b)),
// cooling from a to b takes (1/k) ln(a/b). A memory inconsistent with x0 (w0 = 0 with
// x0 >= x_off, w0 = 1 with x0 <= x_on) is re-initialized at t0.
struct Thermostat {
  double k = 0.2, q = 5.0, x_on = 18.0, x_off = 20.0, x0 = 15.0;
  int w0 = 0;

  struct Switch {
    double t;
    double x;     // x at the switch (x_off or x_on)
    int w_after;  // memory after it
  };
  // Every switch in (t0, tf] (and a re-initialization at t0 = 0).
  std::vector<Switch> Switches(double tf) const {
    std::vector<Switch> switches;
    int w = w0;
    if (w == 0 && x0 >= x_off) w = 1;
    if (w == 1 && x0 <= x_on) w = 0;
    if (w != w0) switches.push_back({0.0, x0, w});
    double t = 0.0, x = x0;
    while (true) {
      const double target = w == 0 ? x_off : x_on;
      const double duration =
          w == 0 ? std::log((q / k - x) / (q / k - target)) / k : std::log(x / target) / k;
      if (t + duration > tf) break;
      t += duration;
      x = target;
      w = 1 - w;
      switches.push_back({t, x, w});
    }
    return switches;
  }
  // x(t).
  double State(double t) const {
    double start = 0.0, x = x0;
    int w = w0;
    for (const Switch& s : Switches(t)) {
      start = s.t;
      x = s.x;
      w = s.w_after;
    }
    const double dt = t - start;
    return w == 0 ? q / k + (x - q / k) * std::exp(-k * dt) : x * std::exp(-k * dt);
  }
};

// H1: the seed's tutorial thermostat.
inline Thermostat H1() { return {}; }
// H3: room a as H1; room b: x' = -0.3 x + 7 (on), off at 21, on at 19, x(0) = 22, heater off.
inline Thermostat H3RoomB() { return {0.3, 7.0, 19.0, 21.0, 22.0, 1}; }

// The half-wave rectifier (scene "rectifier", docs/complementarity.md): an LC oscillator with
// a resistor R and an ideal diode in parallel, x = (v_C, i_L), from v_C(0) = v0 > 0 (the diode
// conducts). Conducting: the damped parallel RLC v'' + 2 alpha v' + omega0^2 v = 0,
// alpha = 1/(2RC), omega0 = 1/sqrt(LC), omega_d = sqrt(omega0^2 - alpha^2), until v_C falls
// to 0; blocking: the LC oscillator, v_C = -(i/(C omega0)) sin(omega0 tau) <= 0, for exactly
// pi/omega0; then conducting again from v_C = 0 for exactly pi/omega_d, and so on. The first
// phase ends at theta1/omega_d, theta1 = atan2(v0, -b) in (0, pi), b = (-i0/C - alpha v0)/omega_d.
struct Rectifier {
  double L = 1e-2, C = 1e-6, R = 1e3, v0 = 10.0, i0 = 0.0;

  double Omega0() const { return 1.0 / std::sqrt(L * C); }
  double Alpha() const { return 1.0 / (2.0 * R * C); }
  double OmegaD() const { return std::sqrt(Omega0() * Omega0() - Alpha() * Alpha()); }
  double Period() const { return 2.0 * std::numbers::pi / Omega0(); }

  struct Phase {
    double start;     // time the phase starts
    bool conducting;  // diode state
    double v, i;      // state at its start
  };
  // Conducting phase from (v, i): v(tau) = e^{-alpha tau}(v cos + b sin)(omega_d tau), and
  // i = -C (v' + 2 alpha v); blocking from (0, i): v = -(i/(C omega0)) sin, i cos.
  Vector Evolve(const Phase& phase, double tau) const {
    if (!phase.conducting) {
      const double w = Omega0();
      return Vector{{-phase.i / (C * w) * std::sin(w * tau), phase.i * std::cos(w * tau)}};
    }
    const double a = Alpha(), w = OmegaD();
    const double b = (-phase.i / C - a * phase.v) / w;
    const double e = std::exp(-a * tau), c = std::cos(w * tau), s = std::sin(w * tau);
    const double v = e * (phase.v * c + b * s);
    const double dv = e * ((-a * phase.v + w * b) * c + (-a * b - w * phase.v) * s);
    return Vector{{v, -C * (dv + 2.0 * a * v)}};
  }
  // The phases up to tf (the first starts at 0).
  std::vector<Phase> Phases(double tf) const {
    std::vector<Phase> phases{{0.0, true, v0, i0}};
    const double b = (-i0 / C - Alpha() * v0) / OmegaD();
    double length = std::atan2(v0, -b) / OmegaD();
    while (phases.back().start + length <= tf) {
      const Phase& last = phases.back();
      const double end = last.start + length;
      const Vector x = Evolve(last, length);
      phases.push_back({end, !last.conducting, 0.0, x[1]});  // v_C = 0 at every switch
      length = phases.back().conducting ? std::numbers::pi / OmegaD() : std::numbers::pi / Omega0();
    }
    return phases;
  }
  std::vector<double> SwitchTimes(double tf) const {
    std::vector<double> times;
    for (const Phase& phase : Phases(tf)) {
      if (phase.start > 0.0) times.push_back(phase.start);
    }
    return times;
  }
  Vector State(double t) const {
    const std::vector<Phase> phases = Phases(t);
    return Evolve(phases.back(), t - phases.back().start);
  }
  // Closed-form reference for the catalog scene (its parameters and x0).
  static Rectifier OfScene() {
    const Scene scene = MakeScene("rectifier");
    auto parameter = [&scene](const char* name) {
      return scene.parameters[static_cast<std::size_t>(scene.FindParameter(name))].value;
    };
    return {parameter("L"), parameter("C"), parameter("R"), scene.initial_state[0],
            scene.initial_state[1]};
  }
};

inline ReferenceProblem RectifierProblem() {
  const Rectifier r = Rectifier::OfScene();
  return {"rectifier", r.SwitchTimes(MakeScene("rectifier").final_time),
          [r](double t) { return r.State(t); }};
}

}  // namespace moreau::testing
