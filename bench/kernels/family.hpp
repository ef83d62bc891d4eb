#pragma once
// Scalable problems for the per-step kernel benchmarks (bench/kernels/): the sizes vary, the
// structure is that of the report's scenes.

#include <cmath>
#include <string>

#include "moreau/model/scene.hpp"

namespace moreau::bench {

// n play operators in a ring: x in R^n, x_i' = k (x_{i+1} - x_i) (n = 1 has no coupling),
// swept by the moving intervals C_i(t) = [sin(t + i) - 1/2, sin(t + i) + 1/2] (2n
// constraints, the lower and upper bound of every coordinate, as in S2). Lowered in gradient
// form: y = (x, clock), z = lambda (2n), 2n complementarity pairs.
inline Scene MovingIntervals(int n) {
  Scene scene;
  scene.name = "moving_intervals_" + std::to_string(n);
  for (int i = 0; i < n; ++i) scene.state_names.push_back("x" + std::to_string(i));
  scene.initial_state = Vector::Zero(n);
  for (int i = 0; i < n; ++i) scene.initial_state[i] = std::sin(static_cast<double>(i));
  scene.final_time = 1.0;
  const int k = scene.AddParameter("k", 0.5, "coupling rate");
  scene.dynamics = MakeSmoothFunction(
      "ring.f", n, [n, k](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        for (int i = 0; i < n; ++i) out[i] = p[k] * (x[(i + 1) % n] - x[i]);
      });
  MovingSet set;
  set.name = "intervals";
  for (int i = 0; i < n; ++i) {
    set.constraint_names.push_back("lower" + std::to_string(i));
    set.constraint_names.push_back("upper" + std::to_string(i));
  }
  set.constraints = MakeSmoothFunction(
      "intervals.c", 2 * n, [n](const auto& x, const auto&, const auto& t, const auto&, auto& out) {
        using std::sin;
        for (int i = 0; i < n; ++i) {
          const auto center = sin(t + static_cast<double>(i));
          out[2 * i] = x[i] - (center - 0.5);
          out[2 * i + 1] = (center + 0.5) - x[i];
        }
      });
  scene.effects.push_back(set);
  return scene;
}

}  // namespace moreau::bench
