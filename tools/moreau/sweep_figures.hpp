#pragma once
// The figures of `moreau sweep` (gnuplot), one point per run and never the run index as an
// axis: for each varied value, vs_<name>.png with every final state, the event count and the
// first event time against it; for sampled sweeps, histograms.png; for two grids (nothing
// sampled), heatmap_<quantity>.png drawn on the grid itself. Failed runs are red crosses
// (and red ticks on the bottom axis);
// a quantity that is the same in every run is titled "(constant: v)" with a range that does
// not magnify round-off.

#include <string>
#include <vector>

#include "moreau/ensemble/sweep.hpp"

namespace moreau::tool {

// Writes the figures into `dir` and returns the images written.
std::vector<std::string> SweepFigures(const SweepResult& result, const SweepSpec& spec,
                                      const std::string& dir);

}  // namespace moreau::tool
