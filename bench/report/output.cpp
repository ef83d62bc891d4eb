// CSV, gnuplot images, the markdown table and the report section of docs/benchmarks.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "report.hpp"

namespace moreau::report {
namespace {

namespace fs = std::filesystem;

// Log axes cannot show 0: errors below this (exact to round-off) are drawn at it.
constexpr double kPlotErrorFloor = 1e-16;

std::string Sci(double value, int digits = 2) {
  if (std::isnan(value)) return "nan";
  std::ostringstream s;
  s << std::scientific << std::setprecision(digits) << value;
  return s.str();
}

std::string Fixed(double value, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << value;
  return s.str();
}

// CPU time with three significant digits in a readable unit.
std::string Duration(double seconds) {
  std::ostringstream s;
  if (seconds < 1e-3) {
    s << std::setprecision(3) << seconds * 1e6 << " µs";
  } else if (seconds < 1.0) {
    s << std::setprecision(3) << seconds * 1e3 << " ms";
  } else {
    s << std::setprecision(3) << seconds << " s";
  }
  return s.str();
}

std::string CsvField(std::string text) {
  std::replace(text.begin(), text.end(), '\n', ' ');
  std::string quoted = "\"";
  for (char c : text) {
    if (c == '"') quoted += '"';
    quoted += c;
  }
  return quoted + "\"";
}

// Markdown cells may not contain '|' or line breaks.
std::string Cell(std::string text) {
  std::replace(text.begin(), text.end(), '\n', ' ');
  std::string escaped;
  for (char c : text) {
    if (c == '|') escaped += '\\';
    escaped += c;
  }
  return escaped;
}

void WriteCsv(const std::vector<Series>& series, const std::string& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write '" + path + "'");
  out << "scene,integrator,stages,method,parameter_name,parameter,status,error,state_error,"
         "switch_time_error,algebraic_error,events_found,events_expected,cpu_median_s,cpu_min_s,"
         "repeats,deterministic,steps,step_unit,iterations,iteration_unit,message\n";
  for (const Series& s : series) {
    if (!s.refused.empty()) {
      out << s.scene->name << "," << s.method->integrator << "," << s.method->stages << ","
          << CsvField(s.method->label) << ",,,refused,,,,,,,,,,,,,,," << CsvField(s.refused)
          << "\n";
      continue;
    }
    for (const Measurement& p : s.points) {
      out << s.scene->name << "," << s.method->integrator << "," << s.method->stages << ","
          << CsvField(s.method->label) << "," << (s.method->tolerance_driven ? "rtol" : "h") << ","
          << Sci(p.parameter, 10) << "," << p.output.status << "," << Sci(p.errors.total, 6) << ","
          << Sci(p.errors.state, 6) << "," << Sci(p.errors.switch_time, 6) << ","
          << Sci(p.errors.algebraic, 6) << "," << p.errors.events_found << ","
          << s.scene->switch_times.size() << "," << Sci(p.timing.median_seconds, 6) << ","
          << Sci(p.timing.min_seconds, 6) << "," << p.timing.repeats << ","
          << (p.timing.deterministic ? "yes" : "no") << "," << p.output.num_steps << ","
          << s.method->step_unit << "," << p.output.num_iterations << ","
          << s.method->iteration_unit << "," << CsvField(p.output.message) << "\n";
    }
  }
}

// Colour per method: blues for FESD, greens for adaptive FESD, reds for time-stepping, purples
// for Radau IIA.
std::string Colour(const Method& method) {
  if (method.integrator == "fesd" && method.tolerance_driven) {
    return method.stages >= 4 ? "#006d2c" : "#31a354";
  }
  static const std::map<std::string, std::vector<std::string>> palette = {
      {"fesd", {"#6baed6", "#3182bd", "#08519c", "#08306b"}},
      {"timestepping", {"#fc9272", "#ef3b2c", "#a50f15"}},
      {"radau", {"#bcbddc", "#9e9ac8", "#6a51a3", "#3f007d"}},
      {"ida", {"#000000"}},
      {"alpha", {"#e6550d"}}};
  const std::vector<std::string>& colours = palette.at(method.integrator);
  const std::size_t index = method.stages > 0 ? static_cast<std::size_t>(method.stages - 1) : 0;
  return colours[std::min(index, colours.size() - 1)];
}

std::string OrderText(const OrderFit& fit) {
  return fit.points_used >= 2 ? Fixed(fit.order, 2) : "—";
}

// One image per scene: error against h with the fitted orders (step-size methods), and error
// against CPU time (all methods).
void WritePlot(const SceneCase& scene, const std::vector<const Series*>& series,
               const std::string& directory) {
  const std::string data_dir = directory + "/gnuplot";
  fs::create_directories(data_dir);
  const std::string data = data_dir + "/" + scene.name + ".dat";
  const std::string script = data_dir + "/" + scene.name + ".gp";
  std::ofstream out(data);
  if (!out) throw std::runtime_error("cannot write '" + data + "'");
  out << std::setprecision(10);
  // Blocks (gnuplot `index`): per series its points (parameter, error, CPU ms), then per
  // series with a fit the fitted line over the points used.
  std::vector<int> point_block(series.size(), -1), fit_block(series.size(), -1);
  int block = 0;
  for (std::size_t i = 0; i < series.size(); ++i) {
    bool any = false;
    for (const Measurement& p : series[i]->points) {
      if (!p.output.success || !std::isfinite(p.errors.total)) continue;
      out << p.parameter << " " << std::max(p.errors.total, kPlotErrorFloor) << " "
          << p.timing.median_seconds * 1e3 << "\n";
      any = true;
    }
    if (!any) continue;
    out << "\n\n";
    point_block[i] = block++;
  }
  for (std::size_t i = 0; i < series.size(); ++i) {
    const Series& s = *series[i];
    if (s.method->tolerance_driven || s.fit.points_used < 2) continue;
    double h_min = INFINITY, h_max = 0.0;
    for (const Measurement& p : s.points) {
      if (!InFitRange(s, p) || !(p.errors.total > scene.floor)) continue;
      h_min = std::min(h_min, p.parameter);
      h_max = std::max(h_max, p.parameter);
    }
    for (double h : {h_max, h_min}) {
      out << h << " " << std::exp(s.fit.constant) * std::pow(h, s.fit.order) << " 0\n";
    }
    out << "\n\n";
    fit_block[i] = block++;
  }
  out.close();

  std::ofstream gp(script);
  if (!gp) throw std::runtime_error("cannot write '" + script + "'");
  const std::string image = directory + "/" + scene.name + ".png";
  gp << "set terminal pngcairo size 1600,560 noenhanced font 'sans,10'\n"
     << "set output '" << image << "'\n"
     << "set multiplot layout 1,2 title '" << scene.title << "  (error against the "
     << scene.answer_source << ")'\n"
     << "set logscale xy\nset format x '%.0e'\nset format y '%.0e'\nset grid\n"
     << "set key outside right top samplen 2 spacing 0.9 font ',9'\nset ylabel 'error'\n";
  // Left: error against h.
  gp << "set title 'error vs step size (p: fitted order, dashed over the points used; dotted: "
        "order-fit floor)'\n"
     << "set xlabel 'step size h" << (scene.scene.Has<HysteresisRelay>() ? " (numerical time)" : "")
     << "'\n";
  std::ostringstream left;
  bool first = true;
  for (std::size_t i = 0; i < series.size(); ++i) {
    const Series& s = *series[i];
    if (s.method->tolerance_driven || point_block[i] < 0) continue;
    left << (first ? "" : ", \\\n  ") << "'" << data << "' index " << point_block[i]
         << " using 1:2 with linespoints lw 2 pt " << 4 + 2 * std::max(0, s.method->stages - 1)
         << " lc rgb '" << Colour(*s.method) << "' title '" << s.method->label
         << " p=" << OrderText(s.fit) << "'";
    if (fit_block[i] >= 0) {
      left << ", '" << data << "' index " << fit_block[i]
           << " using 1:2 with lines dt 2 lw 1 lc rgb '" << Colour(*s.method) << "' notitle";
    }
    first = false;
  }
  if (first) {
    // Only tolerance-driven methods (e.g. --integrators ida): an empty panel. gnuplot cannot
    // autoscale a log axis without points, hence the fixed ranges.
    gp << "set xrange [1e-3:1]\nset yrange [1e-12:1]\n"
       << "set label 1 'no fixed-step method selected' at graph 0.5,0.5 center\n"
       << "plot NaN notitle\nunset label 1\nset autoscale xy\n";
  } else {
    gp << "plot " << left.str() << ", " << scene.floor
       << " with lines dt 3 lw 2 lc rgb '#777777' notitle\n";
  }
  // Right: error against CPU time.
  gp << "set title 'error vs CPU time (median of interleaved repeats)'\n"
     << "set xlabel 'CPU time [ms]'\nplot ";
  first = true;
  for (std::size_t i = 0; i < series.size(); ++i) {
    const Series& s = *series[i];
    if (point_block[i] < 0) continue;
    gp << (first ? "" : ", \\\n  ") << "'" << data << "' index " << point_block[i]
       << " using 3:2 with linespoints lw 2 pt " << 4 + 2 * std::max(0, s.method->stages - 1)
       << " lc rgb '" << Colour(*s.method) << "' title '" << s.method->label << "'";
    first = false;
  }
  if (first) gp << "NaN notitle";
  gp << "\nunset multiplot\n";
  gp.close();
  const std::string command = "gnuplot '" + script + "' 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) throw std::runtime_error("cannot start gnuplot");
  std::string output;
  char buffer[256];
  while (fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
  const int code = pclose(pipe);
  if (code != 0 || !fs::exists(image)) {
    throw std::runtime_error("gnuplot failed on '" + script + "': " + output);
  }
}

std::string GridText(const Series& s) {
  const double first = s.points.front().parameter, last = s.points.back().parameter;
  int failed = 0, unmatched = 0;
  for (const Measurement& p : s.points) {
    failed += p.output.success ? 0 : 1;
    unmatched += p.output.success && std::isinf(p.errors.switch_time) ? 1 : 0;
  }
  std::ostringstream text;
  text << (s.method->tolerance_driven ? "rtol " : "h ") << Sci(first, 1) << "…" << Sci(last, 1)
       << " (" << s.points.size();
  if (failed > 0) text << ", " << failed << " failed";
  if (unmatched > 0) text << ", " << unmatched << " without any switch reported";
  text << ")";
  return text.str();
}

std::string OrderCell(const OrderFit& fit) {
  if (fit.points_used < 2) return "—";
  return Fixed(fit.order, 2) + " (" + std::to_string(fit.points_used) + ")";
}

std::string CheckCell(const Series& s) {
  if (std::isnan(s.expected.order)) return "";
  if (s.fit.points_used >= 2) {
    return s.fit.order >= s.expected.low && s.fit.order <= s.expected.high ? "✓" : "✗ (notes)";
  }
  // No fit: say why. All points of the asymptotic range at the floor: the method is exact to
  // round-off there.
  int above_floor = 0;
  for (const Measurement& p : s.points) {
    if (!InFitRange(s, p)) continue;
    above_floor += p.errors.total > s.scene->floor ? 1 : 0;
  }
  if (above_floor == 0) return "no fit: at the floor";
  return "no fit: " + std::to_string(above_floor) + " point above the floor";
}

std::string TableMarkdown(const std::vector<Series>& series, const std::vector<SceneCase>& scenes) {
  std::ostringstream md;
  md << "| scene | integrator | grid (runs) | order: error | order: x(T) | order: switch times "
        "| theory | matches | CPU to 1e-4 | to 1e-6 | to 1e-8 | to 1e-10 | iterations |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const SceneCase& scene : scenes) {
    // Fastest time per target on this scene, for the ratios.
    std::vector<double> fastest(kTargetErrors.size(), INFINITY);
    for (const Series& s : series) {
      if (s.scene != &scene || !s.refused.empty()) continue;
      for (std::size_t k = 0; k < kTargetErrors.size(); ++k) {
        if (std::isfinite(s.time_to_target[k])) {
          fastest[k] = std::min(fastest[k], s.time_to_target[k]);
        }
      }
    }
    for (const Series& s : series) {
      if (s.scene != &scene || !s.refused.empty()) continue;
      md << "| " << scene.name << " | " << s.method->label << " | " << GridText(s) << " | ";
      if (s.method->tolerance_driven) {
        md << "slope vs rtol " << OrderCell(s.fit) << " | | | ";
      } else {
        md << OrderCell(s.fit) << " | " << OrderCell(s.state_fit) << " | "
           << OrderCell(s.switch_fit) << " | ";
      }
      md << Cell(s.expected.text) << " | " << CheckCell(s) << " | ";
      for (std::size_t k = 0; k < kTargetErrors.size(); ++k) {
        const double t = s.time_to_target[k];
        if (!std::isfinite(t)) {
          md << "— | ";
          continue;
        }
        md << (s.reached_at_first[k] ? "≤ " : "") << Duration(t) << " (×" << std::setprecision(2)
           << t / fastest[k] << ") | ";
      }
      md << (std::isfinite(s.newton_per_step) ? Fixed(s.newton_per_step, 2) : "—") << " "
         << s.method->iteration_unit << "/" << s.method->step_unit << " |\n";
    }
  }
  return md.str();
}

// Adaptive FESD against IDA (issue 16): per scene, the CPU time adaptive FESD needs to reach
// each target error divided by IDA's (both interpolated like the main table, from the same
// run, their points timed in the same interleaved rounds); <= 1: adaptive FESD is not slower.
std::string AdaptiveAgainstIdaMarkdown(const std::vector<Series>& series,
                                       const std::vector<SceneCase>& scenes) {
  std::ostringstream md;
  md << "| scene | method |";
  for (double target : kTargetErrors) md << " to " << Sci(target, 0) << " |";
  md << "\n|---|---|";
  for (std::size_t k = 0; k < kTargetErrors.size(); ++k) md << "---|";
  md << "\n";
  bool any = false;
  for (const SceneCase& scene : scenes) {
    const Series* ida = nullptr;
    std::vector<const Series*> adaptive;
    for (const Series& s : series) {
      if (s.scene != &scene || !s.refused.empty()) continue;
      if (s.method->integrator == "ida") ida = &s;
      if (s.method->integrator == "fesd" && s.method->tolerance_driven) adaptive.push_back(&s);
    }
    if (ida == nullptr || adaptive.empty()) continue;
    any = true;
    for (const Series* s : adaptive) {
      md << "| " << scene.name << " | " << s->method->label << " / IDA |";
      for (std::size_t k = 0; k < kTargetErrors.size(); ++k) {
        const double fesd = s->time_to_target[k], reference = ida->time_to_target[k];
        if (std::isfinite(fesd) && std::isfinite(reference)) {
          md << " " << Fixed(fesd / reference, 2) << (fesd <= reference ? "" : " ✗") << " |";
        } else if (std::isfinite(fesd)) {
          md << " IDA: not reached |";
        } else if (std::isfinite(reference)) {
          md << " ✗ not reached |";
        } else {
          md << " neither |";
        }
      }
      md << "\n";
    }
  }
  return any ? md.str() : "";
}

std::string RefusalMarkdown(const std::vector<Series>& series) {
  // One row per (scene, integrator): the stage variants refuse for the same reason.
  std::ostringstream md;
  md << "| scene | integrator | reason (the integrator's own message) |\n|---|---|---|\n";
  std::string last;
  for (const Series& s : series) {
    if (s.refused.empty()) continue;
    const std::string key = s.scene->name + "/" + s.method->integrator;
    if (key == last) continue;
    last = key;
    md << "| " << s.scene->name << " | " << s.method->integrator << " | " << Cell(s.refused)
       << " |\n";
  }
  return md.str();
}

}  // namespace

std::string WriteReport(const std::vector<Series>& series, const std::vector<SceneCase>& scenes,
                        const ReportInfo& info, const std::string& directory,
                        const std::string& link_base) {
  fs::create_directories(directory);
  WriteCsv(series, directory + "/measurements.csv");
  // Scenes without any successful run (every selected integrator refused it, e.g.
  // --integrators fesd on dai_index2) get no image: gnuplot cannot draw an empty plot.
  std::vector<const SceneCase*> plotted;
  for (const SceneCase& scene : scenes) {
    std::vector<const Series*> of_scene;
    bool any_success = false;
    for (const Series& s : series) {
      if (s.scene != &scene || !s.refused.empty()) continue;
      of_scene.push_back(&s);
      for (const Measurement& p : s.points) any_success |= p.output.success;
    }
    if (!any_success) continue;
    WritePlot(scene, of_scene, directory);
    plotted.push_back(&scene);
  }
  const std::string link = fs::relative(fs::absolute(directory), fs::absolute(link_base)).string();
  std::ostringstream md;
  md << "Generated by `scripts/report`" << (info.revision.empty() ? "" : " from " + info.revision)
     << " in " << Fixed(info.wall_seconds / 60.0, 1) << " min (" << info.runs
     << " simulations). CPU time: median thread CPU time of " << info.timing.min_repeats << " to "
     << info.timing.max_repeats << " timed runs per point (repeated up to "
     << Fixed(info.timing.min_total_seconds, 1)
     << " s of CPU time) after one untimed run, interleaved: the timed runs of all points of a "
        "scene go in rounds, each running every point still short of its repeats once in a "
        "shuffled order, so that a burst of machine load spreads over all methods instead of "
        "landing on one; (×): ratio to the fastest integrator on the same scene at the same "
        "error; ≤: reached already at the coarsest point; —: not reached. "
        "Orders: fitted on the asymptotic range above the scene's floor (points used in "
        "parentheses). Iterations: Newton (IDA: nonlinear, alpha: SQP) iterations per step or "
        "FESD finite element. All runs: `"
     << link << "/measurements.csv`.\n\n"
     << TableMarkdown(series, scenes) << "\n";
  const std::string against_ida = AdaptiveAgainstIdaMarkdown(series, scenes);
  if (!against_ida.empty()) {
    md << "Adaptive FESD against IDA: CPU time to reach each error divided by IDA's, from this "
          "run (medians of the same interleaved rounds; ≤ 1: adaptive FESD is not slower; ✗: "
          "slower or not reached; \"IDA: not reached\": IDA's sweep, down to rtol 1e-13, does "
          "not get there):\n\n"
       << against_ida << "\n";
  }
  md << "Answers, floors and asymptotic ranges:\n\n";
  for (const SceneCase& scene : scenes) {
    md << "- " << scene.title << ": " << scene.answer_source << ", " << scene.switch_times.size()
       << (scene.switch_times.size() == 1 ? " switch" : " switches") << "; order-fit floor "
       << Sci(scene.floor, 1) << " (" << scene.floor_reason << ")";
    if (std::isfinite(scene.fit_max_step)) {
      md << "; orders fitted on h <= " << scene.fit_max_step << " (" << scene.fit_max_step_reason
         << ")";
    }
    if (std::isfinite(scene.reference_error)) {
      md << "; `ComputeReference` (IDA, rtol 1e-12) is off by " << Sci(scene.reference_error, 1);
    }
    md << ".\n";
  }
  for (const Series& s : series) {
    if (s.refused.empty() && s.algebraic_fit.points_used >= 2) {
      md << "- " << s.scene->name << ", " << s.method->label
         << ": the algebraic input u(T) converges with order " << Fixed(s.algebraic_fit.order, 2)
         << " (not part of the error above; the theory bounds algebraic variables of index-2 "
            "constraints by O(h), Lemma 3 of the alpha-method paper, and the maximum over the "
            "mesh attains it: tests/integrators/alpha_dai_test.cpp).\n";
    }
  }
  bool nondeterministic = false;
  for (const Series& s : series) {
    for (const Measurement& p : s.points) nondeterministic |= !p.timing.deterministic;
  }
  if (nondeterministic) {
    md << "- Some repeated runs did not reproduce their final state bitwise (see the "
          "`deterministic` column of the CSV).\n";
  }
  md << "\nNot run (the integrator refuses the scene):\n\n" << RefusalMarkdown(series) << "\n";
  for (const SceneCase* scene : plotted) {
    md << "![" << scene->name << "](" << link << "/" << scene->name << ".png)\n";
  }
  const std::string text = md.str();
  std::ofstream out(directory + "/report.md");
  if (!out) throw std::runtime_error("cannot write '" + directory + "/report.md'");
  out << text;
  return text;
}

namespace {

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("cannot read '" + path + "'");
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

// Start of the text after the begin marker's line and start of the end marker.
std::pair<std::size_t, std::size_t> SectionBounds(const std::string& text,
                                                  const std::string& readme) {
  const std::size_t begin = text.find(kReadmeBegin);
  const std::size_t end = text.find(kReadmeEnd);
  const std::size_t after_begin = begin == std::string::npos ? begin : text.find('\n', begin);
  if (after_begin == std::string::npos || end == std::string::npos || end < after_begin) {
    throw std::invalid_argument("'" + readme + "' lacks the marker lines '" + kReadmeBegin +
                                "' and '" + kReadmeEnd + "' (in this order)");
  }
  return {after_begin + 1, end};
}

}  // namespace

void CheckReadme(const std::string& readme) { SectionBounds(ReadFile(readme), readme); }

void UpdateReadme(const std::string& readme, const std::string& section) {
  const std::string text = ReadFile(readme);
  const auto [begin, end] = SectionBounds(text, readme);
  std::ofstream out(readme);
  if (!out) throw std::runtime_error("cannot write '" + readme + "'");
  out << text.substr(0, begin) << section << text.substr(end);
}

}  // namespace moreau::report
