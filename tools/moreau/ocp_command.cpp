#include "ocp_command.hpp"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <sstream>

#include "moreau/core/error.hpp"
#include "moreau/ocp/catalog.hpp"
#include "output.hpp"

namespace moreau::tool {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

Json Named(const std::vector<std::string>& names, const Vector& values) {
  Json object = Json::object();
  for (std::size_t i = 0; i < names.size() && static_cast<Eigen::Index>(i) < values.size(); ++i) {
    object[names[i]] = values[static_cast<Eigen::Index>(i)];
  }
  return object;
}

std::vector<std::string> ControlNames(const OcpProblem& problem) {
  std::vector<std::string> names;
  for (int index : problem.controls) {
    names.push_back(problem.scene.inputs[static_cast<std::size_t>(index)].name);
  }
  return names;
}

void WriteControlsCsv(const OcpProblem& problem, const OcpResult& result, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << "t_start,t_end";
  for (const std::string& name : ControlNames(problem)) out << "," << name;
  if (result.speeds.size() > 0) out << ",speed";
  out << "\n" << std::setprecision(17);
  for (Eigen::Index k = 0; k < result.controls.rows(); ++k) {
    out << result.grid[static_cast<std::size_t>(k)] << ","
        << result.grid[static_cast<std::size_t>(k) + 1];
    for (Eigen::Index j = 0; j < result.controls.cols(); ++j) out << "," << result.controls(k, j);
    if (result.speeds.size() > 0) out << "," << result.speeds[k];
    out << "\n";
  }
}

void WriteIterationsCsv(const OcpResult& result, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << "level,iteration,objective,primal_infeasibility,dual_infeasibility\n"
      << std::setprecision(17);
  for (const OcpIteration& it : result.log) {
    out << it.level << "," << it.iteration << "," << it.objective << "," << it.primal_infeasibility
        << "," << it.dual_infeasibility << "\n";
  }
}

Json HomotopyJson(const std::vector<OcpHomotopyLevel>& homotopy) {
  Json levels = Json::array();
  for (const OcpHomotopyLevel& level : homotopy) {
    Json parameters = Json::object();
    for (const auto& [name, value] : level.parameters) parameters[name] = value;
    levels.push_back({{"smoothing", level.smoothing},
                      {"relaxation", level.relaxation},
                      {"complementarity", level.complementarity},
                      {"parameters", parameters}});
  }
  return levels;
}

Json SummaryJson(const OcpProblem& problem, const OcpOptions& options, const OcpResult& result) {
  const std::vector<std::string>& states = problem.scene.state_names;
  Json controls = Json::array();
  for (Eigen::Index k = 0; k < result.controls.rows(); ++k) {
    Json row = Json::object();
    row["t_start"] = result.grid[static_cast<std::size_t>(k)];
    row["t_end"] = result.grid[static_cast<std::size_t>(k) + 1];
    row["u"] = Named(ControlNames(problem), result.controls.row(k).transpose());
    if (result.speeds.size() > 0) row["speed"] = result.speeds[k];
    controls.push_back(row);
  }
  Json events = Json::array();
  for (const Event& e : result.events) {
    events.push_back(
        {{"t", e.t}, {"kind", ToString(e.kind)}, {"what", e.what}, {"detail", e.detail}});
  }
  Json levels = Json::array();
  for (const OcpLevelResult& level : result.levels) {
    Json parameters = Json::object();
    for (const auto& [name, value] : level.parameters.parameters) parameters[name] = value;
    levels.push_back({{"smoothing", level.parameters.smoothing},
                      {"relaxation", level.parameters.relaxation},
                      {"complementarity", level.parameters.complementarity},
                      {"parameters", parameters},
                      {"intervals", level.intervals},
                      {"stages", level.stages},
                      {"status", ToString(level.status)},
                      {"message", level.message},
                      {"iterations", level.iterations},
                      {"objective", level.objective},
                      {"seconds", level.seconds}});
  }
  Json log = Json::array();
  for (const OcpIteration& it : result.log) {
    log.push_back({{"level", it.level},
                   {"iteration", it.iteration},
                   {"objective", it.objective},
                   {"primal_infeasibility", it.primal_infeasibility},
                   {"dual_infeasibility", it.dual_infeasibility}});
  }
  Json summary = {
      {"problem", problem.name},
      {"description", problem.description},
      {"options",
       {{"transcription", ToString(options.transcription)},
        {"integrator", ToString(options.integrator)},
        {"intervals", problem.intervals},
        {"stages", options.stages},
        {"refinement_stages", options.collocation_refinement_stages},
        {"finite_elements", options.finite_elements},
        {"tolerance", options.tolerance},
        {"level_tolerance", options.level_tolerance},
        {"hessian", ToString(options.hessian)},
        {"homotopy", HomotopyJson(options.homotopy)},
        {"max_iterations", options.max_iterations}}},
      {"status", ToString(result.status)},
      {"message", result.message},
      {"objective", result.objective},
      {"final_time", result.final_time},
      {"initial_state", Named(states, result.initial_state)},
      {"final_state", Named(states, result.final_state)},
      {"running_cost", result.running_cost},
      {"terminal_equality_error", result.terminal_equality_error},
      {"controls", controls},
      {"events", events},
      {"levels", levels},
      {"iterations", log},
      {"stats",
       {{"ipopt_iterations", result.stats.iterations},
        {"simulations", result.stats.simulations},
        {"fesd_elements", result.stats.fesd_elements},
        {"jacobian_nonzeros", result.stats.jacobian_nonzeros},
        {"hessian_nonzeros", result.stats.hessian_nonzeros},
        {"cpu_seconds", result.stats.cpu_seconds},
        {"verification_seconds", result.stats.verification_seconds}}},
  };
  if (result.complementarity_residual >= 0.0) {
    summary["complementarity_residual"] = result.complementarity_residual;
  }
  summary["verification"] = {{"done", result.verified}, {"message", result.verification_message}};
  if (result.verified) {
    summary["verification"]["integrator"] = "ida (rtol 1e-12)";
    summary["verification"]["final_state"] = Named(states, result.resimulated_final_state);
    summary["verification"]["terminal_error"] = result.resimulated_terminal_error;
    summary["verification"]["state_difference"] = result.resimulated_state_difference;
  }
  summary["fesd_verification"] = {{"done", result.fesd_verified},
                                  {"message", result.fesd_verification_message}};
  if (result.fesd_verified) {
    summary["fesd_verification"]["integrator"] =
        "fesd (s = 3, 3 elements, steps of a tenth of a control interval)";
    summary["fesd_verification"]["final_state"] =
        Named(states, result.fesd_resimulated_final_state);
    summary["fesd_verification"]["terminal_error"] = result.fesd_resimulated_terminal_error;
    summary["fesd_verification"]["state_difference"] = result.fesd_resimulated_state_difference;
  }
  if (result.verification_gap >= 0.0) {
    summary["verification_gap"] = std::isfinite(result.verification_gap)
                                      ? nlohmann::json(result.verification_gap)
                                      : nlohmann::json("inf");
    summary["verification_tolerance"] = kOcpVerificationTolerance;
  }
  return summary;
}

// solution.png: the states (upper panel) and the piecewise-constant controls (lower panel)
// against physical time.
std::string WriteSolutionPlot(const OcpProblem& problem, const OcpResult& result,
                              const std::string& directory) {
  const std::string image = directory + "/solution.png";
  const std::string script_path = directory + "/solution.gp";
  std::ofstream script(script_path);
  RequireArgument(script.good(), "cannot write '", script_path, "'");
  const auto& names = problem.scene.state_names;
  const std::size_t shown = std::min<std::size_t>(names.size(), kMaxPlottedStates);
  const bool with_controls = result.controls.cols() > 0 || result.speeds.size() > 0;
  script << "set terminal pngcairo size 1000," << (with_controls ? 800 : 600) << " noenhanced\n"
         << "set output '" << image << "'\n"
         << "set datafile separator ','\n"
         << "set key outside right top\nset grid\nset xlabel 't'\n"
         << "set lmargin at screen 0.08\nset rmargin at screen 0.8\n"
         << "set xrange [" << result.grid.front() << ":" << result.grid.back() << "]\n";
  if (with_controls) script << "set multiplot layout 2,1\n";
  script << "set title '" << problem.name << " (" << ToString(result.status) << ", objective "
         << std::setprecision(10) << result.objective << ")'\nplot ";
  for (std::size_t i = 0; i < shown; ++i) {
    script << (i ? ", " : "") << "'" << directory << "/trajectory.csv' using 1:" << i + 2
           << " with lines lw 2 title '" << names[i] << "'";
  }
  script << "\n";
  if (with_controls) {
    // One horizontal segment per interval, from t_start to t_end.
    script << "unset title\nplot ";
    const auto controls = ControlNames(problem);
    std::size_t column = 3;
    for (std::size_t j = 0; j < controls.size(); ++j, ++column) {
      script << (j ? ", " : "") << "'" << directory << "/controls.csv' using 1:" << column
             << ":($2-$1):(0) with vectors nohead lw 2 title '" << controls[j] << "'";
    }
    if (result.speeds.size() > 0) {
      script << (controls.empty() ? "" : ", ") << "'" << directory
             << "/controls.csv' using 1:" << column
             << ":($2-$1):(0) with vectors nohead lw 2 dashtype 2 title 'speed of time'";
    }
    script << "\nunset multiplot\n";
  }
  script.close();
  return RunGnuplot(script_path, image) ? image : "";
}

std::string Format(const std::vector<std::string>& names, const Vector& values) {
  std::ostringstream text;
  text.precision(12);
  for (std::size_t i = 0; i < names.size() && static_cast<Eigen::Index>(i) < values.size(); ++i) {
    text << (i ? ", " : "") << names[i] << " = " << values[static_cast<Eigen::Index>(i)];
  }
  return text.str();
}

}  // namespace

std::vector<OcpHomotopyLevel> ParseHomotopy(const std::string& text) {
  std::vector<OcpHomotopyLevel> levels;
  if (text == "none") return levels;
  const std::string usage =
      "--homotopy: expected MU:EPS[:SIGMA][:NAME=VALUE...][,...] or none, got '";
  auto number = [](const std::string& field, double* value) {
    try {
      std::size_t used = 0;
      *value = std::stod(field, &used);
      return used == field.size();
    } catch (const std::exception&) {
      return false;
    }
  };
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    std::vector<std::string> fields;
    std::stringstream parts(item);
    std::string field;
    while (std::getline(parts, field, ':')) fields.push_back(field);
    OcpHomotopyLevel level;
    bool ok = fields.size() >= 2 && number(fields[0], &level.smoothing) &&
              number(fields[1], &level.relaxation);
    std::size_t first_parameter = 2;
    if (ok && fields.size() >= 3 && fields[2].find('=') == std::string::npos) {
      ok = number(fields[2], &level.complementarity);
      first_parameter = 3;
    }
    for (std::size_t i = first_parameter; ok && i < fields.size(); ++i) {
      const auto equals = fields[i].find('=');
      double value = 0.0;
      ok =
          equals != std::string::npos && equals > 0 && number(fields[i].substr(equals + 1), &value);
      if (ok) level.parameters.emplace_back(fields[i].substr(0, equals), value);
    }
    RequireArgument(ok, usage, item, "'");
    levels.push_back(level);
  }
  RequireArgument(!levels.empty(), usage, text, "'");
  return levels;
}

std::vector<int> ParseIntervalCounts(const std::string& text) {
  std::vector<int> counts;
  if (text == "none") return counts;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    int count = 0;
    std::size_t used = 0;
    try {
      count = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    RequireArgument(used == item.size() && used > 0 && count >= 1,
                    "--mesh-continuation: expected interval counts N1,N2,... (>= 1) or none, got '",
                    text, "'");
    counts.push_back(count);
  }
  RequireArgument(!counts.empty(), "--mesh-continuation: expected N1,N2,... or none, got '", text,
                  "'");
  return counts;
}

void ListOcpProblems() {
  for (const OcpDefinition& definition : OcpCatalog()) {
    std::printf("  %-17s %s\n", definition.name.c_str(), definition.summary.c_str());
  }
}

int RunOcpCommand(const OcpCommandSettings& settings) {
  OcpProblem problem = MakeOcpProblem(settings.problem);
  if (settings.intervals_given) {
    RequireArgument(settings.intervals >= 1, "--N must be at least 1 (got ", settings.intervals,
                    ")");
    problem.intervals = settings.intervals;
    problem.initial_controls.resize(0, 0);  // the problem's guess is for its own N
  }
  OcpOptions options = MakeOcpOptions(settings.problem);
  for (const auto& apply : settings.overrides) apply(&options);
  options.Validate();
  const std::string directory =
      settings.out_directory.empty() ? "out/ocp/" + problem.name : settings.out_directory;

  // Progress: one line per IPOPT iteration on a terminal, every 5 s otherwise.
  const bool tty = isatty(STDERR_FILENO) != 0;
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  if (!settings.quiet) {
    int reported_level = -1, reported_stages = options.stages;
    options.progress = [&, reported_level, reported_stages](const OcpProgress& progress) mutable {
      const auto now = std::chrono::steady_clock::now();
      const double elapsed = std::chrono::duration<double>(now - start).count();
      if (progress.stages != reported_stages) {
        // The collocation refinement: the exact level on a transcription with more stages.
        reported_stages = progress.stages;
        reported_level = progress.level;
        std::fprintf(stderr, "[moreau ocp] refinement: the exact problem with s = %d\n",
                     progress.stages);
      }
      if (progress.level != reported_level && progress.levels > 1) {
        reported_level = progress.level;
        if (progress.level + 1 < progress.levels) {
          std::fprintf(stderr,
                       "[moreau ocp] homotopy level %d/%d: smoothing %g, terminal relaxation %g, "
                       "complementarity relaxation %g\n",
                       progress.level + 1, progress.levels, progress.parameters.smoothing,
                       progress.parameters.relaxation, progress.parameters.complementarity);
        } else {
          std::fprintf(stderr, "[moreau ocp] level %d/%d: the exact problem\n", progress.level + 1,
                       progress.levels);
        }
      }
      if (!tty && std::chrono::duration<double>(now - last).count() < 5.0) return;
      last = now;
      std::fprintf(stderr,
                   "[moreau ocp] iteration %4d  objective %-14.8g infeasibility %-9.2e %.1f s\n",
                   progress.iteration, progress.objective, progress.primal_infeasibility, elapsed);
    };
  }
  const OcpResult result = SolveOcp(problem, options);

  fs::create_directories(directory);
  WriteTrajectoryCsv(result.trajectory, directory + "/trajectory.csv");
  WriteControlsCsv(problem, result, directory + "/controls.csv");
  WriteIterationsCsv(result, directory + "/iterations.csv");
  {
    std::ofstream out(directory + "/summary.json");
    RequireArgument(out.good(), "cannot write '", directory, "/summary.json'");
    out << std::setw(2) << SummaryJson(problem, options, result) << "\n";
  }
  WriteViewJson(problem.scene, directory + "/view.json");  // `moreau animate DIR`
  const std::string image = settings.plot ? WriteSolutionPlot(problem, result, directory) : "";
  if (settings.quiet) {  // errors only
    if (result.status != OcpStatus::kSolved && result.status != OcpStatus::kSolvedToAcceptable) {
      std::fprintf(stderr, "moreau: ocp %s: %s: %s\n", problem.name.c_str(),
                   ToString(result.status).c_str(), result.message.c_str());
      return 1;
    }
    return 0;
  }

  const auto& states = problem.scene.state_names;
  const std::string refinement =
      options.transcription == OcpTranscription::kCollocation &&
              options.collocation_refinement_stages > 0
          ? ", refined to s = " + std::to_string(options.collocation_refinement_stages)
          : "";
  std::printf("problem      %s (%s, %s, N = %d, s = %d%s, N_fe = %d)\n", problem.name.c_str(),
              ToString(options.transcription).c_str(), ToString(options.integrator).c_str(),
              problem.intervals, options.stages, refinement.c_str(), options.finite_elements);
  std::printf("status       %s%s%s\n", ToString(result.status).c_str(),
              result.message.empty() ? "" : ": ", result.message.c_str());
  std::printf("objective    %.15g\n", result.objective);
  std::printf("final time   %.15g\n", result.final_time);
  std::printf("x0           %s\n", Format(states, result.initial_state).c_str());
  std::printf("x(T)         %s\n", Format(states, result.final_state).c_str());
  std::printf("switches     %zu\n", result.events.size());
  if (result.complementarity_residual >= 0.0) {
    std::printf("complementarity residual %.3g (largest cross-complementarity product)\n",
                result.complementarity_residual);
  }
  if (result.verified) {
    std::printf(
        "re-simulated IDA rtol 1e-12: terminal-constraint error %.3g, |x_ida(T) - x(T)| %.3g\n",
        result.resimulated_terminal_error, result.resimulated_state_difference);
  } else {
    std::printf("re-simulated no%s%s\n", result.verification_message.empty() ? "" : ": ",
                result.verification_message.c_str());
  }
  if (result.fesd_verified) {
    std::printf(
        "re-simulated FESD (steps H/10): terminal-constraint error %.3g, "
        "|x_fesd(T) - x(T)| %.3g\n",
        result.fesd_resimulated_terminal_error, result.fesd_resimulated_state_difference);
  } else if (!result.fesd_verification_message.empty()) {
    std::printf("re-simulated no: %s\n", result.fesd_verification_message.c_str());
  }
  for (std::size_t i = 0; i + 1 < result.levels.size(); ++i) {
    const OcpLevelResult& level = result.levels[i];
    std::string parameters;
    // Mesh continuation: the coarser meshes' levels come first.
    const std::string mesh = level.intervals != 0 && level.intervals != problem.intervals
                                 ? ", mesh N = " + std::to_string(level.intervals)
                                 : "";
    for (const auto& [name, value] : level.parameters.parameters) {
      parameters += ", " + name + " " + std::to_string(value);
    }
    // A level that relaxes nothing is an exact solve before the last one (the collocation
    // transcription's exact level before its element-minima solve; homotopy levels must
    // relax something).
    const OcpHomotopyLevel& p = level.parameters;
    if (p.smoothing == 0.0 && p.relaxation == 0.0 && p.complementarity == 0.0 &&
        p.parameters.empty()) {
      // Collocation levels carry their stages (the refinement has more).
      const std::string stages =
          level.stages > 0 ? ", s = " + std::to_string(level.stages) : std::string();
      std::printf("exact        level (before the last solve%s): %s, %d iterations, %.3g s\n",
                  stages.c_str(), ToString(level.status).c_str(), level.iterations, level.seconds);
      continue;
    }
    std::printf(
        "homotopy     level %zu (smoothing %g, relaxation %g, complementarity %g%s%s): %s, %d "
        "iterations, %.3g s\n",
        i + 1, level.parameters.smoothing, level.parameters.relaxation,
        level.parameters.complementarity, parameters.c_str(), mesh.c_str(),
        ToString(level.status).c_str(), level.iterations, level.seconds);
  }
  if (!result.levels.empty() && result.levels.back().stages > 0) {
    // Collocation: the last solve (the exact level, its element minima or the refinement).
    const OcpLevelResult& level = result.levels.back();
    std::printf("final        level (s = %d): %s, %d iterations, %.3g s\n", level.stages,
                ToString(level.status).c_str(), level.iterations, level.seconds);
  }
  std::printf(
      "ipopt        %d iterations, %ld interval integrations, %.3g s (verification %.3g s)\n",
      result.stats.iterations, result.stats.simulations, result.stats.cpu_seconds,
      result.stats.verification_seconds);
  std::printf("output       %s/{trajectory,controls,iterations}.csv, %s/summary.json%s%s\n",
              directory.c_str(), directory.c_str(), image.empty() ? "" : ", ", image.c_str());
  if (settings.plot && image.empty()) {
    std::fprintf(stderr, "moreau: warning: no plot written (is gnuplot installed?)\n");
  }
  const bool solved =
      result.status == OcpStatus::kSolved || result.status == OcpStatus::kSolvedToAcceptable;
  return solved ? 0 : 1;
}

}  // namespace moreau::tool
