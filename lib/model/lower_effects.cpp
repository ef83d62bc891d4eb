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
  if (std::holds_alternative<PathConstraints>(effect)) return nullptr;  // DAI stepper only
  ThrowInvalidArgument("scene '", scene.name, "': the ", EffectKind(effect), " '",
                       EffectName(effect),
                       "' has no complementarity lowering in this version (time-freezing for "
                       "hysteresis relays is not implemented yet)");
}

}  // namespace moreau::internal
