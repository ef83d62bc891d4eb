#include "lowered_block.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {

std::unique_ptr<LoweredBlock> LowerEffect(const Scene& scene, const Effect& effect,
                                          const LoweringOptions& options) {
  if (const auto* set = std::get_if<MovingSet>(&effect)) return LowerMovingSet(scene, *set);
  if (const auto* switching = std::get_if<SwitchingSurfaces>(&effect)) {
    return options.switching_form == SwitchingForm::kStewart ? LowerStewart(scene, *switching)
                                                             : LowerHeaviside(scene, *switching);
  }
  if (const auto* complementarity = std::get_if<Complementarity>(&effect)) {
    return LowerComplementarity(scene, *complementarity);
  }
  // Path constraints belong to the DAI stepper; hysteresis relays are lowered together, by
  // LowerHysteresis, because their clock rates multiply.
  MOREAU_ASSERT(std::holds_alternative<PathConstraints>(effect) ||
                    std::holds_alternative<HysteresisRelay>(effect),
                "LowerEffect: unknown effect type");
  return nullptr;
}

}  // namespace moreau::internal
