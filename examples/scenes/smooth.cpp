// Smooth scenes (no effects): test problems for the Radau IIA core.
#include <cmath>
#include <numbers>

#include "scenes.hpp"

namespace moreau::scenes {

Scene MakeHopf() {
  Scene scene;
  scene.name = "hopf";
  scene.description =
      "Hopf normal form: x' = mu x - omega y - x r^2, y' = omega x + mu y - y r^2 (r^2 = x^2 + "
      "y^2); exact solution r^2(t) = mu / (1 + (mu / r0^2 - 1) e^{-2 mu t}), angle omega t";
  scene.state_names = {"x", "y"};
  scene.initial_state = Vector{{0.5, 0.0}};
  scene.final_time = 2.0;
  const int mu = scene.AddParameter("mu", 1.0, "growth rate (limit cycle radius sqrt(mu))");
  const int omega = scene.AddParameter("omega", 2.0 * std::numbers::pi, "angular velocity");
  scene.dynamics = MakeSmoothFunction(
      "hopf.f", 2, [mu, omega](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        const auto r2 = x[0] * x[0] + x[1] * x[1];
        out[0] = p[mu] * x[0] - p[omega] * x[1] - x[0] * r2;
        out[1] = p[omega] * x[0] + p[mu] * x[1] - x[1] * r2;
      });
  return scene;
}

Scene MakeVanDerPol() {
  Scene scene;
  scene.name = "vanderpol";
  scene.description =
      "Van der Pol oscillator x1' = x2, x2' = mu ((1 - x1^2) x2 - x1) (stiff for "
      "large mu)";
  scene.state_names = {"x1", "x2"};
  scene.initial_state = Vector{{2.0, 0.0}};
  scene.final_time = 20.0;
  const int mu = scene.AddParameter("mu", 10.0, "stiffness parameter");
  scene.dynamics = MakeSmoothFunction(
      "vanderpol.f", 2, [mu](const auto& x, const auto&, const auto&, const auto& p, auto& out) {
        out[0] = x[1];
        out[1] = p[mu] * ((1.0 - x[0] * x[0]) * x[1] - x[0]);
      });
  return scene;
}

Scene MakeRobertson() {
  Scene scene;
  scene.name = "robertson";
  scene.description = "Robertson's stiff chemical kinetics (Hairer-Wanner II, IV.1)";
  scene.state_names = {"y1", "y2", "y3"};
  scene.initial_state = Vector{{1.0, 0.0, 0.0}};
  scene.final_time = 1e5;
  const int k1 = scene.AddParameter("k1", 0.04, "rate of y1 -> y2");
  const int k2 = scene.AddParameter("k2", 3e7, "rate of 2 y2 -> y2 + y3");
  const int k3 = scene.AddParameter("k3", 1e4, "rate of y2 + y3 -> y1 + y3");
  scene.dynamics = MakeSmoothFunction(
      "robertson.f", 3,
      [k1, k2, k3](const auto& y, const auto&, const auto&, const auto& p, auto& out) {
        const auto r1 = p[k1] * y[0];
        const auto r2 = p[k2] * y[1] * y[1];
        const auto r3 = p[k3] * y[1] * y[2];
        out[0] = -r1 + r3;
        out[1] = r1 - r2 - r3;
        out[2] = r2;
      });
  return scene;
}

Scene MakeHeat() {
  // u_t = D u_xx on (0, 1), u = 0 at both ends, N interior points, second-order differences.
  // The initial data sin(k pi x_i) is an eigenvector of the difference operator, so the
  // semi-discrete solution is exp(-D (4 / dx^2) sin^2(k pi dx / 2) t) sin(k pi x_i).
  constexpr int kPoints = kHeatPoints;
  Scene scene;
  scene.name = "heat";
  scene.description = "1-D heat equation, " + std::to_string(kPoints) +
                      " states, hand-written sparse Jacobian (large sparse test problem)";
  const double dx = 1.0 / (kPoints + 1);
  scene.initial_state.resize(kPoints);
  for (int i = 0; i < kPoints; ++i) {
    scene.state_names.push_back("u" + std::to_string(i + 1));
    scene.initial_state[i] = std::sin(kHeatMode * std::numbers::pi * (i + 1) * dx);
  }
  scene.final_time = 0.01;
  // The diffusivity is fixed (not a parameter): hand-written functions report zero
  // derivatives with respect to p, so a parameter here would have wrong sensitivities.
  const double scale = kHeatDiffusivity / (dx * dx);
  scene.dynamics = MakeSparseStateFunction(
      "heat.f", kPoints,
      [scale](const ConstVectorRef& u, const ConstVectorRef&, double, const ConstVectorRef&,
              VectorRef out) {
        const auto n = u.size();
        for (Eigen::Index i = 0; i < n; ++i) {
          const double left = i > 0 ? u[i - 1] : 0.0;
          const double right = i + 1 < n ? u[i + 1] : 0.0;
          out[i] = scale * (left - 2.0 * u[i] + right);
        }
      },
      [scale](const ConstVectorRef& u, const ConstVectorRef&, double, const ConstVectorRef&,
              SparseMatrix* jac) {
        const auto n = static_cast<int>(u.size());
        std::vector<Eigen::Triplet<double, int>> entries;
        entries.reserve(static_cast<std::size_t>(3 * n));
        for (int i = 0; i < n; ++i) {
          if (i > 0) entries.emplace_back(i, i - 1, scale);
          entries.emplace_back(i, i, -2.0 * scale);
          if (i + 1 < n) entries.emplace_back(i, i + 1, scale);
        }
        jac->resize(n, n);
        jac->setFromTriplets(entries.begin(), entries.end());
      });
  return scene;
}

}  // namespace moreau::scenes
