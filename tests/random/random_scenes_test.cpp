// Differential testing (docs/differential-testing.md): random scenes run with the default
// settings against an independent reference. The campaign of 10^4 scenes is
// scripts/bench-random-scenes; here a fixed set of seeds, every one of which must agree with
// its reference or say why not (a status, or a warning where it is off the reference).
#include "random_scenes.hpp"

#include <gtest/gtest.h>

#include <map>

namespace moreau::testing {
namespace {

// Scenes per run: 100 in release; under the sanitizers (about 20 times slower) a fifth of them,
// so that the test stays within seconds there too.
constexpr int kScenes = MOREAU_SANITIZED ? 20 : 100;

TEST(RandomScenesTest, DefaultsAgreeWithTheReferenceOrSaySo) {
  std::map<Verdict, int> counts;
  for (std::uint64_t seed = 1; seed <= kScenes; ++seed) {
    const RandomScene scene = GenerateRandomScene(seed);
    const Comparison comparison = CompareWithReference(scene);
    ++counts[comparison.verdict];
    EXPECT_NE(comparison.verdict, Verdict::kSilentDisagreement)
        << "seed " << seed << " (" << scene.families << "): " << comparison.detail << "\n"
        << scene.toml;
    EXPECT_NE(comparison.verdict, Verdict::kNoReference)
        << "seed " << seed << " (" << scene.families << "): " << comparison.detail << "\n"
        << scene.toml;
  }
  // The scenes are well posed with unique solutions: every one should agree, and a status is
  // honest but still a defect of the defaults. Measured with seeds 1..100: 99 agree, 1 ends
  // with a status (seed 69: step_size_too_small, on a time scale of 1e-6 s). Before the dense
  // LU's singularity test and the velocity level's acceptance took the sizes of their unknowns
  // and terms into account, and before a zero-length piece stopped proposing a step of zero,
  // 22 ended with a status. Their number must not grow (the sanitizer run takes seeds 1..20,
  // all of which agree).
  constexpr int kMeasuredHonestFailures = MOREAU_SANITIZED ? 0 : 1;
  EXPECT_LE(counts[Verdict::kHonestFailure], kMeasuredHonestFailures)
      << counts[Verdict::kAgree] << " of " << kScenes << " agree";
}

// The campaign's findings, each of which must agree (not only end with a status): a stop released
// for a window between two stages of a long step (seeds 1240 and 5312: the run stayed on the stop
// with success until the jump free sides were sampled between the stages); a disc brushing a point
// for 1 ms inside a 0.14 s step (seed 4913: the switch group landed on the contact's exit zero, the
// side at zero at the element's end was not searched, and the point was never pushed); a
// relay and a brush on a time scale of 8e-6 s (seed 12: the velocity level's Newton stalled at
// the round-off of its rows' terms, 1e-12, just above its tolerance relative to the guess's
// sizes, and the run ended with event_location_failure); a brush on a time scale of 7e-6 s
// (seed 136: a switch decided at a step's start left a piece of zero length, whose proposal of
// a zero step made every later attempt an element of length zero).
TEST(RandomScenesTest, CampaignFindingsAgree) {
  for (std::uint64_t seed : {1240ULL, 5312ULL, 4913ULL, 12ULL, 136ULL}) {
    const RandomScene scene = GenerateRandomScene(seed);
    const Comparison comparison = CompareWithReference(scene);
    EXPECT_EQ(comparison.verdict, Verdict::kAgree)
        << "seed " << seed << " (" << scene.families << "): " << comparison.detail << "\n"
        << scene.toml;
  }
}

// A switch decided again and again at the same time (seed 735, a brush beside a floor on a
// time scale of 1.6e-5 s) ends the run at once with a status, instead of 10^5 steps of zero
// length up to max_steps (what the zero-length step proposal alone did); agreeing is better.
TEST(RandomScenesTest, SwitchesWithoutProgressEndAtOnce) {
  const RandomScene scene = GenerateRandomScene(735);
  const Comparison comparison = CompareWithReference(scene);
  if (comparison.verdict == Verdict::kAgree) return;
  EXPECT_EQ(comparison.verdict, Verdict::kHonestFailure) << comparison.detail;
  EXPECT_NE(comparison.detail.find("without the time moving"), std::string::npos)
      << comparison.detail;
}

TEST(RandomScenesTest, ScenesAreReproducibleFromTheirSeed) {
  for (std::uint64_t seed : {1ULL, 7ULL, 12345ULL}) {
    EXPECT_EQ(GenerateRandomScene(seed).toml, GenerateRandomScene(seed).toml);
  }
  EXPECT_NE(GenerateRandomScene(1).toml, GenerateRandomScene(2).toml);
}

}  // namespace
}  // namespace moreau::testing
