#pragma once
// Scenes used only by tests: generic enough to exercise every derivative block.

#include <cmath>
#include <string>

#include "moreau/model/scene.hpp"

namespace moreau::testing {

// Switching surfaces for a scene with parameter k and one input u: 1 or 2 surfaces
// (2 or 4 modes), with fields depending on x, u, t and p.
inline SwitchingSurfaces Switching(int k, int surfaces) {
  SwitchingSurfaces switching;
  switching.name = "quadrants";
  switching.surface_names = {"c0", "c1"};
  switching.surface_names.resize(static_cast<std::size_t>(surfaces));
  switching.surfaces = MakeSmoothFunction(
      "c", surfaces,
      [k, surfaces](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = x[0] - 0.1 * sin(t) + p[k] * u[0] * x[1] * x[1];
        if (surfaces > 1) out[1] = x[1] + x[0] * x[0] * p[k];
      });
  const int modes = 1 << surfaces;
  for (int mode = 0; mode < modes; ++mode) {
    switching.mode_names.push_back("m" + std::to_string(mode));
    switching.modes.push_back(MakeSmoothFunction(
        "f" + std::to_string(mode), 2,
        [mode, k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
          using std::cos;
          out[0] = (mode + 1.0) * x[1] + u[0] * t;
          out[1] = -p[k] * x[0] * (mode - 1.5) + cos(x[0] * x[1]);
        }));
  }
  return switching;
}

// A time-varying disc, projected along the first state only (ePDS with E = e_1).
inline MovingSet Disc(int k) {
  MovingSet set;
  set.name = "disc";
  set.constraint_names = {"inside"};
  set.constraints = MakeSmoothFunction(
      "disc.c", 1, [k](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        using std::cos;
        out[0] = 4.0 - (x[0] - cos(t)) * (x[0] - cos(t)) - p[k] * x[1] * x[1] * x[0];
      });
  set.projection_basis = Matrix{{1.0}, {0.0}};
  return set;
}

// A two-surface Filippov scene (four modes) and a moving set with a projection subspace.
inline Scene TwoSurfaceScene() {
  Scene scene;
  scene.name = "two_surfaces";
  scene.state_names = {"a", "b"};
  scene.initial_state = Vector{{0.3, -0.2}};
  scene.final_time = 1.0;
  const int k = scene.AddParameter("k", 1.5, "coefficient");
  InputSpec input;
  input.name = "u";
  input.signal.values = {0.7};
  scene.inputs.push_back(input);
  scene.effects.push_back(Switching(k, 2));
  scene.effects.push_back(Disc(k));
  return scene;
}

// Two hysteresis relays (thresholds as parameters, inputs and modes depending on x, u, t and
// p) together with a switching surface and a moving set: the time-freezing lowering scales
// the smooth dynamics and the switching modes by the product of the relays' clock rates, and
// leaves the moving-set multiplier unscaled.
// With `speed`, a second input is the speed of time (Scene::time_scale_input).
inline Scene MixedHysteresisScene(bool speed = false) {
  Scene scene;
  scene.name = "mixed_hysteresis";
  scene.state_names = {"a", "b"};
  scene.initial_state = Vector{{0.4, -0.3}};
  scene.final_time = 1.0;
  const int k = scene.AddParameter("k", 1.3, "coefficient");
  const int low1 = scene.AddParameter("low1", -0.5, "relay 1 lower threshold");
  const int high1 = scene.AddParameter("high1", 0.8, "relay 1 upper threshold");
  const int low2 = scene.AddParameter("low2", -1.0, "relay 2 lower threshold");
  const int high2 = scene.AddParameter("high2", 0.2, "relay 2 upper threshold");
  InputSpec input;
  input.name = "u";
  input.signal.values = {0.6};
  scene.inputs.push_back(input);
  if (speed) {
    InputSpec s;
    s.name = "speed";
    s.signal.values = {1.7};
    scene.inputs.push_back(s);
    scene.time_scale_input = 1;
  }
  scene.dynamics = MakeSmoothFunction(
      "f", 2, [k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = -p[k] * x[0] + u[0] * sin(t) * x[1];
        out[1] = x[0] * x[1] - 0.3 * x[1] * x[1];
      });
  auto relay = [&](const std::string& name, int low, int high, double sign) {
    HysteresisRelay r;
    r.name = name;
    r.input = MakeSmoothFunction(
        name + ".input", 1,
        [k, sign](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
          using std::cos;
          out[0] = sign * x[0] * x[1] + p[k] * u[0] * cos(t) + x[1] * x[1];
        });
    r.lower_threshold = low;
    r.upper_threshold = high;
    r.mode_a = MakeSmoothFunction(
        name + ".A", 2,
        [k, sign](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
          out[0] = sign * u[0] * x[1] * t;
          out[1] = p[k] * x[0] * x[0];
        });
    r.mode_b = MakeSmoothFunction(
        name + ".B", 2,
        [k, sign](const auto& x, const auto& u, const auto&, const auto& p, auto& out) {
          using std::exp;
          out[0] = -sign * exp(0.2 * x[0]) * p[k];
          out[1] = u[0] * x[0] - x[1];
        });
    r.auxiliary_gain = sign > 0 ? 1.0 : 2.5;
    return r;
  };
  scene.effects.push_back(relay("relay1", low1, high1, 1.0));
  scene.effects.push_back(Switching(k, 1));
  scene.effects.push_back(Disc(k));
  scene.effects.push_back(relay("relay2", low2, high2, -1.0));
  return scene;
}

// Complementarity systems in both forms, every function depending on x, u, t and p: an
// index-1 effect with two pairs and a state-dependent P-matrix D, an index-2 effect (no D)
// with one pair, and (with `relay`) a hysteresis relay, whose time-freezing scales the index-1
// contribution by the clock rate and leaves the index-2 multiplier alone.
inline Scene ComplementarityScene(bool relay = false) {
  Scene scene;
  scene.name = relay ? "complementarity_relay" : "complementarity";
  scene.state_names = {"a", "b", "c"};
  scene.initial_state = Vector{{0.4, -0.3, 0.2}};
  scene.final_time = 1.0;
  const int k = scene.AddParameter("k", 1.3, "coefficient");
  const int low = scene.AddParameter("low", -0.5, "relay lower threshold");
  const int high = scene.AddParameter("high", 0.8, "relay upper threshold");
  InputSpec input;
  input.name = "u";
  input.signal.values = {0.6};
  scene.inputs.push_back(input);
  scene.dynamics = MakeSmoothFunction(
      "f", 3, [k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = -p[k] * x[0] + u[0] * sin(t) * x[1];
        out[1] = x[0] * x[2] - 0.3 * x[1] * x[1];
        out[2] = -x[2] + 0.5 * x[0];
      });
  Complementarity index_one;
  index_one.name = "diodes";
  index_one.pair_names = {"d1", "d2"};
  index_one.output = MakeSmoothFunction(
      "diodes.g", 2, [k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = x[0] - 0.3 * sin(t) + p[k] * u[0] * x[1] * x[1];
        out[1] = x[1] + x[0] * x[2] * p[k];
      });
  index_one.input_matrix = MakeSmoothFunction(
      "diodes.B", 6, [k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::cos;
        out[0] = 1.0 + 0.1 * x[1];
        out[1] = 0.2 * x[0];
        out[2] = -0.5 * t;
        out[3] = cos(x[2]);
        out[4] = p[k] * x[0] * x[1];
        out[5] = u[0];
      });
  index_one.feedthrough = MakeSmoothFunction(
      "diodes.D", 4, [k](const auto& x, const auto& u, const auto& t, const auto& p, auto& out) {
        using std::sin;
        out[0] = 2.0 + 0.1 * x[0] * x[0] + 0.1 * u[0];
        out[1] = 0.3 * sin(x[1]);
        out[2] = -0.2 * x[2] * t;
        out[3] = 1.5 + 0.1 * p[k] * x[1] * x[1];
      });
  scene.effects.push_back(index_one);
  Complementarity index_two;
  index_two.name = "wall";
  index_two.pair_names = {"w"};
  index_two.output = MakeSmoothFunction(
      "wall.g", 1, [k](const auto& x, const auto&, const auto& t, const auto& p, auto& out) {
        using std::cos;
        out[0] = 2.0 - x[0] * x[0] - 0.1 * p[k] * x[1] * x[2] + 0.2 * cos(t);
      });
  index_two.input_matrix = MakeSmoothFunction(
      "wall.B", 3, [k](const auto& x, const auto& u, const auto&, const auto& p, auto& out) {
        out[0] = -x[0] * p[k];
        out[1] = 0.3 * u[0];
        out[2] = x[1];
      });
  scene.effects.push_back(index_two);
  if (relay) {
    HysteresisRelay r;
    r.name = "relay";
    r.input = MakeSmoothFunction(
        "relay.input", 1,
        [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[0] = x[2]; });
    r.lower_threshold = low;
    r.upper_threshold = high;
    r.mode_a = MakeSmoothFunction(
        "relay.A", 3, [k](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
          out[2] = p[k] * x[0];
        });
    r.mode_b = MakeSmoothFunction(
        "relay.B", 3,
        [](const auto& x, const auto&, const auto&, const auto&, auto& out) { out[2] = -x[1]; });
    scene.effects.push_back(r);
  }
  return scene;
}

}  // namespace moreau::testing
