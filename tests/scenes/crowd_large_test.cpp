// The crowd of 100 agents (issue 15 acceptance): FESD with sparse storage and the near-active
// constraint filter keeps every element certified (no overlap of any pair or wall, declared or
// not; complementarity residuals of every element), and the filter changes nothing: the same
// events and the same states as the run that assembles every declared constraint.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "moreau/integrators/fesd.hpp"
#include "moreau/integrators/timestepping.hpp"
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

// The time-stepping baseline with the filter: the layout changes between steps (its stage
// systems and their values-only copies are resized), every step's certificate covers the
// left-out constraints, and the states equal those of the run without the filter.
TEST(CrowdLargeTest, TimeSteppingWithTheFilterEqualsTheFullSystem) {
  CrowdOptions crowd;
  crowd.agents = 100;
  crowd.final_time = kHorizon;
  const CrowdLayout layout = MakeCrowdLayout(crowd);
  const Scene scene = MakeCrowdScene(layout);
  TimeSteppingResult runs[2];
  for (int filtered = 0; filtered < 2; ++filtered) {
    TimeSteppingOptions options;
    options.stages = 2;
    options.step_size = 0.05;
    options.constraint_filter = filtered ? ConstraintFilter::kOn : ConstraintFilter::kOff;
    runs[filtered] = SimulateTimeStepping(scene, options);
    const TimeSteppingResult& run = runs[filtered];
    ASSERT_EQ(run.status, TimeSteppingStatus::kSuccess) << run.message;
    for (double residual : run.step_complementarity_residual) {
      ASSERT_LE(residual, kComplementarityTolerance);
    }
    for (std::size_t k = 0; k < run.trajectory.size(); ++k) {
      const CrowdCertificate c = CertifyCrowdState(layout, run.trajectory.x[k]);
      ASSERT_TRUE(c.Feasible(kOverlapTolerance)) << "t " << run.trajectory.t[k] << c.Summary();
    }
  }
  EXPECT_LT(runs[1].stats.max_working_pairs,
            static_cast<long>(layout.pairs.size() + layout.walls.size()) / 2);
  ASSERT_EQ(runs[0].trajectory.size(), runs[1].trajectory.size());
  for (std::size_t k = 0; k < runs[0].trajectory.size(); ++k) {
    ASSERT_LE((runs[0].trajectory.x[k] - runs[1].trajectory.x[k]).lpNorm<Eigen::Infinity>(),
              kFilterAgreement)
        << "t " << runs[0].trajectory.t[k];
  }
}

}  // namespace
}  // namespace moreau
