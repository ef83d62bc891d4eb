// The crowd of 100 agents (issue 15 acceptance): FESD with sparse storage and the near-active
// constraint filter keeps every element certified (no overlap of any pair or wall, declared or
// not; complementarity residuals of every element), and the filter changes nothing: the same
// events and the same states as the run that assembles every declared constraint.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "moreau/integrators/fesd.hpp"
#include "moreau/scenes/crowd.hpp"

namespace moreau {
namespace {

// The bounds: overlap and complementarity residuals below 1e-9 at every element.
constexpr double kOverlapTolerance = 1e-9;
constexpr double kComplementarityTolerance = 1e-9;
// Filter on against off: "same events, states within 1e-10". The two runs solve systems with
// different unknowns (the left-out constraints' multipliers are identically zero in the full
// run), so Newton's iterates differ at round-off; measured 4e-12 on states and 3e-12 on event
// times over the whole default horizon (docs/sparse-systems.md).
constexpr double kFilterAgreement = 1e-10;
// Horizon: the first wall contacts form at t = 1.25 and pairs from about 1.5; by t = 2.6 the
// front rows press on the jambs and each other (tens of contact events) while the run stays
// short enough for the sanitizer preset.
constexpr double kHorizon = 2.6;

FesdResult RunCrowd(const Scene& scene, ConstraintFilter filter) {
  FesdOptions options;
  options.stages = 2;
  options.step_size = 0.05;
  options.record_stages = true;
  options.constraint_filter = filter;
  return SimulateFesd(scene, options);
}

TEST(CrowdLargeTest, HundredAgentsCertifiedAndTheFilterChangesNothing) {
  CrowdOptions crowd;
  crowd.agents = 100;
  crowd.final_time = kHorizon;
  const CrowdLayout layout = MakeCrowdLayout(crowd);
  const Scene scene = MakeCrowdScene(layout);
  const long declared = static_cast<long>(layout.pairs.size() + layout.walls.size());

  const FesdResult filtered = RunCrowd(scene, ConstraintFilter::kOn);
  const FesdResult full = RunCrowd(scene, ConstraintFilter::kOff);
  ASSERT_EQ(filtered.status, FesdStatus::kSuccess) << filtered.message;
  ASSERT_EQ(full.status, FesdStatus::kSuccess) << full.message;

  // The filter did leave constraints out (else this test compares a run with itself): at
  // most 372 of the 1050 declared constraints were in one system (measured).
  EXPECT_LT(filtered.stats.max_working_pairs, declared / 2);
  EXPECT_GT(filtered.stats.max_working_pairs, 0);

  int contacts = 0;
  for (const Event& event : filtered.events) {
    contacts += event.kind == EventKind::kEnter && event.what.rfind("contacts.", 0) == 0;
  }
  EXPECT_GE(contacts, 10) << "the horizon should form contacts between agents";

  for (const FesdResult* result : {&filtered, &full}) {
    const std::string what = result == &filtered ? "filter on" : "filter off";
    for (const FesdElement& element : result->elements) {
      ASSERT_LE(element.complementarity, kComplementarityTolerance)
          << what << ", element at t " << element.t_start;
      ASSERT_LE(element.cross_complementarity, kComplementarityTolerance)
          << what << ", element at t " << element.t_start;
    }
    for (const Trajectory* trajectory : {&result->trajectory, &result->stage_trajectory}) {
      ASSERT_GT(trajectory->size(), 0u);
      for (std::size_t k = 0; k < trajectory->size(); ++k) {
        const CrowdCertificate c = CertifyCrowdState(layout, trajectory->x[k]);
        ASSERT_TRUE(c.Feasible(kOverlapTolerance))
            << what << " t " << trajectory->t[k] << ": " << c.Summary();
        ASSERT_TRUE(c.ListsSufficed()) << what << " t " << trajectory->t[k] << ": " << c.Summary();
      }
    }
  }

  ASSERT_EQ(filtered.events.size(), full.events.size());
  for (std::size_t k = 0; k < full.events.size(); ++k) {
    EXPECT_EQ(filtered.events[k].what, full.events[k].what) << "event " << k;
    EXPECT_EQ(filtered.events[k].kind, full.events[k].kind) << "event " << k;
    EXPECT_NEAR(filtered.events[k].t, full.events[k].t, kFilterAgreement) << "event " << k;
  }
  ASSERT_EQ(filtered.trajectory.size(), full.trajectory.size());
  for (std::size_t k = 0; k < full.trajectory.size(); ++k) {
    ASSERT_NEAR(filtered.trajectory.t[k], full.trajectory.t[k], kFilterAgreement);
    ASSERT_LE((filtered.trajectory.x[k] - full.trajectory.x[k]).lpNorm<Eigen::Infinity>(),
              kFilterAgreement)
        << "t " << full.trajectory.t[k];
  }
}

}  // namespace
}  // namespace moreau
