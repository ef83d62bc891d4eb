#include "moreau/integrators/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <utility>

#include "moreau/core/error.hpp"

namespace moreau {

void Trajectory::Append(double time, Vector state, Vector algebraic_values, double length) {
  t.push_back(time);
  x.push_back(std::move(state));
  algebraic.push_back(std::move(algebraic_values));
  step.push_back(length);
}

int RelaySignal::ValueAt(double t) const {
  int value = initial_value;
  for (std::size_t k = 0; k < jump_times.size() && jump_times[k] <= t; ++k) value = values[k];
  return value;
}

std::string ErrorEstimateWarning(double error_estimate, double relative_tolerance) {
  if (!(error_estimate > kErrorWarningFactor * relative_tolerance)) return "";
  std::ostringstream s;
  s.precision(3);
  s << "the estimated error of this fixed-step run, " << error_estimate
    << " relative to the solution's scale, exceeds " << kErrorWarningFactor
    << " times the tolerance " << relative_tolerance
    << ": shorten the step h, or leave h out for error-controlled steps (docs/accuracy.md)";
  return s.str();
}

double FixedStepCount(const std::vector<double>& ends, double h) {
  double count = 0.0;
  for (std::size_t k = 0; k + 1 < ends.size(); ++k) {
    const double ratio = (ends[k + 1] - ends[k]) / h;
    const double rounded = std::max(1.0, std::round(ratio));
    count += std::fabs(ratio - rounded) <= 1e-9 * rounded ? rounded : std::ceil(ratio);
  }
  return count;
}

void RequireFixedStepsWithin(const std::vector<double>& ends, double h, long max_steps) {
  RequireArgument(std::isfinite(h) && h > 0.0, "step size h must be positive and finite, got ", h);
  // A horizon that is not finite is the scene's defect, named by its validation.
  for (double t : ends) {
    if (!std::isfinite(t)) return;
  }
  const double count = FixedStepCount(ends, h);
  RequireArgument(count <= static_cast<double>(max_steps), "fixed steps h = ", h, " over [",
                  ends.front(), ", ", ends.back(), "] need ", count,
                  " steps, more than max_steps = ", max_steps,
                  ": give a larger h or max_steps, or leave h out for error-controlled steps");
}

std::vector<double> FixedStepGrid(double t0, double tf, double h) {
  RequireArgument(std::isfinite(h) && h > 0.0, "step size h must be positive and finite, got ", h);
  RequireArgument(tf > t0, "grid needs tf > t0, got t0 = ", t0, ", tf = ", tf);
  const double ratio = (tf - t0) / h;
  RequireArgument(ratio <= kMaxFixedSteps, "step size h = ", h, " gives ", ratio,
                  " fixed steps on [", t0, ", ", tf, "], more than the limit of ", kMaxFixedSteps,
                  " fixed steps per segment (raise h or shorten the horizon)");
  const double resolution =
      64.0 * std::numeric_limits<double>::epsilon() * std::max(std::fabs(t0), std::fabs(tf));
  RequireArgument(h >= resolution, "step size h = ", h, " is below the resolution of t on [", t0,
                  ", ", tf, "] (64 eps max(|t0|, |tf|) = ", resolution, ")");
  const double rounded = std::max(1.0, std::round(ratio));
  std::vector<double> grid{t0};
  if (std::fabs(ratio - rounded) <= 1e-9 * rounded) {
    const auto n = static_cast<long long>(rounded);
    for (long long k = 1; k < n; ++k)
      grid.push_back(t0 + (tf - t0) * static_cast<double>(k) / static_cast<double>(n));
  } else {
    const auto n = static_cast<long long>(std::floor(ratio));
    for (long long k = 1; k <= n; ++k) grid.push_back(t0 + h * static_cast<double>(k));
    if (grid.back() >= tf) grid.pop_back();
  }
  grid.push_back(tf);
  return grid;
}

std::vector<double> SegmentEnds(double t0, double tf, const std::vector<double>& breakpoints) {
  std::vector<double> ends{t0};
  for (double b : breakpoints) {
    if (b > ends.back() && b < tf) ends.push_back(b);
  }
  ends.push_back(tf);
  return ends;
}

std::vector<double> StretchEnds(double t0, double tf, const std::vector<double>& breakpoints,
                                const std::vector<double>& stops, std::vector<int>* control) {
  for (double stop : stops) {
    RequireArgument(std::isfinite(stop), "stop time (tstops) must be finite, got ", stop);
  }
  const std::vector<double> segments = SegmentEnds(t0, tf, breakpoints);
  std::vector<double> sorted = stops;
  std::sort(sorted.begin(), sorted.end());
  std::vector<double> ends{t0};
  if (control != nullptr) control->clear();
  std::size_t next_stop = 0;
  for (std::size_t segment = 0; segment + 1 < segments.size(); ++segment) {
    const double end = segments[segment + 1];
    for (; next_stop < sorted.size() && sorted[next_stop] < end; ++next_stop) {
      if (sorted[next_stop] <= ends.back()) continue;
      ends.push_back(sorted[next_stop]);
      if (control != nullptr) control->push_back(static_cast<int>(segment));
    }
    ends.push_back(end);
    if (control != nullptr) control->push_back(static_cast<int>(segment));
  }
  return ends;
}

}  // namespace moreau
