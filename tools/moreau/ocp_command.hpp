#pragma once
// `moreau ocp <problem>`: solve an example optimal control problem (examples/ocp) and write
// its solution (docs/ocp.md).

#include <functional>
#include <string>
#include <vector>

#include "moreau/ocp/ocp.hpp"

namespace moreau::tool {

struct OcpCommandSettings {
  std::string problem;
  bool intervals_given = false;  ///< false: the problem's own N
  int intervals = 0;
  /// Command-line flags, applied in order to the problem's options (MakeOcpOptions).
  std::vector<std::function<void(OcpOptions*)>> overrides;
  std::string out_directory;  ///< empty: out/ocp/<problem>
  bool plot = true;
  bool quiet = false;
};

// Solves and writes DIR/trajectory.csv (FESD at the optimum, physical time), controls.csv
// (one row per interval: t_start, t_end, controls, speed of time), iterations.csv (IPOPT log),
// summary.json and, with gnuplot, solution.png. Prints a summary. Returns the exit code: 0
// solved (also to acceptable tolerances), 1 any other status. Throws std::invalid_argument
// for an unknown problem or invalid options.
int RunOcpCommand(const OcpCommandSettings& settings);

// Homotopy levels from "MU:EPS[:SIGMA][:NAME=VALUE...],..." (smoothing, terminal relaxation) or
// "none". Throws std::invalid_argument naming the bad entry.
std::vector<OcpHomotopyLevel> ParseHomotopy(const std::string& text);
// Interval counts from "N1,N2,..." (--mesh-continuation) or "none". Throws
// std::invalid_argument.
std::vector<int> ParseIntervalCounts(const std::string& text);

// The summary lines of `moreau list` for the optimal control problems.
void ListOcpProblems();

}  // namespace moreau::tool
