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

std::string Quote(const std::string& text) { return "'" + text + "'"; }

// Column numbers (1-based, gnuplot) of the CSV written by WriteSweepCsv.
struct Columns {
  int varied = 2;  // first varied value
  int state = 0;   // first final state
  int events = 0;  // num_events
  int first_event = 0;
};
Columns CsvColumns(const SweepResult& r) {
  Columns c;
  const int varied = static_cast<int>(r.varied_names.size());
  c.state = 2 + varied + 4;  // index, varied..., status, success, message, final_time
  c.events = c.state + static_cast<int>(r.state_names.size());
  c.first_event = c.events + 1;
  return c;
}

std::vector<std::string> Plots(const SweepResult& r, const std::string& dir) {
  std::vector<std::string> images;
  const std::string csv = dir + "/sweep.csv";
  const Columns c = CsvColumns(r);
  const std::size_t shown = std::min<std::size_t>(r.state_names.size(), kMaxPlottedStates);
  auto header = [&](std::ofstream& s, const std::string& image, const std::string& title) {
    s << "set terminal pngcairo size 1000,600 noenhanced\nset output " << Quote(image)
      << "\nset datafile separator ','\nset key autotitle columnhead outside right top\n"
      << "set grid\nset title " << Quote(title) << "\n";
  };
  if (r.varied_names.size() == 1) {
    const std::string name = r.varied_names[0];
    {
      const std::string image = dir + "/final_states.png", script = dir + "/final_states.gp";
      std::ofstream s(script);
      header(s, image, r.scene + ": final states against " + name + " (" + r.integrator + ")");
      s << "set xlabel " << Quote(name) << "\nplot ";
      for (std::size_t i = 0; i < shown; ++i) {
        s << (i ? ", " : "") << Quote(csv) << " using " << c.varied << ":"
          << c.state + static_cast<int>(i) << " with linespoints lw 2 pt 7 ps 0.5";
      }
      s << "\n";
      s.close();
      if (RunGnuplot(script, image)) images.push_back(image);
    }
    if (r.num_event_times > 0) {
      const std::string image = dir + "/event_times.png", script = dir + "/event_times.gp";
      std::ofstream s(script);
      header(s, image, r.scene + ": event times against " + name + " (" + r.integrator + ")");
      s << "set xlabel " << Quote(name) << "\nset ylabel 't'\nplot ";
      for (int e = 0; e < r.num_event_times; ++e) {
        s << (e ? ", " : "") << Quote(csv) << " using " << c.varied << ":" << c.first_event + e
          << " with points pt 7 ps 0.6";
      }
      s << "\n";
      s.close();
      if (RunGnuplot(script, image)) images.push_back(image);
    }
  } else if (r.varied_names.size() == 2) {
    // Heat maps on the scattered (a, b) points (exact grids and samples alike).
    std::vector<std::pair<std::string, int>> quantities;
    for (std::size_t i = 0; i < std::min<std::size_t>(shown, 4); ++i) {
      quantities.push_back({"x." + r.state_names[i], c.state + static_cast<int>(i)});
    }
    quantities.push_back({"num_events", c.events});
    for (const auto& [quantity, column] : quantities) {
      const std::string base = dir + "/heatmap_" + quantity;
      const std::string image = base + ".png", script = base + ".gp";
      std::ofstream s(script);
      header(s, image, r.scene + ": " + quantity + " (" + r.integrator + ")");
      s << "set xlabel " << Quote(r.varied_names[0]) << "\nset ylabel " << Quote(r.varied_names[1])
        << "\nset palette rgbformulae 33,13,10\nunset key\nplot " << Quote(csv) << " using "
        << c.varied << ":" << c.varied + 1 << ":" << column << " with points pt 5 ps 1.5 palette\n";
      s.close();
      if (RunGnuplot(script, image)) images.push_back(image);
    }
  }
  return images;
}

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
      settings.plot ? Plots(result, dir) : std::vector<std::string>{};

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
