// The error of a run against its scene's answer, CPU timing and the per-series summary.
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <random>
#include <sstream>

#include "moreau/core/clock.hpp"
#include "report.hpp"

namespace moreau::report {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Events closer than this (relative to 1 + |t|) are one instant: several pairs switching
// together (e.g. a mode switch and the start of a slide) are reported as separate events with
// the same time; integrators give them bitwise equal times, this only absorbs round-off.
constexpr double kSameInstant = 1e-12;

// Sorted distinct times of the events, ambiguous events (a documented choice among
// continuations, not a switch) left out.
std::vector<double> DistinctSwitchTimes(const std::vector<Event>& events) {
  std::vector<double> times;
  for (const Event& event : events) {
    if (event.kind != EventKind::kAmbiguous) times.push_back(event.t);
  }
  std::sort(times.begin(), times.end());
  std::vector<double> distinct;
  for (double t : times) {
    if (distinct.empty() || t - distinct.back() > kSameInstant * (1.0 + std::fabs(t))) {
      distinct.push_back(t);
    }
  }
  return distinct;
}

// Largest distance from a point of one set to the nearest point of the other (Hausdorff
// distance): a missed switch and a spurious event both count, duplicates do not.
double Hausdorff(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.empty() && b.empty()) return 0.0;
  if (a.empty() || b.empty()) return kInfinity;
  auto one_sided = [](const std::vector<double>& from, const std::vector<double>& to) {
    double worst = 0.0;
    for (double x : from) {
      double nearest = kInfinity;
      for (double y : to) nearest = std::min(nearest, std::fabs(x - y));
      worst = std::max(worst, nearest);
    }
    return worst;
  };
  return std::max(one_sided(a, b), one_sided(b, a));
}

// Seed of the shuffled order of TimeInterleaved's rounds (any fixed value).
constexpr std::mt19937::result_type kShuffleSeed = 16;

double Median(std::vector<double> values) {
  if (values.empty()) return kNaN;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

// Accepted band around a theoretical order (the tests' kOrderSlack).
constexpr double kOrderSlack = 0.3;
// "About 1" for the time-stepping baseline (the band of tests/integrators/timestepping_test).
constexpr double kFirstOrderLow = 0.8, kFirstOrderHigh = 1.3;

std::string Band(double low, double high) {
  std::ostringstream text;
  text << std::fixed << std::setprecision(1) << "[" << low << ", " << high << "]";
  return text.str();
}

ExpectedOrder Expect(const Method& method, const SceneCase& scene) {
  auto around = [](double order, const std::string& text) {
    const double low = order - kOrderSlack, high = order + kOrderSlack;
    return ExpectedOrder{order, low, high, text + " " + Band(low, high)};
  };
  const int radau = 2 * method.stages - 1;
  switch (method.theory) {
    case OrderTheory::kRadau:
      return around(radau, "2s-1 = " + std::to_string(radau));
    case OrderTheory::kFirstOrderAcrossSwitches:
      if (scene.switch_times.empty()) {
        return around(radau, "no switches: 2s-1 = " + std::to_string(radau));
      }
      if (scene.continuous_at_switches) {
        const int capped = std::min(radau, 2);
        return around(capped, "kinks only: min(2s-1, 2) = " + std::to_string(capped));
      }
      return {1.0, kFirstOrderLow, kFirstOrderHigh,
              "about 1 " + Band(kFirstOrderLow, kFirstOrderHigh)};
    case OrderTheory::kSecondOrder:
      return around(2.0, "2 (state)");
    case OrderTheory::kNone:
      break;
  }
  return {kNaN, kNaN, kNaN, "—"};
}

// Fit of one error component over the successful points.
OrderFit FitComponent(const Series& series, double Errors::*component) {
  std::vector<double> parameters, errors;
  for (const Measurement& point : series.points) {
    if (!InFitRange(series, point)) continue;
    parameters.push_back(point.parameter);
    errors.push_back(point.errors.*component);
  }
  return FitOrder(parameters, errors, series.scene->floor);
}

}  // namespace

bool InFitRange(const Series& series, const Measurement& point) {
  return point.output.success &&
         (series.method->tolerance_driven || point.parameter <= series.scene->fit_max_step);
}

Errors MeasureErrors(const SceneCase& scene, const RunOutput& output) {
  Errors errors;
  std::vector<double> times = DistinctSwitchTimes(output.events);
  errors.events_found = static_cast<int>(times.size());
  // A switch exactly at tf (S2: the lower bound arrives at T = 4 pi) is left out of the
  // switch-time error, together with events reported at tf: a fixed-grid method ends on tf
  // whatever it does, so reporting that contact or not is a tie at the last grid point (the
  // time-stepping baseline reports it depending on round-off), not an accuracy; the state
  // error at T covers it.
  std::vector<double> exact = scene.switch_times;
  const double tf = scene.scene.final_time;
  auto at_tf = [tf](double t) { return std::fabs(t - tf) <= kSameInstant * (1.0 + std::fabs(tf)); };
  if (!exact.empty() && at_tf(exact.back())) {
    exact.pop_back();
    std::erase_if(times, at_tf);
  }
  if (!output.success) {
    errors.state = errors.switch_time = errors.algebraic = errors.total = kNaN;
    return errors;
  }
  errors.state = (output.final_state - scene.final_state).lpNorm<Eigen::Infinity>();
  errors.switch_time = scene.switch_times.empty() ? kNaN : Hausdorff(times, exact);
  errors.algebraic =
      scene.final_algebraic_inputs.size() > 0 &&
              output.final_inputs.size() == scene.final_algebraic_inputs.size()
          ? (output.final_inputs - scene.final_algebraic_inputs).lpNorm<Eigen::Infinity>()
          : kNaN;
  errors.total =
      std::isnan(errors.switch_time) ? errors.state : std::max(errors.state, errors.switch_time);
  return errors;
}

void TimeInterleaved(const SceneCase& scene, const std::vector<Measurement*>& points,
                     const TimingOptions& options) {
  // Per point: the timed runs so far and their sum; only successful first runs are timed.
  struct Pending {
    Measurement* point;
    std::vector<double> seconds;
    double total = 0.0;
  };
  std::vector<Pending> pending;
  for (Measurement* point : points) {
    point->timing = Timing{};
    if (point->output.success) {
      pending.push_back({point, {}, 0.0});
    } else {  // a failed run is reported, not timed
      point->timing.median_seconds = point->timing.min_seconds = kNaN;
    }
  }
  auto needs_more = [&options](const Pending& p) {
    const int repeats = static_cast<int>(p.seconds.size());
    return repeats < options.max_repeats &&
           (repeats < options.min_repeats || p.total < options.min_total_seconds);
  };
  // A fixed seed: the order is shuffled against position effects (a point always following
  // the same neighbour), not to be random; two runs of the report time in the same order.
  std::mt19937 shuffle_engine(kShuffleSeed);
  std::vector<Pending*> round;
  for (;;) {
    round.clear();
    for (Pending& p : pending) {
      if (needs_more(p)) round.push_back(&p);
    }
    if (round.empty()) break;
    std::shuffle(round.begin(), round.end(), shuffle_engine);
    for (Pending* p : round) {
      Measurement& point = *p->point;
      const double start = ThreadCpuSeconds();
      const RunOutput repeat = point.method->run(scene.scene, point.parameter);
      const double elapsed = ThreadCpuSeconds() - start;
      p->seconds.push_back(elapsed);
      p->total += elapsed;
      if (repeat.final_state.size() != point.output.final_state.size() ||
          (repeat.final_state.array() != point.output.final_state.array()).any()) {
        point.timing.deterministic = false;
      }
    }
  }
  for (Pending& p : pending) {
    Timing& timing = p.point->timing;
    timing.repeats = static_cast<int>(p.seconds.size());
    timing.median_seconds = Median(p.seconds);
    timing.min_seconds = *std::min_element(p.seconds.begin(), p.seconds.end());
  }
}

void Summarize(Series* series) {
  series->expected = Expect(*series->method, *series->scene);
  series->fit = FitComponent(*series, &Errors::total);
  series->state_fit = FitComponent(*series, &Errors::state);
  series->switch_fit = FitComponent(*series, &Errors::switch_time);
  series->algebraic_fit = FitComponent(*series, &Errors::algebraic);
  // Points in order of increasing work: the grids run from coarse to fine (or loose to
  // tight tolerances). The time to reach a target is interpolated in log-log between the
  // last point above it and the first point at or below it.
  std::vector<const Measurement*> points;
  std::vector<double> iterations_per_step;
  for (const Measurement& point : series->points) {
    if (!point.output.success || !std::isfinite(point.errors.total)) continue;
    points.push_back(&point);
    if (point.output.num_steps > 0) {
      iterations_per_step.push_back(static_cast<double>(point.output.num_iterations) /
                                    static_cast<double>(point.output.num_steps));
    }
  }
  series->newton_per_step = Median(iterations_per_step);
  series->time_to_target.assign(kTargetErrors.size(), kNaN);
  series->reached_at_first.assign(kTargetErrors.size(), false);
  for (std::size_t k = 0; k < kTargetErrors.size(); ++k) {
    const double target = kTargetErrors[k];
    for (std::size_t j = 0; j < points.size(); ++j) {
      const double error = points[j]->errors.total;
      if (error > target) continue;
      const double time = points[j]->timing.median_seconds;
      if (j == 0) {
        series->time_to_target[k] = time;
        series->reached_at_first[k] = true;
        break;
      }
      const double previous_error = points[j - 1]->errors.total;
      const double previous_time = points[j - 1]->timing.median_seconds;
      if (error <= 0.0) {  // exact to the last bit: no logarithm, take the measured point
        series->time_to_target[k] = time;
        break;
      }
      const double fraction = (std::log(target) - std::log(previous_error)) /
                              (std::log(error) - std::log(previous_error));
      series->time_to_target[k] =
          std::exp(std::log(previous_time) + fraction * (std::log(time) - std::log(previous_time)));
      break;
    }
  }
}

}  // namespace moreau::report
