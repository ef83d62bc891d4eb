// Determinism (issue 9): two runs of every catalog scene with the integrator `moreau run`
// picks by default (radau without effects, alpha for path constraints, fesd otherwise) give
// bit-identical results: status, message, final time and state, every trajectory point and
// every event.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>

#include "moreau/integrators/alpha_dai.hpp"
#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/radau.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Horizon of the determinism runs: the scene's own, shortened so that every scene costs at
// most a fraction of a second (determinism does not depend on the horizon length).
constexpr double kMaxHorizon = 1.0;

struct Fingerprint {
  std::string status, message;
  double final_time = 0.0;
  Vector final_state;
  Trajectory trajectory;
  std::vector<Event> events;
};

Fingerprint RunDefault(const Scene& scene) {
  Fingerprint f;
  if (scene.effects.empty()) {
    const RadauResult r = SimulateRadau(scene, RadauOptions{});
    f = {ToString(r.status), r.message, r.final_time, r.final_state, r.trajectory, {}};
  } else if (scene.Has<PathConstraints>()) {
    const AlphaDaiResult r = SimulateAlphaDai(scene, AlphaDaiOptions{});
    f = {ToString(r.status), r.message, r.final_time, r.final_state, r.trajectory, r.events};
  } else {
    const FesdResult r = SimulateFesd(scene, FesdOptions{});
    f = {ToString(r.status), r.message, r.final_time, r.final_state, r.trajectory, r.events};
  }
  return f;
}

// Bitwise equality of two vectors (distinguishes -0.0 from 0.0 and compares NaN payloads).
bool BitEqual(const Vector& a, const Vector& b) {
  if (a.size() != b.size()) return false;
  if (a.size() == 0) return true;  // empty vectors may have null data (memcmp needs pointers)
  return std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}
bool BitEqual(double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; }

class DeterminismTest : public ::testing::TestWithParam<std::string> {};

// Scenes whose default size makes two runs cost minutes with dense derivatives: their family's
// small member has the same structure (the crowd: 100 agents, 572 constraints; 9 agents here).
std::string DeterminismVariant(const std::string& name) {
  return name == "crowd" ? "crowd:N=9" : name;
}

TEST_P(DeterminismTest, TwoRunsAreBitIdentical) {
  Scene scene = MakeScene(DeterminismVariant(GetParam()));
  scene.final_time = std::min(scene.final_time, scene.initial_time + kMaxHorizon);
  const Fingerprint first = RunDefault(scene);
  const Fingerprint second = RunDefault(scene);
  EXPECT_EQ(first.status, second.status);
  EXPECT_EQ(first.message, second.message);
  EXPECT_TRUE(BitEqual(first.final_time, second.final_time));
  EXPECT_TRUE(BitEqual(first.final_state, second.final_state));
  ASSERT_EQ(first.trajectory.size(), second.trajectory.size());
  EXPECT_GE(first.trajectory.size(), 1u);  // runs that stop at t0 (a status) count too
  for (std::size_t k = 0; k < first.trajectory.size(); ++k) {
    ASSERT_TRUE(BitEqual(first.trajectory.t[k], second.trajectory.t[k])) << "point " << k;
    ASSERT_TRUE(BitEqual(first.trajectory.x[k], second.trajectory.x[k])) << "point " << k;
    ASSERT_TRUE(BitEqual(first.trajectory.algebraic[k], second.trajectory.algebraic[k]))
        << "point " << k;
    ASSERT_TRUE(BitEqual(first.trajectory.step[k], second.trajectory.step[k])) << "point " << k;
  }
  ASSERT_EQ(first.events.size(), second.events.size());
  for (std::size_t k = 0; k < first.events.size(); ++k) {
    EXPECT_TRUE(BitEqual(first.events[k].t, second.events[k].t)) << "event " << k;
    EXPECT_EQ(first.events[k].what, second.events[k].what) << "event " << k;
    EXPECT_EQ(first.events[k].detail, second.events[k].detail) << "event " << k;
  }
}

std::vector<std::string> CatalogNames() {
  std::vector<std::string> names;
  for (const SceneDefinition& definition : SceneCatalog()) names.push_back(definition.name);
  return names;
}

INSTANTIATE_TEST_SUITE_P(Catalog, DeterminismTest, ::testing::ValuesIn(CatalogNames()),
                         [](const auto& test_info) { return test_info.param; });

}  // namespace
}  // namespace moreau
