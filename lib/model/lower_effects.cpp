#include "lowered_block.hpp"
#include "moreau/core/error.hpp"

namespace moreau::internal {

std::unique_ptr<LoweredBlock> LowerEffect(const Scene& scene, const Effect& effect,
                                          const LoweringOptions& /*options*/) {
  if (std::holds_alternative<PathConstraints>(effect)) return nullptr;  // DAI stepper only
  ThrowInvalidArgument("scene '", scene.name, "': the ", EffectKind(effect), " '",
                       EffectName(effect), "' cannot be lowered to complementarity form yet");
}

}  // namespace moreau::internal
