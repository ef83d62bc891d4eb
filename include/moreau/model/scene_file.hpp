#pragma once
/// @file
/// Scene files: a Scene written in TOML, its model functions as expressions with exact
/// derivatives (moreau/model/expression.hpp). The format is documented line by line in
/// docs/scene-files.md; examples/scenes/*.toml hold the reference problems.
///
/// Every problem in a file is reported as std::invalid_argument
/// "<file>:<line>:<column>: <what> (<key path>)", with what was expected and what was found:
/// TOML syntax, missing or unknown keys (with the closest valid key), wrong types and vector
/// lengths, unknown names in expressions (with the closest valid name), defs that refer to
/// themselves, duplicate names, nonsmooth functions, and the scene checks of ValidateScene
/// (non-finite values at x0, x0 outside a moving set, ...).

#include <string>

#include "moreau/model/scene.hpp"

namespace moreau {

/// Reads and parses a scene file. Throws std::invalid_argument (see file comment), also when
/// the file cannot be read.
Scene LoadScene(const std::string& path);

/// Parses scene-file text; `source_name` names it in messages.
Scene ParseScene(const std::string& text, const std::string& source_name = "<string>");

/// True if `argument` names a scene file rather than a built-in scene: it ends in ".toml", or
/// it is a path (contains '/') to an existing file.
bool IsSceneFile(const std::string& argument);

}  // namespace moreau
