// The cost of FESD's adjoint gradient against one forward run (docs/sensitivities.md,
// scripts/bench-adjoint): one configuration per process, so that the peak resident memory is
// that configuration's.
//
//   build/release/bench/adjoint_cost --scene F1 --h 0.05 --mode adjoint --repeats 5
//
// Modes: `forward` (a plain run), `adjoint` (the gradient of the scalar J = sum_i x_i(T) with
// respect to x0, p and u by the reverse sweep: the run with its tape and the sweep),
// `directional` (one direction), `full` (the full matrices). Prints one JSON object with the
// median CPU seconds over the repeats (process user + system time around Simulate), the sweep's
// share, the bytes the tape kept and the process's peak resident set.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/catalog.hpp"
#include "process_usage.hpp"

namespace {

using moreau::bench::PeakResidentMegabytes;
using moreau::bench::ProcessCpuSeconds;

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"adjoint_cost: cost of one FESD configuration (forward, adjoint, ...) as JSON"};
  std::string scene_name = "F1";
  std::string mode = "forward";
  double step = 0.05;
  double horizon = 0.0;
  long stages = 3;
  int repeats = 3;
  app.add_option("--scene", scene_name, "built-in scene, e.g. F1, H1, crowd:N=1000");
  app.add_option("--mode", mode, "forward, adjoint, directional or full")
      ->check(CLI::IsMember({"forward", "adjoint", "directional", "full"}));
  app.add_option("--h", step, "FESD step")->check(CLI::PositiveNumber);
  app.add_option("--tf", horizon, "horizon (0: the scene's)");
  app.add_option("--stages", stages, "Radau IIA stages")->check(CLI::Range(1, 6));
  app.add_option("--repeats", repeats, "runs (the median is reported)")->check(CLI::PositiveNumber);
  std::vector<std::string> extra;
  app.add_option("--set", extra,
                 "another FESD option as name=value (true/false or a number), e.g. "
                 "estimate_error=false");
  CLI11_PARSE(app, argc, argv);

  moreau::Scene scene = moreau::MakeScene(scene_name);
  if (horizon > 0.0) scene.final_time = horizon;
  const int nx = scene.num_states();
  moreau::SimulationSettings settings{"fesd", {{"stages", stages}, {"h", step}}};
  for (const std::string& option : extra) {
    const std::size_t equals = option.find('=');
    if (equals == std::string::npos) {
      std::fprintf(stderr, "adjoint_cost: --set needs name=value, got '%s'\n", option.c_str());
      return 2;
    }
    const std::string name = option.substr(0, equals), value = option.substr(equals + 1);
    if (value == "true" || value == "false") {
      settings.options[name] = value == "true";
    } else {
      settings.options[name] = std::stod(value);
    }
  }
  if (mode == "adjoint") {
    settings.options["adjoint_weights"] = std::vector<double>(static_cast<std::size_t>(nx), 1.0);
  } else if (mode == "directional") {
    std::size_t segments = 1;  // control segments: breakpoints inside (t0, tf)
    for (double t : scene.ControlBreakpoints()) {
      segments += t > scene.initial_time && t < scene.final_time ? 1 : 0;
    }
    const std::size_t n_theta = static_cast<std::size_t>(nx + scene.num_parameters()) +
                                static_cast<std::size_t>(scene.num_inputs()) * segments;
    std::vector<double> direction(n_theta, 0.0);
    direction[0] = 1.0;
    settings.options["directions"] = direction;
  } else if (mode == "full") {
    settings.options["sensitivities"] = true;
  }
  std::vector<double> seconds, sweep;
  moreau::SimulationResult result;
  for (int r = 0; r < repeats; ++r) {
    const double start = ProcessCpuSeconds();
    result = moreau::Simulate(scene, settings);
    seconds.push_back(ProcessCpuSeconds() - start);
    if (!result.success) {
      std::cerr << "adjoint_cost: " << result.status << ": " << result.message << "\n";
      return 1;
    }
    if (mode == "adjoint") sweep.push_back(result.Stat("adjoint_cpu_seconds"));
  }
  nlohmann::json out;
  out["scene"] = scene_name;
  out["mode"] = mode;
  out["h"] = step;
  out["tf"] = scene.final_time;
  out["stages"] = stages;
  out["states"] = nx;
  out["repeats"] = repeats;
  out["cpu_seconds"] = Median(seconds);
  out["sweep_seconds"] = sweep.empty() ? 0.0 : Median(sweep);
  out["elements"] = result.Stat("num_elements");
  out["switches"] = result.Stat("num_switches");
  out["tape_megabytes"] = result.Stat("adjoint_memory_bytes") / (1024.0 * 1024.0);
  out["peak_megabytes"] = PeakResidentMegabytes();
  std::cout << out.dump() << "\n";
  return 0;
}
