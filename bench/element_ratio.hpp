#pragma once
// The FESD element against smooth Radau IIA elements, shared by the benchmarks that compare
// them (fesd_bench.cpp: CPU time; element_cost.cpp: instructions under callgrind).
#include <stdexcept>
#include <variant>

#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/model/scene.hpp"

namespace moreau::bench {

// The smooth part of a reference scene: its dynamics without effects (S3: the rotation x' =
// (x2, -x1) without the floor), or for a switching system the vector field of the region
// that contains x0 (F1: x' = A2 x, the field inside the unit circle). Same states, horizon and
// initial state, so that its Radau IIA elements have the size of the scene's FESD elements
// (n_y states including the clock, s stages) and the same vector fields.
inline moreau::Scene SmoothPart(const moreau::Scene& scene) {
  moreau::Scene smooth = scene;
  smooth.name = scene.name + "-smooth";
  smooth.effects.clear();
  for (const moreau::Effect& effect : scene.effects) {
    const auto* switching = std::get_if<moreau::SwitchingSurfaces>(&effect);
    if (switching == nullptr) continue;
    if (!scene.dynamics.empty()) throw std::invalid_argument("SmoothPart: dynamics and modes");
    moreau::Vector c;
    switching->surfaces.Evaluate(scene.initial_state, scene.InputValues(scene.initial_time),
                                 scene.initial_time, scene.ParameterValues(), &c);
    int mode = 0;  // bit j set: c_j > 0 (lower_switching.cpp)
    for (int j = 0; j < c.size(); ++j) mode |= c[j] > 0.0 ? 1 << j : 0;
    smooth.dynamics = switching->modes[static_cast<std::size_t>(mode)];
  }
  return smooth;
}

// The options of BM_FesdElementRatio and BM_FesdRunCost: FESD with h = 0.1 and N_fe = 2 beside
// Radau IIA with steps of 0.05 (the FESD elements' nominal length), s stages both.
struct PairedOptions {
  moreau::FesdOptions fesd;
  moreau::RadauOptions radau;
};
inline PairedOptions ElementRatioOptions(int stages) {
  PairedOptions options;
  options.fesd.stages = stages;
  options.fesd.step_size = 0.1;
  options.fesd.finite_elements = 2;
  options.fesd.record_trajectory = false;
  // Element against element: neither run makes its fixed-step error estimate (on by default
  // in both: FESD's extra solves per step, Radau's embedded estimate with one more LU per step).
  options.fesd.estimate_error = false;
  options.radau.stages = stages;
  options.radau.step_size = options.fesd.step_size / options.fesd.finite_elements;
  options.radau.record_trajectory = false;
  options.radau.estimate_error = false;
  return options;
}

}  // namespace moreau::bench
