#pragma once
/// @file
/// The catalog of example scenes (the papers' systems and smooth test problems), used by
/// the command-line tool, the tests and the benchmarks. Target: moreau::scenes.

#include <functional>
#include <string>
#include <vector>

#include "moreau/model/scene.hpp"

namespace moreau {

/// A built-in scene: its name, a one-line summary and its factory.
struct SceneDefinition {
  std::string name;     ///< command-line name, e.g. "F1"
  std::string summary;  ///< one line for `moreau list`
  /// Makes the scene.
  std::function<Scene()> make;
};

/// All scenes, in the order `moreau list` shows them.
const std::vector<SceneDefinition>& SceneCatalog();
/// The scene with this name (case-sensitive). Scene families whose structure has options take
/// them after a colon as comma-separated KEY=VALUE pairs: "crowd:N=1000,seed=3"
/// (include/moreau/scenes/crowd.hpp, docs/crowd-motion.md); "crowd" is "crowd:" with the
/// defaults. Throws std::invalid_argument naming the unknown scene (listing the available
/// ones) or the bad option.
Scene MakeScene(const std::string& name);
/// The scene `moreau run` simulates when none is named (S3).
std::string DefaultSceneName();

}  // namespace moreau
