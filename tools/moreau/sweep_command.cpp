#include "sweep_command.hpp"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>

#include "moreau/core/error.hpp"
#include "output.hpp"
#include "sweep_figures.hpp"

namespace moreau::tool {
namespace {

// "[sweep] 1234/10000 runs (12.3%), 456 runs/s, ETA 19 s" on stderr: in place on a terminal
// (every 0.2 s), a line every 5 s otherwise; nothing during the first second.
class SweepProgressBar {
 public:
  explicit SweepProgressBar(bool enabled)
      : enabled_(enabled), tty_(isatty(STDERR_FILENO) != 0), start_(Clock::now()), last_(start_) {}
  void Update(long done, long total) {
    if (!enabled_) return;
    std::lock_guard<std::mutex> lock(mutex_);
    const auto now = Clock::now();
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const double since = std::chrono::duration<double>(now - last_).count();
    if (done < total && (elapsed < 1.0 || since < (tty_ ? 0.2 : 5.0))) return;
    if (done == total && !printed_) return;  // short sweeps print nothing
    last_ = now;
    const double rate = done / std::max(elapsed, 1e-9);
    const double eta = (total - done) / std::max(rate, 1e-9);
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(kWidth * done / std::max(total, 1L));
    std::fprintf(stderr, "%s[sweep] [%s%s] %ld/%ld runs (%5.1f%%), %.3g runs/s, ETA %.0f s%s",
                 tty_ ? "\r" : "", std::string(static_cast<std::size_t>(filled), '#').c_str(),
                 std::string(static_cast<std::size_t>(kWidth - filled), '.').c_str(), done, total,
                 100.0 * done / std::max(total, 1L), rate, eta, tty_ ? "   " : "\n");
    printed_ = true;
    if (done == total && tty_) std::fprintf(stderr, "\n");
  }

 private:
  using Clock = std::chrono::steady_clock;
  bool enabled_, tty_, printed_ = false;
  Clock::time_point start_, last_;
  std::mutex mutex_;
};

}  // namespace

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

  SweepProgressBar bar(!settings.quiet);
  const SweepResult result = RunSweep(scene, spec, settings.simulation, settings.jobs, {},
                                      [&bar](long done, long total) { bar.Update(done, total); });

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
  const bool all = by_status.size() == 1 && by_status.count("success") == 1;
  return all ? 0 : 1;
}

}  // namespace moreau::tool
