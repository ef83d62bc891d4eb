// work_precision: the accuracy-vs-time report (see report.hpp and docs/benchmarks.md,
// "Work-precision report"). Usually run through scripts/report.
//
//   work_precision [--out DIR] [--page docs/benchmarks.md] [--scenes F1,S2]
//                  [--integrators fesd,ida]
//                  [--min-repeats N] [--max-repeats N] [--min-seconds S] [--revision TEXT]
//
// Exit codes: 0 success; 1 a failure while measuring or writing (reference, gnuplot, files);
// 2 bad usage (unknown option, scene or integrator, bad value).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <set>
#include <stdexcept>

#include "report.hpp"

namespace {

using namespace moreau::report;

struct Settings {
  std::string out = "docs/report";
  std::string readme;
  std::vector<std::string> scenes;
  std::vector<std::string> integrators;
  TimingOptions timing;
  std::string revision;
};

std::string Short(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.3g", value);
  return buffer;
}

void Validate(const Settings& settings, const std::vector<Method>& methods) {
  std::set<std::string> known;
  for (const Method& m : methods) known.insert(m.integrator);
  for (const std::string& name : settings.integrators) {
    if (known.count(name) == 0) {
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      throw std::invalid_argument("unknown integrator '" + name +
                                  "'; the report's integrators are: " + list);
    }
  }
  if (settings.timing.min_repeats < 1 ||
      settings.timing.max_repeats < settings.timing.min_repeats) {
    throw std::invalid_argument("--min-repeats must be >= 1 and <= --max-repeats, got " +
                                std::to_string(settings.timing.min_repeats) + " and " +
                                std::to_string(settings.timing.max_repeats));
  }
  if (!(settings.timing.min_total_seconds >= 0.0)) {
    throw std::invalid_argument("--min-seconds must be >= 0");
  }
}

int Run(const Settings& settings) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  const std::vector<Method> methods = Methods();
  Validate(settings, methods);
  if (!settings.readme.empty()) CheckReadme(settings.readme);
  std::fprintf(stderr, "[report] reference solutions and scenes...\n");
  const std::vector<SceneCase> scenes = SceneCases(settings.scenes);
  std::vector<Series> series;
  std::size_t planned = 0;
  for (const SceneCase& scene : scenes) {
    for (const Method& method : methods) {
      if (!settings.integrators.empty() &&
          std::find(settings.integrators.begin(), settings.integrators.end(), method.integrator) ==
              settings.integrators.end()) {
        continue;
      }
      Series s;
      s.scene = &scene;
      s.method = &method;
      series.push_back(s);
      planned += scene.grid(method).size();
    }
  }
  ReportInfo info;
  info.timing = settings.timing;
  info.revision = settings.revision;
  std::size_t done = 0;
  for (const SceneCase& scene : scenes) {
    std::vector<Series*> of_scene;
    for (Series& s : series) {
      if (s.scene == &scene) of_scene.push_back(&s);
    }
    // One untimed run per point (warm-up): its output, its errors, or the integrator's
    // refusal of the scene.
    for (Series* s : of_scene) {
      for (double parameter : scene.grid(*s->method)) {
        Measurement point;
        point.scene = scene.name;
        point.method = s->method;
        point.parameter = parameter;
        try {
          point.output = s->method->run(scene.scene, parameter);
        } catch (const std::invalid_argument& refusal) {
          if (!s->points.empty()) throw;  // accepted once: a refusal now would be a bug
          s->refused = refusal.what();
          break;
        }
        point.errors = MeasureErrors(scene, point.output);
        s->points.push_back(std::move(point));
      }
    }
    // The timed runs of all the scene's points, interleaved (see TimeInterleaved).
    std::vector<Measurement*> points;
    for (Series* s : of_scene) {
      for (Measurement& point : s->points) points.push_back(&point);
    }
    std::fprintf(stderr, "[report] %s: %zu points run once, timing them interleaved...\n",
                 scene.name.c_str(), points.size());
    TimeInterleaved(scene, points, settings.timing);
    const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
    for (Series* s : of_scene) {
      if (!s->refused.empty()) {
        done += scene.grid(*s->method).size();
        std::fprintf(stderr, "[report %3zu/%zu] %s %s: refused (%s)\n", done, planned,
                     scene.name.c_str(), s->method->label.c_str(), s->refused.c_str());
      }
      for (const Measurement& point : s->points) {
        ++done;
        info.runs += 1 + point.timing.repeats;
        std::fprintf(stderr, "[report %3zu/%zu %5.0f s] %s %s %s = %s: %s, error %s, %s ms (%d)\n",
                     done, planned, elapsed, scene.name.c_str(), s->method->label.c_str(),
                     s->method->tolerance_driven ? "rtol" : "h", Short(point.parameter).c_str(),
                     point.output.status.c_str(), Short(point.errors.total).c_str(),
                     Short(point.timing.median_seconds * 1e3).c_str(), point.timing.repeats);
      }
      Summarize(s);
    }
  }
  info.wall_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  const std::string link_base =
      settings.readme.empty() ? settings.out
                              : std::filesystem::absolute(settings.readme).parent_path().string();
  const std::string section = WriteReport(series, scenes, info, settings.out, link_base);
  if (!settings.readme.empty()) UpdateReadme(settings.readme, section);
  std::fprintf(stderr, "[report] done in %.0f s: %s/report.md%s%s\n", info.wall_seconds,
               settings.out.c_str(), settings.readme.empty() ? "" : ", ", settings.readme.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Accuracy-vs-time report: every scene with every integrator over a grid"};
  Settings settings;
  app.add_option("--out", settings.out, "output directory (CSV, images, report.md)");
  app.add_option("--page,--readme", settings.readme,
                 "rewrite the report section of this Markdown page, docs/benchmarks.md (between "
                 "its marker lines)");
  app.add_option("--scenes", settings.scenes, "scenes to run (default: all)")->delimiter(',');
  app.add_option("--integrators", settings.integrators,
                 "integrators to run: fesd, timestepping, radau, ida, alpha (default: all)")
      ->delimiter(',');
  app.add_option("--min-repeats", settings.timing.min_repeats, "timed repeats at least");
  app.add_option("--max-repeats", settings.timing.max_repeats, "timed repeats at most");
  app.add_option("--min-seconds", settings.timing.min_total_seconds,
                 "repeat until this much CPU time (up to --max-repeats)");
  app.add_option("--revision", settings.revision, "source revision printed in the report");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    return app.exit(error) == 0 ? 0 : 2;
  }
  try {
    return Run(settings);
  } catch (const std::invalid_argument& error) {
    std::cerr << "work_precision: " << error.what() << "\n";
    return 2;
  } catch (const std::exception& error) {
    std::cerr << "work_precision: " << error.what() << "\n";
    return 1;
  }
}
