// The wave-rider comparison of the sweeping-process FESD paper (Sec. VI-A, Fig. 5): solve the
// wave-rider OCP with N control stages, discretized by FESD or by the standard time-stepping
// scheme with s = 1..4 Radau IIA stages, re-simulate the optimal controls with IDA at
// rtol = 1e-12 and report the terminal error |x(T) - (1, 4)|_2 of that simulation.
//
//   ocp_wave_rider [OUT_DIR] [--N 5,10,25,50] [--stages 1,2,3,4] [--fe 3]
//
// Writes OUT_DIR/ocp_wave_rider.csv and OUT_DIR/ocp_wave_rider.md (default OUT_DIR:
// out/bench). Opt-in (scripts/bench-ocp); never part of the tests.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "moreau/ocp/catalog.hpp"

namespace {

std::vector<int> ParseList(const std::string& text) {
  std::vector<int> values;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) values.push_back(std::stoi(item));
  return values;
}

struct Row {
  std::string integrator;
  int stages = 0, intervals = 0;
  std::string status;
  double objective = 0.0, terminal_error = 0.0, cpu_seconds = 0.0;
  int iterations = 0;
  bool verified = false;
};

}  // namespace

int main(int argc, char** argv) {
  using namespace moreau;
  std::string out_directory = "out/bench";
  std::vector<int> intervals = {5, 10, 25, 50}, stages = {1, 2, 3, 4};
  int finite_elements = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if ((arg == "--N" || arg == "--stages" || arg == "--fe") && i + 1 < argc) {
      const std::string value = argv[++i];
      if (arg == "--N") intervals = ParseList(value);
      if (arg == "--stages") stages = ParseList(value);
      if (arg == "--fe") finite_elements = std::stoi(value);
    } else if (!arg.empty() && arg[0] != '-') {
      out_directory = arg;
    } else {
      std::fprintf(stderr,
                   "usage: ocp_wave_rider [OUT_DIR] [--N 5,10,25,50] [--stages 1,2,3,4] "
                   "[--fe 3]\n(unknown or incomplete option '%s')\n",
                   arg.c_str());
      return 2;
    }
  }
  std::filesystem::create_directories(out_directory);
  const Vector target{{1.0, 4.0}};
  std::vector<Row> rows;
  const auto start = std::chrono::steady_clock::now();
  for (const OcpIntegrator integrator : {OcpIntegrator::kFesd, OcpIntegrator::kTimeStepping}) {
    for (int s : stages) {
      for (int n : intervals) {
        OcpProblem problem = MakeOcpProblem("wave_rider");
        problem.intervals = n;
        OcpOptions options = MakeOcpOptions("wave_rider");
        options.integrator = integrator;
        options.stages = s;
        options.finite_elements = finite_elements;
        options.max_iterations = 3000;
        const OcpResult result = SolveOcp(problem, options);
        Row row;
        row.integrator = ToString(integrator);
        row.stages = s;
        row.intervals = n;
        row.status = ToString(result.status);
        row.objective = result.objective;
        row.iterations = result.stats.iterations;
        row.cpu_seconds = result.stats.cpu_seconds;
        row.verified = result.verified;
        row.terminal_error =
            result.verified ? (result.resimulated_final_state - target).norm() : -1.0;
        rows.push_back(row);
        std::fprintf(
            stderr, "[%6.1f s] %-12s s = %d N = %2d: %-26s terminal error %.3g (%d its)\n",
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
            row.integrator.c_str(), s, n, row.status.c_str(), row.terminal_error, row.iterations);
      }
    }
  }

  std::ofstream csv(out_directory + "/ocp_wave_rider.csv");
  csv << "integrator,stages,N,N_fe,status,objective,ipopt_iterations,cpu_seconds,"
         "resimulated_terminal_error\n";
  csv.precision(10);
  for (const Row& row : rows) {
    csv << row.integrator << "," << row.stages << "," << row.intervals << "," << finite_elements
        << "," << row.status << "," << row.objective << "," << row.iterations << ","
        << row.cpu_seconds << "," << row.terminal_error << "\n";
  }

  // Markdown: terminal error |x_IDA(T) - (1, 4)|_2, one row per discretization, one column
  // per N; a status other than solved is marked.
  std::ofstream md(out_directory + "/ocp_wave_rider.md");
  md << "Wave-rider OCP: terminal error |x(T) - (1, 4)|_2 of the optimal controls re-simulated "
        "by IDA (rtol 1e-12), N_fe = "
     << finite_elements << " elements (FESD) or steps (time-stepping) per control interval.\n\n";
  md << "| discretization |";
  for (int n : intervals) md << " N = " << n << " |";
  md << "\n|---|";
  for (std::size_t i = 0; i < intervals.size(); ++i) md << "---|";
  md << "\n";
  for (const OcpIntegrator integrator : {OcpIntegrator::kFesd, OcpIntegrator::kTimeStepping}) {
    for (int s : stages) {
      md << "| " << ToString(integrator) << " s = " << s << " |";
      for (int n : intervals) {
        for (const Row& row : rows) {
          if (row.integrator != ToString(integrator) || row.stages != s || row.intervals != n) {
            continue;
          }
          char cell[64];
          if (!row.verified) {
            std::snprintf(cell, sizeof cell, " not verified (%s) |", row.status.c_str());
          } else {
            std::snprintf(cell, sizeof cell, " %.2e%s |", row.terminal_error,
                          row.status == "solved" ? "" : "*");
          }
          md << cell;
        }
      }
      md << "\n";
    }
  }
  md << "\n\\* IPOPT status other than solved (see the CSV).\n";
  std::printf("wrote %s/ocp_wave_rider.csv and %s/ocp_wave_rider.md\n", out_directory.c_str(),
              out_directory.c_str());
  return 0;
}
