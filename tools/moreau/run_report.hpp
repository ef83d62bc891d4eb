#pragma once
// The command-line tool's integrator-independent view of a run, and the adapters that fill
// it from each integrator's own Options/Result types.

#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "moreau/integrators/simulation.hpp"
#include "moreau/model/scene.hpp"

namespace moreau::tool {

// Command-line settings shared by all integrators; `given` lists the options the user set
// explicitly, so that an option the chosen integrator does not use is reported as an error.
struct RunSettings {
  std::string integrator = "auto";
  int stages = 3;
  bool stages_given = false;
  double step_size = 0.01;
  bool step_size_given = false;
  bool adaptive = false;
  double relative_tolerance = 1e-6;
  double absolute_tolerance = 1e-8;
  int finite_elements = 2;
  std::string switching_form = "stewart";
  std::string linear_solver = "auto";
  bool numerical_time = false;  // time-freezing scenes: trajectory in numerical time
  // alpha-method DAI stepper (--rho, --errtol, --rank-tol, --max-retries, --objective).
  double rho = 0.5;
  double error_tolerance = std::numeric_limits<double>::infinity();
  double rank_tolerance = 1e-2;
  int max_retries = 5;
  std::string objective = "reference";
  std::set<std::string> given;
};

struct RunReport {
  std::string scene;
  std::string integrator;
  nlohmann::json options;
  std::string status;
  bool success = false;
  std::string message;
  double final_time = 0.0;
  std::vector<std::string> state_names;  // the scene's states (the entries of final_state)
  Vector final_state;
  std::vector<Event> events;
  nlohmann::json stats;
  std::string stats_summary;
  long num_steps = 0;
  long num_newton_iterations = 0;
  double cpu_seconds = 0.0;
  Trajectory trajectory;
  Trajectory stage_trajectory;  // written to stages.csv when not empty
  // Time-freezing scenes (hysteresis relays): the numerical-time trajectory (numerical.csv)
  // and each relay's memory w(t) in physical time (relays.csv, plotted under the states).
  Trajectory numerical_trajectory;
  std::vector<RelaySignal> relays;
  bool numerical_time_axis = false;  // `trajectory` is the numerical-time one
  // Per-element table (element.csv): column names and rows, when the integrator has elements.
  std::vector<std::string> element_columns;
  std::vector<std::vector<double>> element_rows;
};

// The integrator that `--integrator auto` picks for a scene.
std::string AutomaticIntegrator(const Scene& scene);

// Names of the integrators `moreau run --integrator` accepts, with one-line descriptions.
const std::vector<std::pair<std::string, std::string>>& IntegratorNames();

// Runs `scene` with the integrator named in `settings`. Throws std::invalid_argument for an
// unknown integrator, an option it does not use, or an effect it does not support.
RunReport RunScene(const Scene& scene, const RunSettings& settings,
                   const ProgressCallback& progress);

}  // namespace moreau::tool
