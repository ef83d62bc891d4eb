#pragma once
/// @file
/// Switch events: what changed in a scene's nonsmooth state, and when.

#include <string>

namespace moreau {

/// What happened at an event.
enum class EventKind {
  kEnter,        ///< a constraint of a moving set (or a path constraint) became active, or a
                 ///< complementarity pair's w = 0 (a diode starts conducting)
  kLeave,        ///< a constraint of a moving set (or a path constraint) became inactive, or a
                 ///< complementarity pair's lambda = 0 (a diode blocks)
  kModeSwitch,   ///< the Filippov mode changed by crossing a switching surface
  kSlideStart,   ///< a sliding mode started on a switching surface
  kSlideEnd,     ///< a sliding mode ended
  kRelaySwitch,  ///< a hysteresis relay switched its memory state
  kAmbiguous,    ///< non-unique continuation; the documented (slow) solution was taken
};
/// The kind as text (as in summary.json: "enter", "leave", ...).
std::string ToString(EventKind kind);

/// A switch event.
struct Event {
  /// Time of the event (physical time).
  double t = 0.0;
  /// What happened.
  EventKind kind = EventKind::kEnter;
  std::string what;    ///< which constraint, mode or relay (e.g. "wall.c1")
  std::string detail;  ///< free text (e.g. "below -> above")
};

}  // namespace moreau
