#pragma once
// Shared helpers of the hard-case tests: one outcome type for the DCS integrators and the
// per-point certificates every run is checked with (finite values, constraint violation and
// complementarity of the moving-set multipliers at every recorded point).

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <variant>

#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/ida.hpp"
#include "moreau/integrators/timestepping.hpp"
#include "moreau/model/scene.hpp"

namespace moreau::hard {

// The outcome of one run, integrator-independent.
struct Outcome {
  std::string integrator;
  bool success = false;
  std::string status;
  std::string message;
  double final_time = 0.0;
  Vector final_state;
  Trajectory trajectory;
  std::vector<Event> events;
  // The integrator's own per-element/per-step complementarity certificate (max over the run):
  // FESD max(complementarity, cross complementarity) of every element; time-stepping the
  // stage residual max |min(a, b)| of every step; IDA has none (-1).
  double certificate = -1.0;
  long steps = 0;
  double seconds = 0.0;

  std::string Describe() const {
    std::string text = integrator + ": " + status + (message.empty() ? "" : " (" + message + ")") +
                       ", t_final = " + std::to_string(final_time) + ", x_final =";
    for (Eigen::Index i = 0; i < final_state.size(); ++i) {
      text += " " + std::to_string(final_state[i]);
    }
    return text + ", " + std::to_string(steps) + " steps, " + std::to_string(events.size()) +
           " events, certificate " + std::to_string(certificate);
  }
};

inline double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The fields shared by every integrator's result, timed from `start`.
template <class Result, class Status>
Outcome CommonOutcome(const char* integrator, const Result& result, Status success, long steps,
                      std::chrono::steady_clock::time_point start) {
  Outcome outcome;
  outcome.integrator = integrator;
  outcome.success = result.status == success;
  outcome.status = ToString(result.status);
  outcome.message = result.message;
  outcome.final_time = result.final_time;
  outcome.final_state = result.final_state;
  outcome.trajectory = result.trajectory;
  outcome.events = result.events;
  outcome.steps = steps;
  outcome.seconds = Seconds(start);
  return outcome;
}

inline Outcome RunFesd(const Scene& scene, const FesdOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const FesdResult result = SimulateFesd(scene, options);
  Outcome outcome =
      CommonOutcome("fesd", result, FesdStatus::kSuccess, result.stats.num_elements, start);
  outcome.certificate =
      std::max(result.stats.max_complementarity, result.stats.max_cross_complementarity);
  return outcome;
}

inline Outcome RunTimeStepping(const Scene& scene, const TimeSteppingOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const TimeSteppingResult result = SimulateTimeStepping(scene, options);
  Outcome outcome = CommonOutcome("timestepping", result, TimeSteppingStatus::kSuccess,
                                  result.stats.num_steps, start);
  outcome.certificate = 0.0;
  for (double r : result.step_complementarity_residual) {
    outcome.certificate = std::max(outcome.certificate, r);
  }
  return outcome;
}

inline Outcome RunIda(const Scene& scene, const IdaOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const IdaResult result = SimulateIda(scene, options);
  return CommonOutcome("ida", result, IdaStatus::kSuccess, result.stats.num_steps, start);
}

// Per-point certificates of a trajectory (see CheckTrajectory).
struct PointCertificates {
  bool finite = true;
  bool time_monotone = true;
  double max_violation = 0.0;        // max over points and constraints of max(0, -c)
  double max_complementarity = 0.0;  // max |min(c, lambda)| of the moving-set pairs
  double min_multiplier = 0.0;       // min(0, min lambda)
  std::size_t points = 0;
  std::string worst;  // where the worst violation occurred
};

// Evaluates every moving set's c(x_k, t_k) at every recorded point and pairs it with the
// multiplier "<set>.lambda_<constraint>" of the trajectory's algebraic values, if recorded.
inline PointCertificates CheckTrajectory(const Scene& scene, const Trajectory& trajectory) {
  PointCertificates out;
  out.points = trajectory.size();
  const Vector p = scene.ParameterValues();
  for (std::size_t k = 0; k < trajectory.size(); ++k) {
    const double t = trajectory.t[k];
    const Vector& x = trajectory.x[k];
    if (!std::isfinite(t) || !x.allFinite()) out.finite = false;
    if (k < trajectory.algebraic.size() && !trajectory.algebraic[k].allFinite()) {
      out.finite = false;
    }
    if (k > 0 && !(t >= trajectory.t[k - 1])) out.time_monotone = false;
    if (!x.allFinite()) continue;
    for (const Effect& effect : scene.effects) {
      const auto* set = std::get_if<MovingSet>(&effect);
      if (set == nullptr) continue;
      Vector c;
      set->constraints.Evaluate(x, scene.InputValues(t), t, p, &c);
      for (Eigen::Index j = 0; j < c.size(); ++j) {
        const std::string name = set->name + ".lambda_" + set->constraint_names[std::size_t(j)];
        if (-c[j] > out.max_violation) {
          out.max_violation = -c[j];
          out.worst = name + " at t = " + std::to_string(t);
        }
        const auto& names = trajectory.algebraic_names;
        const auto it = std::find(names.begin(), names.end(), name);
        if (it == names.end() || k >= trajectory.algebraic.size()) continue;
        const auto index = static_cast<Eigen::Index>(it - names.begin());
        if (index >= trajectory.algebraic[k].size()) continue;
        const double lambda = trajectory.algebraic[k][index];
        out.min_multiplier = std::min(out.min_multiplier, lambda);
        out.max_complementarity =
            std::max(out.max_complementarity, std::fabs(std::min(c[j], lambda)));
      }
    }
  }
  return out;
}

}  // namespace moreau::hard
