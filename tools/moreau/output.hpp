#pragma once
// Files written by `moreau run`: trajectory.csv, summary.json and trajectory.png.

#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "moreau/integrators/simulate.hpp"

namespace moreau::tool {

// At most this many states are drawn in the plot (the CSV always has all of them).
inline constexpr std::size_t kMaxPlottedStates = 8;

// Header "t," then the state names, then algebraic names (multipliers) and "h" (the length
// of the step or element ending at t) where the integrator has them.
void WriteTrajectoryCsv(const Trajectory& trajectory, const std::string& path);
// relays.csv: columns t and one per relay; a row at t0 with the initial memories, one per
// jump time with the memories after it, and one at t_final (a step plot of w(t)).
void WriteRelaysCsv(const SimulationResult& report, const std::string& path);
// elements.csv: one row per finite element (integrators with elements only).
void WriteElementsCsv(const SimulationResult& report, const std::string& path);
// SettingValue and statistics as JSON (non-finite numbers as "inf", "-inf" or "nan").
nlohmann::json SettingJson(const SettingValue& value);
// The options used, name -> value, in declaration order.
nlohmann::json OptionsJson(const SimulationResult& result);
// The options of a run that differ from the integrator's declared defaults, "name = value" in
// declaration order. `implicit` holds the values the command line sets itself (FESD's
// record_stages): those count as defaults.
std::vector<std::string> ChangedOptions(const SimulationResult& result,
                                        const std::map<std::string, SettingValue>& implicit);
// "fesd (stages = 4, rtol = 1e-08; other options at their defaults)" or "fesd (all options at
// their defaults)": the summary's integrator line (every option is in summary.json).
std::string IntegratorLine(const SimulationResult& result,
                           const std::map<std::string, SettingValue>& implicit);
// The summary object: scene, integrator, options, status, message, t_final, x_final
// (state name -> value), events (t, kind, what, detail), stats, and for scenes with
// hysteresis relays "relays" (name, initial, jumps [{t, w}], final).
nlohmann::json SummaryJson(const SimulationResult& report);
void WriteSummaryJson(const SimulationResult& report, const std::string& path);
// view.json: what `moreau animate` needs to draw the run (render/view_geometry.hpp).
void WriteViewJson(const Scene& scene, const std::string& path);
// The algebraic columns a figure shows: multipliers of moving sets and complementarity pairs
// ("<effect>.lambda_<name>"), and with `internal` also the lowering's own variables (Filippov
// theta, lambda, mu; time-freezing variables).
std::vector<std::string> ShownAlgebraicNames(const Scene& scene, const Trajectory& trajectory,
                                             bool internal);
// Draws DIR/trajectory.png with gnuplot from what the scene contains (run_figure.cpp): states
// with labels and units, multipliers, active sets/modes/relay memories as bands, events in
// rows by constraint and kind, and the phase portrait of two-state scenes; figure.json holds
// the phase panel's pixel geometry. Returns the image path, or "" if gnuplot is unavailable or
// failed. With numerical_time_axis the trajectory is the numerical-time one (no events).
std::string WritePlot(const Scene& scene, const SimulationResult& report,
                      const Trajectory& trajectory, const std::string& directory,
                      bool numerical_time_axis, bool internal = false);
// Runs gnuplot on a script that writes `image`; true if the image exists afterwards.
bool RunGnuplot(const std::string& script_path, const std::string& image);

}  // namespace moreau::tool
