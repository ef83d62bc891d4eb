#include "sweep_command.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <nlohmann/json.hpp>

#include "moreau/core/error.hpp"
#include "output.hpp"
#include "progress.hpp"
#include "sweep_figures.hpp"

namespace moreau::tool {

int RunSweepCommand(const Scene& scene, const SweepCommandSettings& settings) {
  SweepSpec spec;
  for (const std::string& g : settings.grids) spec.grids.push_back(ParseSweepGrid(g));
  for (const std::string& s : settings.samples) spec.samples.push_back(ParseSweepSample(s));
  spec.num_samples = settings.num_samples;
  spec.seed = settings.seed;
  spec.num_event_times = settings.event_times;
  RequireArgument(settings.jobs >= 0, "--jobs must be >= 0 (0: all cores), got ", settings.jobs);
  spec.Validate(scene);
  const std::string dir =
      settings.out_directory.empty() ? "out/sweep/" + scene.name : settings.out_directory;

  ProgressBar bar("sweep", !settings.quiet);
  const auto start = std::chrono::steady_clock::now();
  auto runs_text = [&start](long done, long total) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    char text[96];
    std::snprintf(text, sizeof text, "%ld/%ld runs, %.3g runs/s", done, total,
                  done / std::max(seconds, 1e-9));
    return std::string(text);
  };
  const SweepResult result =
      RunSweep(scene, spec, settings.simulation, settings.jobs, {}, [&](long done, long total) {
        bar.Update(static_cast<double>(done) / std::max(total, 1L),
                   [&] { return runs_text(done, total); });
      });
  const long runs = static_cast<long>(result.rows.size());
  bar.Finish(1.0, runs_text(runs, runs));

  std::filesystem::create_directories(dir);
  WriteSweepCsv(result, dir + "/sweep.csv");
  std::map<std::string, long> by_status;
  double cpu = 0.0;
  for (const SweepRow& row : result.rows) {
    ++by_status[row.status];
    cpu += row.cpu_seconds;
  }
  nlohmann::json summary;
  summary["scene"] = result.scene;
  summary["integrator"] = result.integrator;
  summary["options"] = nlohmann::json::object();
  for (const auto& [name, value] : settings.simulation.options) {
    summary["options"][name] = SettingJson(value);
  }
  summary["grids"] = settings.grids;
  summary["samples"] = settings.samples;
  summary["num_samples"] = spec.num_samples;
  summary["seed"] = spec.seed;
  summary["runs"] = result.rows.size();
  summary["by_status"] = by_status;
  summary["threads"] = result.threads;
  summary["wall_seconds"] = result.wall_seconds;
  summary["runs_per_second"] = static_cast<double>(result.rows.size()) / result.wall_seconds;
  summary["cpu_seconds"] = cpu;
  std::ofstream(dir + "/summary.json") << std::setw(2) << summary << "\n";
  const std::vector<std::string> images =
      settings.plot ? SweepFigures(result, spec, dir) : std::vector<std::string>{};

  const bool all = by_status.size() == 1 && by_status.count("success") == 1;
  if (settings.quiet) {  // errors only
    if (!all) {
      std::fprintf(stderr, "moreau: sweep of %s: %ld of %zu runs did not succeed (%s/sweep.csv)\n",
                   result.scene.c_str(),
                   static_cast<long>(result.rows.size()) -
                       (by_status.count("success") != 0 ? by_status.at("success") : 0L),
                   result.rows.size(), dir.c_str());
    }
    return all ? 0 : 1;
  }
  std::printf("scene       %s\n", result.scene.c_str());
  std::printf("integrator  %s\n", result.integrator.c_str());
  std::printf("runs        %zu on %d threads in %.3g s (%.4g runs/s, %.3g s CPU)\n",
              result.rows.size(), result.threads, result.wall_seconds,
              static_cast<double>(result.rows.size()) / result.wall_seconds, cpu);
  for (const auto& [status, count] : by_status) {
    std::printf("  %-24s %ld\n", status.c_str(), count);
  }
  std::printf("output      %s/sweep.csv, %s/summary.json", dir.c_str(), dir.c_str());
  for (const std::string& image : images) std::printf(", %s", image.c_str());
  std::printf("\n");
  return all ? 0 : 1;
}

}  // namespace moreau::tool
