#pragma once
// `moreau animate RUN_DIR` and `moreau run ... --animate`: frames of a planar scene (its view)
// from the trajectory of a run (or of an optimal control solution of `moreau ocp`), written as DIR/animation.mp4, DIR/animation.gif and
// DIR/snapshots/snapshot_<k>_t<time>.png at event times (render/animation.hpp).

#include <CLI/CLI.hpp>
#include <string>

#include "moreau/integrators/simulate.hpp"
#include "render/animation.hpp"

namespace moreau::tool {

struct AnimateSettings {
  render::AnimationOptions options;  // paths are filled in from the run directory
  bool mp4 = true;
  bool gif = true;
  bool quiet = false;
};

// Adds --fps, --duration, --speed, --width, --gif-width, --snapshots, --no-mp4, --no-gif,
// --frames DIR to a subcommand.
void AddAnimateOptions(CLI::App* command, AnimateSettings* settings);

// Animates a run directory written by `moreau run` (view.json, summary.json and stages.csv or
// trajectory.csv, streamed). Returns 0, or throws std::invalid_argument / std::runtime_error.
int RunAnimateCommand(const std::string& run_directory, AnimateSettings settings);

// Animates a simulation just run (its trajectory in memory) into `directory`; prints the files.
void AnimateResult(const Scene& scene, const SimulationResult& result, const std::string& directory,
                   AnimateSettings settings);

}  // namespace moreau::tool
