// Sweeps (include/moreau/ensemble/sweep.hpp): closed-form answers at every grid point, the
// same table whatever the threads and the order and grouping of runs, a row for every run
// (numerical failures and invalid drawn values included), and clear errors for bad specs.
#include "moreau/ensemble/sweep.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <random>

#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// FESD s = 3 with h = 0.05 locates S3's switches to about 1e-11 (order 5; the work-precision
// report measures 1e-10 at h = 0.04 for the whole error): 1e-8 leaves two decades of margin.
constexpr double kSwitchTimeTolerance = 1e-8;

// S3 from x0 = (a, b) with r = |x0| > 1 above the floor x2 = -1: x = r (cos psi, sin psi),
// psi = atan2(b, a) - t, meets the floor where psi = -asin(1/r) (contact at
// (sqrt(r^2 - 1), -1)), slides with x1' = -1 and leaves at x1 = 0, sqrt(r^2 - 1) later.
std::pair<double, double> S3ContactAndLeave(double a, double b) {
  const double r = std::hypot(a, b);
  const double contact = std::atan2(b, a) + std::asin(1.0 / r);
  return {contact, contact + std::sqrt(r * r - 1.0)};
}

TEST(SweepTest, S3GridReproducesClosedFormContactAndLeavingTimes) {
  Scene scene = MakeScene("S3");
  SetSceneValue(&scene, "tf", 7.0);  // after leaving and before the next (grazing) contact
  SweepSpec spec;
  spec.grids = {ParseSweepGrid("x0.x1=1:2:6"), ParseSweepGrid("x0.x2=0.5:1.5:5")};
  const SweepResult result = RunSweep(scene, spec, {"fesd", {{"stages", 3L}, {"h", 0.05}}}, 2);
  ASSERT_EQ(result.rows.size(), 30u);
  for (const SweepRow& row : result.rows) {
    ASSERT_TRUE(row.success) << row.message;
    const auto [contact, leave] = S3ContactAndLeave(row.values[0], row.values[1]);
    ASSERT_EQ(row.num_events, 2) << row.values[0] << ", " << row.values[1];
    EXPECT_NEAR(row.event_times[0], contact, kSwitchTimeTolerance);
    EXPECT_NEAR(row.event_times[1], leave, kSwitchTimeTolerance);
  }
  // Grid order: the first grid varies slowest.
  EXPECT_EQ(result.rows[1].values[0], 1.0);
  EXPECT_EQ(result.rows[1].values[1], 0.75);
  EXPECT_EQ(result.rows[5].values[0], 1.2);
}

bool SameRow(const SweepRow& a, const SweepRow& b) {
  auto same = [](const std::vector<double>& x, const std::vector<double>& y) {
    return x.size() == y.size() &&
           (x.empty() || std::memcmp(x.data(), y.data(), x.size() * sizeof(double)) == 0);
  };
  std::vector<double> sa(a.stats), sb(b.stats);  // cpu_seconds is the last stat: not compared
  if (!sa.empty()) sa.pop_back();
  if (!sb.empty()) sb.pop_back();
  return a.index == b.index && same(a.values, b.values) && a.status == b.status &&
         a.message == b.message && a.final_state.size() == b.final_state.size() &&
         std::memcmp(a.final_state.data(), b.final_state.data(),
                     sizeof(double) * static_cast<std::size_t>(a.final_state.size())) == 0 &&
         a.num_events == b.num_events && same(a.event_times, b.event_times) && same(sa, sb);
}

TEST(SweepTest, SameTableWhateverTheThreadsAndTheOrderOfChunks) {
  const Scene scene = MakeScene("H1");
  SweepSpec spec;
  spec.samples = {ParseSweepSample("heat=normal:5:0.5"),
                  ParseSweepSample("decay=uniform:0.15:0.25")};
  spec.num_samples = 16;
  spec.seed = 7;
  const SimulationSettings settings{"fesd", {{"h", 0.2}}};
  const SweepResult one = RunSweep(scene, spec, settings, 1);
  const SweepResult two = RunSweep(scene, spec, settings, 2);
  // Chunks of 5 runs in a shuffled order, as a cluster would finish them.
  std::vector<long> order(16);
  for (long i = 0; i < 16; ++i) order[static_cast<std::size_t>(i)] = i;
  std::shuffle(order.begin(), order.end(), std::mt19937(1));
  std::vector<SweepRow> chunked(16);
  for (std::size_t start = 0; start < order.size(); start += 5) {
    const std::vector<long> chunk(
        order.begin() + static_cast<long>(start),
        order.begin() + static_cast<long>(std::min(start + 5, order.size())));
    for (const SweepRow& row : RunSweep(scene, spec, settings, 2, chunk).rows) {
      chunked[static_cast<std::size_t>(row.index)] = row;
    }
  }
  for (std::size_t i = 0; i < 16; ++i) {
    EXPECT_TRUE(one.rows[i].success) << one.rows[i].message;
    EXPECT_TRUE(SameRow(one.rows[i], two.rows[i])) << i;
    EXPECT_TRUE(SameRow(one.rows[i], chunked[i])) << i;
  }
}

TEST(SweepTest, EveryRunIsARowFailuresIncluded) {
  // x0.x2 below the floor (-1) puts x0 outside the moving set: invalid_input rows; the others
  // succeed.
  SweepSpec spec;
  spec.grids = {ParseSweepGrid("x0.x2=-2:1:4")};
  const SweepResult result = RunSweep(MakeScene("S3"), spec, {"fesd", {}}, 2);
  ASSERT_EQ(result.rows.size(), 4u);
  EXPECT_EQ(result.rows[0].status, "invalid_input");
  EXPECT_NE(result.rows[0].message.find("floor"), std::string::npos) << result.rows[0].message;
  EXPECT_TRUE(std::isnan(result.rows[0].final_state[0]));
  for (std::size_t i = 2; i < 4; ++i) EXPECT_TRUE(result.rows[i].success) << result.rows[i].message;
  // A numerical failure (FESD s = 3, H = 0.1 on the stiff set: the documented
  // event_location_failure at t = 0) is a row with the integrator's status.
  SweepSpec stiff;
  stiff.grids = {ParseSweepGrid("tf=1:2:2")};
  const SweepResult failed =
      RunSweep(MakeScene("hard_stiff_set"), stiff, {"fesd", {{"stages", 3L}, {"h", 0.1}}}, 2);
  ASSERT_EQ(failed.rows.size(), 2u);
  for (const SweepRow& row : failed.rows) {
    EXPECT_EQ(row.status, "event_location_failure");
    EXPECT_FALSE(row.message.empty());
  }
}

TEST(SweepTest, SamplesFollowTheirDistributions) {
  SweepSpec spec;
  spec.samples = {ParseSweepSample("heat=normal:5:2"), ParseSweepSample("decay=uniform:1:3")};
  spec.num_samples = 40000;
  double sum = 0, sum2 = 0, usum = 0, umin = 1e9, umax = -1e9;
  for (long i = 0; i < spec.num_samples; ++i) {
    const std::vector<double> v = spec.ValuesOf(i);
    sum += v[0];
    sum2 += v[0] * v[0];
    usum += v[1];
    umin = std::min(umin, v[1]);
    umax = std::max(umax, v[1]);
  }
  const double n = static_cast<double>(spec.num_samples);
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  // Five standard errors: a correct generator fails this with probability below 1e-6.
  EXPECT_NEAR(mean, 5.0, 5 * 2.0 / std::sqrt(n));
  EXPECT_NEAR(sd, 2.0, 5 * 2.0 / std::sqrt(2 * n));
  EXPECT_NEAR(usum / n, 2.0, 5 * (2.0 / std::sqrt(12.0)) / std::sqrt(n));
  EXPECT_GE(umin, 1.0);
  EXPECT_LT(umax, 3.0);
  // Values depend on (seed, index) only.
  SweepSpec other = spec;
  other.seed = 1;
  EXPECT_NE(spec.ValuesOf(3)[0], other.ValuesOf(3)[0]);
  EXPECT_EQ(spec.ValuesOf(3), spec.ValuesOf(3));
}

TEST(SweepTest, BadSpecificationsAreNamed) {
  auto expect = [](auto&& call, const std::string& part) {
    try {
      call();
      ADD_FAILURE() << "no error, expected: " << part;
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(part), std::string::npos) << error.what();
    }
  };
  expect([] { ParseSweepGrid("r=0:1"); }, "expected name=start:stop:count");
  expect([] { ParseSweepGrid("=0:1:3"); }, "expected name=start:stop:count");
  expect([] { ParseSweepGrid("r=0:1:2.5"); }, "count must be a whole number >= 1");
  expect([] { ParseSweepGrid("r=a:1:3"); }, "bad grid start 'a'");
  expect([] { ParseSweepSample("r=gauss:0:1"); }, "expected name=normal:mean:std");
  expect([] { ParseSweepSample("r=normal:0:-1"); }, "standard deviation must be >= 0");
  expect([] { ParseSweepSample("r=uniform:1:1"); }, "needs a < b");
  const Scene scene = MakeScene("S3");
  SweepSpec unknown;
  unknown.grids = {ParseSweepGrid("radius=0:1:3")};
  expect([&] { unknown.Validate(scene); }, "has no value named 'radius' to vary; valid names: tf");
  SweepSpec twice;
  twice.grids = {ParseSweepGrid("floor=0:1:3"), ParseSweepGrid("floor=0:1:2")};
  expect([&] { twice.Validate(scene); }, "'floor' is varied twice");
  SweepSpec no_count;
  no_count.samples = {ParseSweepSample("floor=normal:0:1")};
  expect([&] { no_count.Validate(scene); }, "needs --samples N");
  expect([] { SweepSpec().Validate(MakeScene("S3")); }, "at least one --grid or --sample");
  SweepSpec ok;
  ok.grids = {ParseSweepGrid("floor=-1:-0.5:3")};
  expect(
      [&] {
        RunSweep(scene, ok, {"fesd", {{"rho", 0.5}}});
      },
      "option 'rho' does not apply to integrator 'fesd'");
  expect([&] { RunSweep(scene, ok, {"fesd", {}}, 1, {7}); }, "run index 7 is outside");
}

}  // namespace
}  // namespace moreau
