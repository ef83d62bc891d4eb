#pragma once
// The accuracy-vs-time report (bench/report/, program `work_precision`, command
// `scripts/report`): every benchmark scene with every integrator that accepts it, over a grid
// of step sizes (or tolerances), errors against the closed form or an IDA reference, CPU time
// as the median of repeated runs (interleaved over the points of a scene); CSV, gnuplot
// images, a markdown table and the README section.
//
// Layers of this program, one file each:
//   cases.cpp    the scenes, their known answers, floors and grids
//   methods.cpp  the integrator settings of each method (run through moreau::Simulate)
//   measure.cpp  the error of a run against its scene's answer (one place), CPU timing, fits
//   output.cpp   CSV, gnuplot images, markdown table, README section

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "moreau/core/convergence.hpp"
#include "moreau/core/types.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/model/events.hpp"
#include "moreau/model/scene.hpp"

namespace moreau::report {

// What one run produced, whatever the integrator: the library's common result.
using RunOutput = SimulationResult;

// What theory predicts for the error at T and the switch times of a method.
enum class OrderTheory {
  kRadau,                     // 2s - 1 (Radau IIA; FESD also across switches)
  kFirstOrderAcrossSwitches,  // about 1 with switches, 2s - 1 without (time-stepping)
  kSecondOrder,               // 2 in the state (alpha-method)
  kNone,                      // tolerance-driven (IDA)
};

// One integrator configuration, swept over one parameter: the step size h (fixed-step
// methods) or the relative tolerance (IDA).
struct Method {
  std::string integrator;  // "fesd", "timestepping", "ida", "radau", "alpha"
  int stages = 0;          // Radau IIA stages; 0 where not applicable
  std::string label;       // e.g. "FESD s=3"
  bool tolerance_driven = false;
  OrderTheory theory = OrderTheory::kNone;
  std::string step_unit;       // what RunOutput::num_steps counts ("element", "step")
  std::string iteration_unit;  // what RunOutput::num_iterations counts ("Newton", "SQP")
  std::function<RunOutput(const Scene&, double parameter)> run;
};

// All methods of the report, in table order.
std::vector<Method> Methods();

// A benchmark scene with its known answer.
struct SceneCase {
  std::string name;   // catalog name
  std::string title;  // e.g. "F1: oscillator with a switch at the unit circle"
  Scene scene;
  std::string answer_source;  // "closed form"
  // Error of ComputeReference (IDA at rtol 1e-12) against the answer, NaN where IDA refuses
  // the scene: how far the library's reference facility is from the closed form.
  double reference_error = 0.0;
  Vector final_state;  // x(T)
  // Every switch in (t0, tf], in order; empty where the scene has none (then no switch-time
  // error is measured).
  std::vector<double> switch_times;
  Vector final_algebraic_inputs;  // u(T) of DAI scenes (empty otherwise)
  // Errors at or below this are excluded from order fits (FitOrder's floor), with the reason.
  double floor = 0.0;
  std::string floor_reason;
  // True where the right-hand side stays continuous across switches (index-1 complementarity:
  // only its derivative jumps). Time-stepping then loses O(h^2) per switch instead of O(h):
  // its expected order is min(2s - 1, 2) rather than about 1 (docs/complementarity.md).
  bool continuous_at_switches = false;
  // Order fits use only step sizes up to this (the asymptotic range), with the reason;
  // tolerance-driven methods are not restricted.
  double fit_max_step = std::numeric_limits<double>::infinity();
  std::string fit_max_step_reason;
  // The parameter grid for a method on this scene (step sizes, coarse to fine, or
  // tolerances, loose to tight).
  std::function<std::vector<double>(const Method&)> grid;
};

// The scenes of the report, in table order, restricted to `names` (all if empty). Throws
// std::invalid_argument naming an unknown scene. Reference solutions are computed here.
std::vector<SceneCase> SceneCases(const std::vector<std::string>& names);
// Names of all scenes of the report.
std::vector<std::string> SceneCaseNames();

// Errors of one run against its scene's answer (infinity norms; NaN where not measured).
struct Errors {
  double state = 0.0;        // |x(T) - x*(T)|
  double switch_time = 0.0;  // Hausdorff distance between reported and exact switch times
  double algebraic = 0.0;    // |u(T) - u*(T)| (DAI scenes)
  double total = 0.0;        // max(state, switch_time): the error of the tables and plots
  int events_found = 0;      // distinct non-ambiguous event times reported
};
Errors MeasureErrors(const SceneCase& scene, const RunOutput& output);

// CPU time of repeated runs (thread CPU time of the calling thread).
// Defaults: the whole report measures in about one and a half minutes on a shared two-core
// machine (most runs take 0.1 to 30 ms), and a median of at least five runs is robust to the
// occasional preempted run.
struct TimingOptions {
  int min_repeats = 5;             // timed runs per point at least
  int max_repeats = 51;            // and at most
  double min_total_seconds = 0.5;  // keep repeating (up to max_repeats) until this much
};
struct Timing {
  double median_seconds = 0.0;
  double min_seconds = 0.0;
  int repeats = 0;
  bool deterministic = true;  // every repeat gave bitwise the same final state
};

// One measured point.
struct Measurement {
  std::string scene;
  const Method* method = nullptr;
  double parameter = 0.0;
  RunOutput output;
  Errors errors;
  Timing timing;
};

// The expected order of a method on a scene and the band the table accepts (NaN: none).
struct ExpectedOrder {
  double order = 0.0, low = 0.0, high = 0.0;
  std::string text;  // as printed in the table
};

// Times the points of one scene (each already run once untimed, its output in
// Measurement::output), interleaved: in rounds, each of which runs every point still short of
// its repeats (`options`) once, timed, in a shuffled order (fixed seed), until none is; then
// the median per point. A burst of machine load thus spreads over the points of every method
// of the scene instead of landing on the block of one of them. Points whose first run failed
// are not timed (NaN). Sets Measurement::timing, including the determinism check against
// the first run.
void TimeInterleaved(const SceneCase& scene, const std::vector<Measurement*>& points,
                     const TimingOptions& options);

// Everything known about one (scene, method) pair.
struct Series {
  const SceneCase* scene = nullptr;
  const Method* method = nullptr;
  std::string refused;  // the integrator's reason if it refused the scene (then no points)
  std::vector<Measurement> points;
  ExpectedOrder expected;
  OrderFit fit;  // of the total error over parameter, points above the scene's floor
  OrderFit state_fit, switch_fit, algebraic_fit;
  // CPU seconds to reach each of kTargetErrors (log-log interpolation), NaN if not reached;
  // reached_at_first: already reached at the cheapest point (the value is then that point's
  // time, an upper bound).
  std::vector<double> time_to_target;
  std::vector<bool> reached_at_first;
  double newton_per_step = 0.0;  // median over the successful points
};
inline const std::vector<double> kTargetErrors = {1e-4, 1e-6, 1e-8, 1e-10};
// True if the point is a successful run in the scene's asymptotic range (SceneCase::
// fit_max_step); the order fits use these points with errors above the floor.
bool InFitRange(const Series& series, const Measurement& point);
// Sets the expected order, fits orders, interpolates the times to the target errors and the
// iterations per step.
void Summarize(Series* series);

struct ReportInfo {
  double wall_seconds = 0.0;
  std::string revision;  // e.g. the git commit the report was generated from
  TimingOptions timing;
  long runs = 0;  // simulations, warm-ups and repeats included
};

// Writes measurements.csv, the images (<scene>.png) and report.md into `directory`; gnuplot
// inputs go to `directory`/gnuplot. Returns the markdown (image links relative to
// `link_base`). Throws std::runtime_error if a file cannot be written or gnuplot fails.
std::string WriteReport(const std::vector<Series>& series, const std::vector<SceneCase>& scenes,
                        const ReportInfo& info, const std::string& directory,
                        const std::string& link_base);
// Replaces the text between the marker lines kReadmeBegin and kReadmeEnd of the file at
// `readme` by `section`. CheckReadme verifies beforehand that it can: it throws
// std::invalid_argument if the file cannot be read or lacks the markers.
inline constexpr const char* kReadmeBegin = "<!-- work-precision report: begin -->";
inline constexpr const char* kReadmeEnd = "<!-- work-precision report: end -->";
void CheckReadme(const std::string& readme);
void UpdateReadme(const std::string& readme, const std::string& section);

}  // namespace moreau::report
