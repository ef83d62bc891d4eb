#pragma once
// `moreau sweep SCENE|FILE`: parameter grids and Monte Carlo over the scene's named values on a
// thread pool (moreau::RunSweep), with a progress bar, a CSV table and summary plots.

#include <string>
#include <vector>

#include "moreau/ensemble/sweep.hpp"

namespace moreau::tool {

struct SweepCommandSettings {
  std::vector<std::string> grids;    // "name=start:stop:count"
  std::vector<std::string> samples;  // "name=normal:mean:std", "name=uniform:a:b"
  long num_samples = 0;
  unsigned long seed = 0;
  int jobs = 0;  // 0: all cores
  int event_times = 5;
  SimulationSettings simulation;
  std::string out_directory;  // empty: out/sweep/<scene>
  bool plot = true;
  bool quiet = false;
};

// Runs the sweep and writes DIR/sweep.csv (a row per run), DIR/summary.json (the spec, runs
// by status, wall time, runs per second) and, with gnuplot, the figures of sweep_figures.hpp.
// Returns 0 if every run succeeded, 1 otherwise (the rows say which).
int RunSweepCommand(const Scene& scene, const SweepCommandSettings& settings);

}  // namespace moreau::tool
