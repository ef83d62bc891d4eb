#pragma once
/// @file
/// The catalog of example scenes (the papers' systems and smooth test problems), used by
/// the command-line tool, the tests and the benchmarks. Target: moreau::scenes.

#include <functional>
#include <string>
#include <vector>

#include "moreau/model/scene.hpp"

namespace moreau {

struct SceneDefinition {
  std::string name;     ///< command-line name, e.g. "F1"
  std::string summary;  ///< one line for `moreau list`
  std::function<Scene()> make;
};

/// All scenes, in the order `moreau list` shows them.
const std::vector<SceneDefinition>& SceneCatalog();
/// The scene with this name (case-sensitive). Throws std::invalid_argument naming the
/// unknown scene and listing the available ones.
Scene MakeScene(const std::string& name);
/// The scene simulated by the README's first command.
std::string DefaultSceneName();

}  // namespace moreau
