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

namespace moreau::tool {
namespace {

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
        bar.Update(static_cast<double>(done) / std::max(total, 1L), runs_text(done, total));
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
      settings.plot ? Plots(result, dir) : std::vector<std::string>{};

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
