#pragma once
// `moreau check SCENE|FILE`: validate a scene (a scene file's every error names file:line:column)
// and print the sizes of its lowered system without simulating.

#include "moreau/model/scene.hpp"

namespace moreau::tool {

// A built-in scene name or a scene file (moreau::IsSceneFile) as a Scene.
Scene ResolveScene(const std::string& argument);

// Prints states, inputs, parameters, effects, the lowered DCS's sizes (only the parts it has:
// states with relay memories and clock, algebraic unknowns, equations, complementarity pairs),
// the unknowns of a
// FESD element for `stages` (and what a group with the event equation adds), and which
// integrators support the scene. Throws std::invalid_argument for an invalid scene.
void CheckScene(const Scene& scene, int stages);

}  // namespace moreau::tool
