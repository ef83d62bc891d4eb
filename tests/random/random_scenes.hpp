#pragma once
// Differential testing (docs/differential-testing.md): random scenes, each run with the
// default settings and compared with an independent reference. Shared by the test suite
// (tests/random/random_scenes_test.cpp, 100 fixed seeds) and the campaign program
// (bench/random_scenes.cpp, scripts/bench-random-scenes).
//
// A scene is written as a scene file (expression language, docs/scene-files.md) and parsed, so
// that every scene of a campaign can be printed and rerun with `moreau run`. Its time axis is
// scaled by tau = 10^U(-6, 3): every rate is (1/tau) times a rate in the dimensionless time
// s = t/tau, on a horizon of 2 .. 8 units of s. The final state is therefore independent of
// tau, and so is what an integrator has to resolve; only the numbers it sees change. States are
// of order one. Each scene has smooth, stable dynamics (linear damping, coupling, forcing and a
// mild quadratic term) and one or two effects, each on states of its own:
//   pulse     a switching surface in time, exp(-((s - s0)/w)^2) - 1/2, whose upper side adds a
//             rate to one state only while the pulse is up (w = 10^U(-3, -1): down to a
//             thousandth of the horizon, narrower than any default step);
//   sliding   a switching surface x_i = b whose two fields push x_i towards it (attractive
//             sliding: a unique Filippov solution);
//   floor     a moving set x_i >= h sin(om s) + b that x_i drifts onto (sweeping process);
//   brush     a disc of radius R = 10^U(-3, -1) sweeping at unit speed past a point at rest
//             that it grazes (the point moves only while the disc pushes it);
//   diode     an index-1 complementarity pair (rectifier: 0 <= lambda _|_ x_i - E sin(om s) +
//             r lambda >= 0 with r > 0, a P-matrix: a unique multiplier);
//   stop      an index-2 complementarity pair x_i >= b (lambda pushes x_i up);
//   relay     a hysteresis relay on x_i with thresholds +-theta whose modes drive x_i up and
//             down (a thermostat).
// These families are the switch types the integrators handle (switching surfaces, moving sets,
// complementarity systems of both indices, relays) with solutions that are unique, so that
// two correct integrators must agree.
//
// The reference is IDA at rtol 1e-10, atol 1e-12, with its step bounded by 1/200 of the horizon
// and stop times inside every pulse and at every brush's closest approach: it is another
// method (BDF with root finding) and it does not rely on the bounds of the event indicators to
// see what the scene hides inside a step. Where it fails, fixed-step FESD on a fine grid with
// the same stop times is the reference.

#include <cstdint>
#include <string>
#include <vector>

#include "moreau/integrators/simulate.hpp"
#include "moreau/model/scene.hpp"

namespace moreau::testing {

struct RandomScene {
  std::uint64_t seed = 0;
  std::string toml;  // the scene file (ParseScene gives `scene`)
  Scene scene;
  std::string families;     // the effects, e.g. "pulse+floor"
  double time_scale = 1.0;  // tau
  // For the reference: times inside every pulse and at every brush's closest approach, and
  // the largest step that resolves the scene's features.
  std::vector<double> stop_times;
  double reference_max_step = 0.0;
};

// The scene of `seed` (deterministic on every platform: its own generator and uniform numbers).
RandomScene GenerateRandomScene(std::uint64_t seed);

// What a user runs who gives no option: the only place the campaign spells its defaults.
SimulationSettings DefaultSettings();
// The reference's settings for `scene` (see the file comment); fine = true for the fallback
// (fixed-step FESD on a fine grid).
SimulationSettings ReferenceSettings(const RandomScene& scene, bool fine_fesd);

enum class Verdict {
  kAgree,               // success, final state within kAgreement of the reference
  kHonestFailure,       // not a success (a status with its reason), or off the reference with
                        // a warning that says it may be
  kSilentDisagreement,  // success without a warning, final state off the reference
  kNoReference,         // no reference could be computed (not counted against the defaults)
};
std::string ToString(Verdict verdict);

// Agreement of the final states: max_i |x_i - x_ref,i| / (1 + |x_ref,i|) below this. The
// default tolerances ask for a global error of about rtol = 1e-6 relative to the solution's
// scale (docs/fesd-formulation.md, section 10); the scenes are stable, so a factor 100 covers
// the error growth, while a missed pulse, brush, contact or switch moves the final state by
// at least the pulse's effect, 10^-3 k and more.
inline constexpr double kAgreement = 1e-4;

struct Comparison {
  Verdict verdict = Verdict::kAgree;
  double error = 0.0;  // the relative final-state difference (when both succeeded)
  std::string detail;  // statuses, warnings, states (for reports)
};

// Runs the scene with DefaultSettings() and against its reference.
Comparison CompareWithReference(const RandomScene& scene);

}  // namespace moreau::testing
