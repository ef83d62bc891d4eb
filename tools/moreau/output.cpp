#include "output.hpp"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "moreau/core/error.hpp"

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

void WriteElementsCsv(const RunReport& report, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  for (std::size_t i = 0; i < report.element_columns.size(); ++i) {
    out << (i ? "," : "") << report.element_columns[i];
  }
  out << "\n" << std::setprecision(17);
  for (const std::vector<double>& row : report.element_rows) {
    for (std::size_t i = 0; i < row.size(); ++i) out << (i ? "," : "") << row[i];
    out << "\n";
  }
}

nlohmann::json SummaryJson(const RunReport& report) {
  nlohmann::json summary;
  summary["scene"] = report.scene;
  summary["integrator"] = report.integrator;
  summary["options"] = report.options;
  summary["status"] = report.status;
  summary["message"] = report.message;
  summary["t_final"] = report.final_time;
  nlohmann::json x_final = nlohmann::json::object();
  for (std::size_t i = 0; i < report.trajectory.state_names.size(); ++i) {
    x_final[report.trajectory.state_names[i]] = report.final_state[static_cast<Eigen::Index>(i)];
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
  summary["stats"] = report.stats;
  return summary;
}

void WriteSummaryJson(const RunReport& report, const std::string& path) {
  std::ofstream out(path);
  RequireArgument(out.good(), "cannot write '", path, "'");
  out << std::setw(2) << SummaryJson(report) << "\n";
}

std::string WritePlot(const RunReport& report, const std::string& directory) {
  const std::string csv = directory + "/trajectory.csv";
  const std::string image = directory + "/trajectory.png";
  const std::string script_path = directory + "/plot.gp";
  std::ofstream script(script_path);
  RequireArgument(script.good(), "cannot write '", script_path, "'");
  const auto& names = report.trajectory.state_names;
  const std::size_t shown = std::min<std::size_t>(names.size(), kMaxPlottedStates);
  script << "set terminal pngcairo size 1000,600 noenhanced\n"
         << "set output '" << image << "'\n"
         << "set datafile separator ','\n"
         << "set key outside right top\n"
         << "set grid\n"
         << "set xlabel 't'\n"
         << "set title '" << report.scene << " (" << report.integrator << ", " << report.status
         << (shown < names.size() ? ", first " + std::to_string(shown) + " states" : "") << ")'\n";
  for (const Event& event : report.events) {
    script << "set arrow from " << std::setprecision(17) << event.t << ", graph 0 to " << event.t
           << ", graph 1 nohead dashtype 2 lc rgb '#999999'\n";
  }
  script << "plot ";
  for (std::size_t i = 0; i < shown; ++i) {
    script << (i ? ", " : "") << "'" << csv << "' using 1:" << i + 2 << " with lines lw 2 title '"
           << names[i] << "'";
  }
  script << "\n";
  script.close();
  const std::string command = "gnuplot '" + script_path + "' 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  std::string output;
  if (pipe != nullptr) {
    char buffer[256];
    while (fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
    const int code = pclose(pipe);
    if (code == 0 && fs::exists(image)) return image;
  }
  return "";  // no plot (gnuplot missing or failed); the caller reports it
}

}  // namespace moreau::tool
