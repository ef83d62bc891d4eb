#include "moreau/model/events.hpp"

namespace moreau {

std::string ToString(EventKind kind) {
  switch (kind) {
    case EventKind::kEnter:
      return "enter";
    case EventKind::kLeave:
      return "leave";
    case EventKind::kModeSwitch:
      return "mode_switch";
    case EventKind::kSlideStart:
      return "slide_start";
    case EventKind::kSlideEnd:
      return "slide_end";
    case EventKind::kRelaySwitch:
      return "relay_switch";
    case EventKind::kAmbiguous:
      return "ambiguous";
  }
  return "?";
}

}  // namespace moreau
