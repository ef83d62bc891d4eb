// Dense output of FESD: states at requested times from the collocation polynomial of the
// element that contains them (docs/fesd-formulation.md, section 10).
#include <algorithm>
#include <cmath>

#include "fesd_run.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {
namespace {

// Newton iterations for the element parameter theta at which the clock polynomial reaches an
// output time (the clock is affine in theta on every element: one iteration is exact up to
// round-off; the others only confirm it).
constexpr int kThetaIterations = 3;

}  // namespace

void FesdRun::PrepareOutputTimes() {
  const Scene& scene = system_.scene();
  const double t0 = scene.initial_time, tf = scene.final_time;
  // With a speed of time the horizon is in numerical time and the physical end is not known.
  const bool physical_horizon = scene.time_scale_input < 0;
  output_times_.clear();
  next_output_ = 0;
  for (double t : options_.output_times) {
    RequireArgument(t >= t0 && (!physical_horizon || t <= tf), "output time ", t,
                    " is outside [t0, tf] = [", t0, ", ", tf, "]");
    if (t > t0) output_times_.push_back(t);
  }
  if (options_.output_step > 0.0) {
    const double count = std::floor((tf - t0) / options_.output_step * (1.0 + 1e-12));
    RequireArgument(count <= kMaxFixedSteps, "output step ", options_.output_step, " gives ", count,
                    " output times on [", t0, ", ", tf, "], more than ", kMaxFixedSteps);
    for (double k = 1; k <= count; ++k) {
      output_times_.push_back(std::min(tf, t0 + k * options_.output_step));
    }
  }
  std::sort(output_times_.begin(), output_times_.end());
  output_times_.erase(std::unique(output_times_.begin(), output_times_.end()), output_times_.end());
  dense_output_ = !options_.output_times.empty() || options_.output_step > 0.0;
  if (dense_output_) {
    // One point per output time (and t0): appended per element without regrowth.
    Trajectory& out = result_.trajectory;
    const std::size_t points = out.size() + output_times_.size() + 1;
    out.t.reserve(points);
    out.x.reserve(points);
    out.algebraic.reserve(points);
    out.step.reserve(points);
  }
}

void FesdRun::DenseOutput(const ElementPolynomial& element) {
  if (!dense_output_ || element.frozen || next_output_ >= output_times_.size()) return;
  const int clock = system_.clock_index();
  const double start = element.y0[clock];
  const double end = start + element.increments(clock, s_ - 1);
  if (!(end > start)) return;  // physical time frozen: no output time inside
  // The last element of a run ends on tf up to the Newton tolerance (time-freezing: the
  // clock lands on it within kClockTolerance).
  const double slack = kClockTolerance * std::max(1.0, std::fabs(end));
  while (next_output_ < output_times_.size() && output_times_[next_output_] <= end + slack) {
    const double t = output_times_[next_output_++];
    // theta with clock(theta) = t: Newton on the clock row of the collocation polynomial.
    double theta = std::clamp((t - start) / (end - start), 0.0, 1.0);
    for (int k = 0; k < kThetaIterations; ++k) {
      tableau_.InterpolationWeights(theta, &output_weights_);
      tableau_.InterpolationDerivativeWeights(theta, &output_slope_weights_);
      const double value = start + element.increments.row(clock).dot(output_weights_);
      const double slope = element.increments.row(clock).dot(output_slope_weights_);
      if (!(slope > 0.0)) break;
      theta = std::clamp(theta - (value - t) / slope, 0.0, 1.0);
    }
    tableau_.InterpolationWeights(theta, &output_weights_);
    // y0 + (Z w), with the product formed first as before (the same rounding).
    output_state_.noalias() = element.increments * output_weights_;
    output_state_ += element.y0;
    const Vector& y = output_state_;
    Vector z;
    if (nz_ > 0) {
      // Consistent algebraic values at the interpolated state: continuous variables from the
      // state, jump variables from the velocity-level problem with the element's statuses.
      Eigen::Index nearest = 0;
      (tableau_.c.array() - theta).abs().minCoeff(&nearest);
      z = element.algebraic.col(nearest);
      const std::vector<bool>& continuous = system_.continuous_algebraic();
      if (std::all_of(continuous.begin(), continuous.end(), [](bool c) { return c; })) {
        // Every algebraic variable is a function of the state (index-1 complementarity, as
        // the circuits' diodes): ConsistentGuess takes nothing from the velocity level, whose
        // solve (most of a circuit's dense output) is skipped.
        z = ConsistentGuess(y, z);
      } else {
        Vector v;
        if (system_.SolveVelocityLevel(y, element.a_zero, z, &v)) z = ConsistentGuess(y, v);
      }
    }
    result_.trajectory.Append(t, y.head(nx_), TrajectoryAlgebraic(z), element.h);
  }
}

}  // namespace moreau::internal
