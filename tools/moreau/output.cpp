#include "output.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "moreau/core/error.hpp"
#include "render/view_geometry.hpp"

namespace moreau::tool {

namespace fs = std::filesystem;

void WriteTrajectoryCsv(const Trajectory& trajectory, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << "t";
  for (const std::string& name : trajectory.state_names) out << "," << name;
  for (const std::string& name : trajectory.algebraic_names) out << "," << name;
  const bool with_steps = !trajectory.step.empty();
  if (with_steps) out << ",h";
  out << "\n" << std::setprecision(17);
  for (std::size_t k = 0; k < trajectory.size(); ++k) {
    out << trajectory.t[k];
    for (Eigen::Index i = 0; i < trajectory.x[k].size(); ++i) out << "," << trajectory.x[k][i];
    // Algebraic values exist at element/step ends only; the initial point leaves them empty.
    const Vector& algebraic = trajectory.algebraic[k];
    for (std::size_t i = 0; i < trajectory.algebraic_names.size(); ++i) {
      out << ",";
      if (static_cast<Eigen::Index>(i) < algebraic.size())
        out << algebraic[static_cast<Eigen::Index>(i)];
    }
    if (with_steps) out << "," << trajectory.step[k];
    out << "\n";
  }
}

void WriteRelaysCsv(const SimulationResult& report, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << "t";
  for (const RelaySignal& relay : report.relays) out << "," << relay.relay;
  out << "\n" << std::setprecision(17);
  std::vector<double> times;
  for (const RelaySignal& relay : report.relays) {
    times.insert(times.end(), relay.jump_times.begin(), relay.jump_times.end());
  }
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  const double t0 = report.trajectory.t.empty() ? 0.0 : report.trajectory.t.front();
  out << t0;
  for (const RelaySignal& relay : report.relays) out << "," << relay.initial_value;
  out << "\n";
  for (double t : times) {
    out << t;
    for (const RelaySignal& relay : report.relays) out << "," << relay.ValueAt(t);
    out << "\n";
  }
  out << report.final_time;
  for (const RelaySignal& relay : report.relays) out << "," << relay.FinalValue();
  out << "\n";
}

void WriteElementsCsv(const SimulationResult& report, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  for (std::size_t i = 0; i < report.record_columns.size(); ++i) {
    out << (i ? "," : "") << report.record_columns[i];
  }
  out << "\n" << std::setprecision(17);
  for (const std::vector<double>& row : report.records) {
    for (std::size_t i = 0; i < row.size(); ++i) out << (i ? "," : "") << row[i];
    out << "\n";
  }
}

namespace {
nlohmann::json NumberJson(double value) {
  if (std::isfinite(value)) return value;
  return std::isnan(value) ? "nan" : (value > 0 ? "inf" : "-inf");
}
}  // namespace

nlohmann::json SettingJson(const SettingValue& value) {
  return std::visit(
      [](const auto& v) -> nlohmann::json {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, double>) {
          return NumberJson(v);
        } else if constexpr (std::is_same_v<T, std::vector<double>>) {
          nlohmann::json list = nlohmann::json::array();
          for (double x : v) list.push_back(NumberJson(x));
          return list;
        } else {
          return v;
        }
      },
      value);
}

nlohmann::json OptionsJson(const SimulationResult& result) {
  nlohmann::json options = nlohmann::json::object();
  for (const auto& [name, value] : result.options) options[name] = SettingJson(value);
  return options;
}

std::vector<std::string> ChangedOptions(const SimulationResult& result,
                                        const std::map<std::string, SettingValue>& implicit) {
  const IntegratorSpec& spec = FindIntegrator(result.integrator);
  std::vector<std::string> changed;
  for (const auto& [name, value] : result.options) {
    const auto set = implicit.find(name);
    const OptionSpec* option = spec.FindOption(name);
    const SettingValue& reference = set != implicit.end() ? set->second
                                    : option != nullptr   ? option->default_value
                                                          : value;
    if (value == reference) continue;
    // Reals with 10 significant digits (FormatSetting's 17 show 0.1 as 0.10000000000000001).
    char text[64];
    if (const double* real = std::get_if<double>(&value)) {
      std::snprintf(text, sizeof text, "%.10g", *real);
      changed.push_back(name + " = " + text);
    } else {
      changed.push_back(name + " = " + FormatSetting(value));
    }
  }
  return changed;
}

std::string IntegratorLine(const SimulationResult& result,
                           const std::map<std::string, SettingValue>& implicit) {
  const std::vector<std::string> changed = ChangedOptions(result, implicit);
  if (changed.empty()) return result.integrator + " (all options at their defaults)";
  std::string line = result.integrator + " (";
  for (std::size_t i = 0; i < changed.size(); ++i) line += (i ? ", " : "") + changed[i];
  return line + "; other options at their defaults)";
}

nlohmann::json SummaryJson(const SimulationResult& report) {
  nlohmann::json summary;
  summary["scene"] = report.scene;
  summary["integrator"] = report.integrator;
  summary["options"] = OptionsJson(report);
  summary["status"] = report.status;
  summary["message"] = report.message;
  summary["t_final"] = report.final_time;
  nlohmann::json x_final = nlohmann::json::object();
  for (std::size_t i = 0; i < report.state_names.size(); ++i) {
    x_final[report.state_names[i]] = report.final_state[static_cast<Eigen::Index>(i)];
  }
  summary["x_final"] = x_final;
  nlohmann::json events = nlohmann::json::array();
  for (const Event& event : report.events) {
    events.push_back({{"t", event.t},
                      {"kind", ToString(event.kind)},
                      {"what", event.what},
                      {"detail", event.detail}});
  }
  summary["events"] = events;
  if (!report.relays.empty()) {
    nlohmann::json relays = nlohmann::json::array();
    for (const RelaySignal& relay : report.relays) {
      nlohmann::json jumps = nlohmann::json::array();
      for (std::size_t k = 0; k < relay.jump_times.size(); ++k) {
        jumps.push_back({{"t", relay.jump_times[k]}, {"w", relay.values[k]}});
      }
      relays.push_back({{"relay", relay.relay},
                        {"initial", relay.initial_value},
                        {"jumps", jumps},
                        {"final", relay.FinalValue()}});
    }
    summary["relays"] = relays;
  }
  // Counters as integers, the rest as numbers (declared in the integrator's StatSpec).
  const IntegratorSpec& spec = FindIntegrator(report.integrator);
  nlohmann::json stats = nlohmann::json::object();
  for (std::size_t i = 0; i < report.stats.size(); ++i) {
    const auto& [name, value] = report.stats[i];
    const bool count = i < spec.stats.size() && spec.stats[i].count;
    stats[name] = count ? nlohmann::json(static_cast<long>(value)) : NumberJson(value);
  }
  summary["stats"] = stats;
  summary["wall_seconds"] = NumberJson(report.wall_seconds);  // elapsed; stats: CPU time
  if (report.error_estimate) summary["error_estimate"] = NumberJson(*report.error_estimate);
  summary["warnings"] = report.warnings;
  if (!report.step_sequence.empty()) summary["step_sequence"] = report.step_sequence;
  // Sensitivities (options sensitivities, directions, adjoint_weights), matrices as rows over
  // theta = (x0, p, u per segment); the states at sample_times.
  auto rows = [](const Matrix& m) {
    nlohmann::json out = nlohmann::json::array();
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      nlohmann::json row = nlohmann::json::array();
      for (Eigen::Index j = 0; j < m.cols(); ++j) row.push_back(NumberJson(m(i, j)));
      out.push_back(row);
    }
    return out;
  };
  if (report.sensitivities) {
    const SimulationSensitivities& s = *report.sensitivities;
    nlohmann::json sensitivities = nlohmann::json::object();
    if (s.initial_state.size() > 0) {
      sensitivities["dx_dx0"] = rows(s.initial_state);
      sensitivities["dx_dp"] = rows(s.parameters);
      sensitivities["dx_du"] = rows(s.inputs);
    }
    if (s.directional.size() > 0) sensitivities["directional"] = rows(s.directional);
    if (s.adjoint.size() > 0) sensitivities["adjoint"] = rows(s.adjoint);
    summary["sensitivities"] = sensitivities;
  }
  if (!report.sample_states.empty()) {
    Matrix states(static_cast<Eigen::Index>(report.sample_states.size()),
                  report.final_state.size());
    for (std::size_t j = 0; j < report.sample_states.size(); ++j) {
      states.row(static_cast<Eigen::Index>(j)) = report.sample_states[j].transpose();
    }
    summary["sample_states"] = rows(states);
  }
  return summary;
}

void WriteSummaryJson(const SimulationResult& report, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << std::setw(2) << SummaryJson(report) << "\n";
}

void WriteViewJson(const Scene& scene, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << render::ViewJson(scene) << "\n";
}

bool RunGnuplot(const std::string& script_path, const std::string& image) {
  const std::string command = "gnuplot '" + script_path + "' 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return false;
  char buffer[256];
  while (fgets(buffer, sizeof buffer, pipe) != nullptr) {
  }
  const int code = pclose(pipe);
  return code == 0 && fs::exists(image);  // false: gnuplot missing or failed; the caller reports it
}

}  // namespace moreau::tool
