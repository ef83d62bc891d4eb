// Cost of the crowd scene (docs/crowd-motion.md) against its size, one run per process
// (issue 15; README "Large scenes"; scripts/bench-crowd runs the sizes and prints the table):
// time per element (per step for time-stepping), Newton iterations, events, active contacts,
// the near-active filter's working set and peak memory (the process's maximum resident set,
// which is why each configuration runs in a process of its own).
//
//   build/release/bench/crowd_scaling --agents 1000 --integrator fesd --stages 2
//
// Prints one JSON object. Times are the integrator's CPU seconds (the process's user + system
// time spent in Simulate; the scene set-up is reported separately). Every recorded state is
// certified against every pair and wall (CertifyCrowdState) and the run fails loudly if an
// overlap beyond 1e-9 or a missed contact appears, so a faster run cannot be a wrong one.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/crowd.hpp"
#include "process_usage.hpp"

namespace {

using moreau::bench::PeakResidentMegabytes;
using moreau::bench::ProcessCpuSeconds;

// Overlap allowed in the certificate: the integrators' complementarity tolerances are 1e-10
// and below; the acceptance bound for the crowd is 1e-9.
constexpr double kOverlapTolerance = 1e-9;
// A declared pair counts as an active contact at the end when its gap is below this.
constexpr double kActiveGap = 1e-8;

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"crowd_scaling: one crowd simulation, its cost and certificate as JSON"};
  int agents = 100;
  std::string integrator = "fesd";
  long stages = 2;
  double step = 0.05;
  double horizon = 0.0;
  std::string filter = "auto";
  std::string linear_solver = "auto";
  long threads = 0;
  bool progress = false;
  app.add_option("--agents", agents, "number of agents N")->check(CLI::PositiveNumber);
  app.add_option("--integrator", integrator, "fesd or timestepping")
      ->check(CLI::IsMember({"fesd", "timestepping"}));
  app.add_option("--stages", stages, "Radau IIA stages s")->check(CLI::Range(1, 6));
  app.add_option("--h", step, "step (FESD: finite-element group length)")
      ->check(CLI::PositiveNumber);
  app.add_option("--tf", horizon, "horizon; 0 keeps the scene's (4.5)");
  app.add_option("--filter", filter, "near-active constraint filter: auto, on, off");
  app.add_option("--linear-solver", linear_solver, "auto, dense, sparse or klu");
  app.add_option("--threads", threads,
                 "threads for the scene's model blocks; 0 (the integrators' default) uses every "
                 "core")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--progress", progress, "print the simulated time to stderr");
  CLI11_PARSE(app, argc, argv);

  const double setup_start = ProcessCpuSeconds();
  moreau::CrowdOptions crowd;
  crowd.agents = agents;
  if (horizon > 0.0) crowd.final_time = horizon;
  const moreau::CrowdLayout layout = moreau::MakeCrowdLayout(crowd);
  const moreau::Scene scene = moreau::MakeCrowdScene(layout);
  const double setup_seconds = ProcessCpuSeconds() - setup_start;

  moreau::SimulationSettings settings{integrator,
                                      {{"stages", stages},
                                       {"h", step},
                                       {"constraint_filter", filter},
                                       {"linear_solver", linear_solver},
                                       {"threads", threads}}};
  const double start = ProcessCpuSeconds();
  const auto wall_start = std::chrono::steady_clock::now();
  const moreau::SimulationResult result = moreau::Simulate(scene, settings, [&](double t) {
    if (progress) std::cerr << "t = " << t << "   \r" << std::flush;
  });
  const double seconds = ProcessCpuSeconds() - start;
  const double wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  if (progress) std::cerr << "\n";

  double min_gap = INFINITY;
  bool lists_sufficed = true;
  for (const moreau::Vector& q : result.trajectory.x) {
    const moreau::CrowdCertificate c = moreau::CertifyCrowdState(layout, q);
    min_gap = std::min({min_gap, c.min_pair_gap, c.min_wall_gap});
    lists_sufficed = lists_sufficed && c.ListsSufficed();
  }
  int active = 0;
  const double r = crowd.radius;
  for (const auto& [i, j] : layout.pairs) {
    const double dx = result.final_state[2 * i] - result.final_state[2 * j];
    const double dy = result.final_state[2 * i + 1] - result.final_state[2 * j + 1];
    active += std::sqrt(dx * dx + dy * dy) - 2 * r < kActiveGap;
  }
  const bool certified = min_gap >= -kOverlapTolerance && lists_sufficed;

  nlohmann::json out;
  out["agents"] = agents;
  out["states"] = 2 * agents;
  out["constraints"] = layout.pairs.size() + layout.walls.size();
  out["integrator"] = integrator;
  out["stages"] = stages;
  out["h"] = step;
  out["threads"] = threads;
  out["tf"] = scene.final_time;
  out["status"] = result.status;
  out["message"] = result.message;
  out["setup_seconds"] = setup_seconds;
  out["cpu_seconds"] = seconds;
  out["wall_seconds"] = wall_seconds;
  out["steps"] = result.num_steps;  // FESD: elements; time-stepping: steps
  out["ms_per_step"] = 1e3 * seconds / static_cast<double>(std::max(1L, result.num_steps));
  out["newton_iterations"] = result.num_iterations;
  out["events"] = result.events.size();
  out["active_contacts_at_end"] = active;
  out["min_gap"] = min_gap;
  out["lists_sufficed"] = lists_sufficed;
  out["certified"] = certified;
  out["peak_rss_mb"] = PeakResidentMegabytes();
  for (const auto& [name, value] : result.stats) {
    if (name == "max_working_pairs" || name == "num_filter_rechecks") out[name] = value;
  }
  std::cout << out.dump() << "\n";
  return result.success && certified ? 0 : 1;
}
