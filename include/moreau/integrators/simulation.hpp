#pragma once
/// @file
/// Output types shared by all integrators: the recorded trajectory, switch events and the
/// progress callback, plus the step grids integrators use between control breakpoints.

#include <functional>
#include <string>
#include <vector>

#include "moreau/core/types.hpp"
#include "moreau/model/events.hpp"

namespace moreau {

/// A recorded trajectory: scene states (and, where the integrator has them, algebraic
/// unknowns such as multipliers and the length of the element or step ending at t).
struct Trajectory {
  std::vector<std::string> state_names;      ///< the scene's states
  std::vector<std::string> algebraic_names;  ///< multipliers etc. (may be empty)
  /// The recorded times, ascending.
  std::vector<double> t;
  std::vector<Vector> x;          ///< scene states at t
  std::vector<Vector> algebraic;  ///< algebraic values at t (empty vectors if none)
  std::vector<double> step;       ///< length of the step/element ending at t (0 at t0)

  /// Number of recorded points.
  std::size_t size() const { return t.size(); }
  /// Appends one point (the vectors moved in: pass temporaries or std::move to avoid copies).
  void Append(double time, Vector state, Vector algebraic_values, double length);
};

/// The memory w(t) of a hysteresis relay in physical time, a piecewise-constant signal:
/// initial_value on [t0, jump_times[0]), values[k] on [jump_times[k], jump_times[k + 1]).
/// A relay whose initial memory is inconsistent with its input jumps at t0.
struct RelaySignal {
  /// The relay's name.
  std::string relay;
  /// The memory at t0 (0 or 1).
  int initial_value = 0;
  /// The times of the memory's jumps, ascending.
  std::vector<double> jump_times;
  std::vector<int> values;  ///< the value after each jump

  /// w(t) (right-continuous: the new value at a jump time).
  int ValueAt(double t) const;
  /// The value after the last jump.
  int FinalValue() const { return values.empty() ? initial_value : values.back(); }
};

/// Called by integrators with the current time during long runs (may be empty).
using ProgressCallback = std::function<void(double t)>;

/// The default relative tolerance of the error-controlled integrators (FESD, smooth Radau
/// IIA) when the user gives no step: chosen so that every built-in scene and example file
/// meets 1e-5 relative accuracy with no options (docs/accuracy.md, where the measurement is;
/// tests/integrators/default_accuracy_test.cpp checks it).
inline constexpr double kDefaultRelativeTolerance = 1e-6;

/// A run's estimated error (FesdStats::error_estimate, RadauStats::error_estimate) above this
/// multiple of its relative tolerance makes a warning (fixed steps, whose error nothing
/// controls; docs/accuracy.md).
inline constexpr double kErrorWarningFactor = 10.0;

/// The warning for an estimated error above kErrorWarningFactor times rtol (empty if it is
/// not): the same sentence from every integrator.
std::string ErrorEstimateWarning(double error_estimate, double relative_tolerance);

/// Fixed grids: the number of steps of FixedStepGrid over the segments between `ends`.
double FixedStepCount(const std::vector<double>& ends, double h);
/// Throws std::invalid_argument, before any work, if a fixed step h over the segments between
/// `ends` needs more than max_steps steps (naming both and the ways out).
void RequireFixedStepsWithin(const std::vector<double>& ends, double h, long max_steps);

/// Most steps a fixed-step grid may have on one segment (FixedStepGrid stores every point:
/// 8e8 bytes at this limit).
inline constexpr double kMaxFixedSteps = 1e8;

/// Breakpoints of a fixed-step grid on [t0, tf]: uniform steps of (tf - t0)/N when h divides
/// the interval up to round-off (|(tf - t0)/h - N| <= 1e-9 N), otherwise steps of h and one
/// shorter last step. Returns the grid points t0 < t1 < ... < tN = tf. Throws
/// std::invalid_argument for h not positive and finite, tf <= t0, more than kMaxFixedSteps
/// steps, or h below the resolution of t on [t0, tf] (h < 64 eps max(|t0|, |tf|), where
/// consecutive grid points could coincide in floating point).
std::vector<double> FixedStepGrid(double t0, double tf, double h);

/// Splits [t0, tf] at the given breakpoints (sorted, inside (t0, tf)): returns the segment
/// end points t0 < b1 < ... < tf.
std::vector<double> SegmentEnds(double t0, double tf, const std::vector<double>& breakpoints);

/// Splits [t0, tf] at the control breakpoints (sorted) and at the user's stop times (any order;
/// those outside (t0, tf) are ignored): the end points t0 < e1 < ... < tf of the stretches an
/// integrator steps through without crossing. *control (if not null) receives, per stretch,
/// the index of the control segment (SegmentEnds(t0, tf, breakpoints)) it lies in. Throws
/// std::invalid_argument for a stop time that is not finite.
std::vector<double> StretchEnds(double t0, double tf, const std::vector<double>& breakpoints,
                                const std::vector<double>& stops, std::vector<int>* control);

}  // namespace moreau
