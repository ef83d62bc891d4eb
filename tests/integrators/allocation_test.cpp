// Heap allocations in the steady-state step loop. The executable replaces the global operator
// new (every allocation of the process passes through it) and counts, between two calls of an
// integrator's progress callback (one per element or step), the allocations the integrating
// thread makes. After the first steps (workspaces sized, patterns detected, plans made) a step
// should allocate nothing.
//
// Two checks per case. (1) Steps without an event: a steady step whose interval holds no event
// of the run (no switch, contact change or relay jump) allocates nothing, asserted as zero for
// the cases that reach it (`smooth_steps_allocate_nothing`). Steps at events legitimately
// allocate: the events themselves (names, details), and the first meeting of a working set
// (new element systems, sparsity detection of a mode's functions, factorization plans).
// (2) All steady steps: the mean allocations per step at most the recorded count (a ratchet:
// release and dev presets count the same calls, the library makes them, not the sanitizers;
// docs/benchmarks.md, "Allocations in the step loop").
//
// Every heap allocation is counted: the executable also replaces malloc, calloc and realloc
// (forwarding to glibc's), which Eigen's dynamic matrices call directly. Under AddressSanitizer
// (the dev preset), which replaces them itself, only operator new and aligned_alloc are
// counted: a subset, so that the same bounds hold there. The sparse LU (KLU, UMFPACK) allocates
// through SuiteSparse's configurable allocator, which this test points at its own functions:
// those allocations (KLU's numeric factors at every factorization of the crowd) are counted
// apart and reported, not asserted (SuiteSparse's, not moreau's).
#include <SuiteSparse_config.h>
#include <execinfo.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <map>
#include <new>
#include <ostream>
#include <string>
#include <vector>

#include "moreau/core/error.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/integrators/working_set.hpp"
#include "moreau/scenes/catalog.hpp"

namespace {
// Counting is per thread: gtest's and other threads' allocations do not count, and the
// integrators run on the calling thread (their worker threads are off at these sizes).
thread_local bool counting = false;
thread_local long allocations = 0;
thread_local long sparse_lu_allocations = 0;  // through SuiteSparse_config (see above)
thread_local long new_allocations = 0;        // the subset made by operator new
// MOREAU_ALLOCATION_TRACE=1 prints the call stack of every allocation in a steady step (to find
// what still allocates; symbols need -rdynamic or addr2line).
thread_local bool in_steady_step = false;
thread_local long step_index = 0;  // the step being counted (printed with each trace)
const bool trace = std::getenv("MOREAU_ALLOCATION_TRACE") != nullptr;

void Trace() {
  if (!trace || !in_steady_step) return;
  in_steady_step = false;  // backtrace itself may allocate
  void* frames[24];
  const int depth = backtrace(frames, 24);
  backtrace_symbols_fd(frames, depth, 2);
  char separator[48];
  const int length = std::snprintf(separator, sizeof(separator), "---- step %ld\n", step_index);
  (void)!write(2, separator, static_cast<std::size_t>(length));
  in_steady_step = true;
}

void Count() {
  if (counting) {
    ++allocations;
    Trace();
  }
}

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kCountsMalloc = false;
#else
constexpr bool kCountsMalloc = true;
#endif

void* Allocate(std::size_t size) {
  if (counting) ++new_allocations;
  if (!kCountsMalloc) Count();  // else std::malloc counts it
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void* AllocateAligned(std::size_t size, std::align_val_t align) {
  if (counting) ++new_allocations;
  Count();  // aligned_alloc is glibc's own
  const auto a = static_cast<std::size_t>(align);
  if (void* p = std::aligned_alloc(a, (std::max<std::size_t>(size, 1) + a - 1) / a * a)) return p;
  throw std::bad_alloc();
}
}  // namespace

#if !defined(__SANITIZE_ADDRESS__)
// glibc's allocator under its internal names (the replacements below forward to them).
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* p, std::size_t size);
void __libc_free(void* p);

void* malloc(std::size_t size) {
  Count();
  return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) {
  Count();
  return __libc_calloc(count, size);
}
void* realloc(void* p, std::size_t size) {
  if (size > 0) Count();  // (size 0 frees)
  return __libc_realloc(p, size);
}
void free(void* p) { __libc_free(p); }
}
#endif

// SuiteSparse's allocator: counted apart, then glibc's (or the sanitizer's) directly.
namespace {
#if defined(__SANITIZE_ADDRESS__)
void* RawMalloc(std::size_t size) { return std::malloc(size); }
void* RawCalloc(std::size_t count, std::size_t size) { return std::calloc(count, size); }
void* RawRealloc(void* p, std::size_t size) { return std::realloc(p, size); }
void RawFree(void* p) { std::free(p); }
#else
void* RawMalloc(std::size_t size) { return __libc_malloc(size); }
void* RawCalloc(std::size_t count, std::size_t size) { return __libc_calloc(count, size); }
void* RawRealloc(void* p, std::size_t size) { return __libc_realloc(p, size); }
void RawFree(void* p) { __libc_free(p); }
#endif
void* SparseLuMalloc(std::size_t size) {
  if (counting) ++sparse_lu_allocations;
  return RawMalloc(size);
}
void* SparseLuCalloc(std::size_t count, std::size_t size) {
  if (counting) ++sparse_lu_allocations;
  return RawCalloc(count, size);
}
void* SparseLuRealloc(void* p, std::size_t size) {
  if (counting && size > 0) ++sparse_lu_allocations;
  return RawRealloc(p, size);
}
// Installed before main (no SuiteSparse call can have happened yet).
[[maybe_unused]] const bool sparse_lu_allocator_installed = [] {
  SuiteSparse_config.malloc_func = &SparseLuMalloc;
  SuiteSparse_config.calloc_func = &SparseLuCalloc;
  SuiteSparse_config.realloc_func = &SparseLuRealloc;
  SuiteSparse_config.free_func = &RawFree;
  return true;
}();
}  // namespace

void* operator new(std::size_t size) { return Allocate(size); }
void* operator new[](std::size_t size) { return Allocate(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return Allocate(size);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return Allocate(size);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t size, std::align_val_t align) {
  return AllocateAligned(size, align);
}
void* operator new[](std::size_t size, std::align_val_t align) {
  return AllocateAligned(size, align);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

namespace moreau {
namespace {

// Steps before the loop is taken as steady: the first ones size workspaces, detect patterns
// and make factorization plans for each working set met.
constexpr int kWarmupSteps = 10;

struct Case {
  std::string name;  // test name
  std::string scene, integrator;
  std::map<std::string, SettingValue> options;
  // Most allocations per steady step (mean over the steady steps) measured when written.
  double max_per_step = 0.0;
  // Steady steps without an event allocate nothing (asserted exactly).
  bool smooth_steps_allocate_nothing = false;
  // Scenes with the near-active filter, whose working set changes at steps without an event:
  // steady steps without an event and without a working-set change (in them or the step
  // before) make no allocation with operator new (asserted exactly), and at least this many
  // steps are such (half the count measured when written: the assertion must check something).
  // 0: not asserted.
  long min_steady_set_steps = 0;
  // Their allocations in all (Eigen's working-set-sized vectors; see the test), measured.
  long max_steady_set_allocations = 0;
};
void PrintTo(const Case& c, std::ostream* out) { *out << c.name; }

class AllocationTest : public testing::TestWithParam<Case> {};

TEST_P(AllocationTest, SteadyStepsAllocateAtMostTheRecordedCount) {
  const Case& c = GetParam();
  const Scene scene = MakeScene(c.scene);
  SimulationSettings settings{c.integrator, {}};
  for (const auto& [key, value] : c.options) settings.options[key] = value;
  // Steady-state count per step: allocations between consecutive progress calls.
  std::vector<long> per_step, new_per_step;  // every allocation; those by operator new
  std::vector<double> step_ends;
  // Whether the near-active filter changed the working set in the step (the element systems'
  // unknowns and pattern changed: new plans, patterns and sizes may be met).
  std::vector<bool> set_changed;
  // Reserved: the callback's own bookkeeping must not allocate inside the counted steps.
  constexpr std::size_t kMostSteps = 1 << 16;
  per_step.reserve(kMostSteps);
  new_per_step.reserve(kMostSteps);
  step_ends.reserve(kMostSteps);
  set_changed.reserve(kMostSteps);
  long last = 0, last_new = 0, last_changes = WorkingSetChangesOnThisThread();
  long sparse_lu_steady = 0;  // the sparse LU's allocations from the first steady step on
  const ProgressCallback progress = [&](double t) {
    MOREAU_ASSERT(per_step.size() < kMostSteps, "more steps than reserved");
    per_step.push_back(allocations - last);
    new_per_step.push_back(new_allocations - last_new);
    last_new = new_allocations;
    step_ends.push_back(t);
    const long changes = WorkingSetChangesOnThisThread();
    set_changed.push_back(changes != last_changes);
    last_changes = changes;
    last = allocations;
    step_index = static_cast<long>(per_step.size());
    in_steady_step = per_step.size() >= static_cast<std::size_t>(kWarmupSteps);
    if (per_step.size() == static_cast<std::size_t>(kWarmupSteps)) {
      sparse_lu_steady = -sparse_lu_allocations;
    }
  };
  allocations = 0;
  new_allocations = 0;
  sparse_lu_allocations = 0;
  counting = true;
  const SimulationResult result = Simulate(scene, settings, progress);
  counting = false;
  sparse_lu_steady += sparse_lu_allocations;
  in_steady_step = false;
  ASSERT_TRUE(result.success) << result.message;
  ASSERT_GT(per_step.size(), static_cast<std::size_t>(2 * kWarmupSteps))
      << "too few steps to see a steady state";
  // A step [t_{k-1}, t_k] holds an event if an event time lies in it (ends included, up to
  // round-off in the event's time): the step that ends on a switch and the one that starts
  // there (the statuses are decided after the last element's progress call).
  auto holds_event = [&](std::size_t k) {
    const double a = step_ends[k - 1], b = step_ends[k];
    const double margin = 1e-9 * (1.0 + std::max(std::fabs(a), std::fabs(b)));
    for (const Event& event : result.events) {
      if (event.t >= a - margin && event.t <= b + margin) return true;
    }
    return false;
  };
  long total = 0, steps_allocating = 0, most = 0, smooth_steps = 0, smooth_allocations = 0;
  long steady_set_steps = 0, steady_set_allocations = 0, steady_set_new = 0, set_change_steps = 0;
  for (std::size_t k = kWarmupSteps; k < per_step.size(); ++k) {
    total += per_step[k];
    steps_allocating += per_step[k] > 0 ? 1 : 0;
    most = std::max(most, per_step[k]);
    set_change_steps += set_changed[k] ? 1 : 0;
    // A new working set is met in the step that changes it and, at its new sizes, in the next
    // one: the filter evaluates the system at each step's start with the layout the step before
    // chose, and a vector of another length is storage of another length.
    const bool meets_new_set = set_changed[k] || set_changed[k - 1];
    if (!holds_event(k)) {
      ++smooth_steps;
      smooth_allocations += per_step[k];
      if (!meets_new_set) {
        ++steady_set_steps;
        steady_set_allocations += per_step[k];
        steady_set_new += new_per_step[k];
      }
      if (trace && per_step[k] > 0) {
        std::cout << "  step " << k << " (no event"
                  << (meets_new_set ? ", working set changed" : "") << ") allocates " << per_step[k]
                  << "\n";
      }
    }
  }
  const auto steps = static_cast<double>(per_step.size() - kWarmupSteps);
  const double mean = static_cast<double>(total) / steps;
  RecordProperty("allocations_per_step", std::to_string(mean));
  std::cout << c.name << ": " << per_step.size() << " steps, " << mean
            << " allocations per steady step (" << steps_allocating << " steps allocate, at most "
            << most << "); " << smooth_steps << " steady steps without an event allocate "
            << smooth_allocations << "; " << set_change_steps
            << " steady steps change the working set, " << steady_set_steps
            << " steps without an event or working-set change allocate " << steady_set_allocations
            << " (" << steady_set_new << " by operator new)"
            << "; the sparse LU's own allocations: "
            << static_cast<double>(sparse_lu_steady) / steps << " per steady step\n";
  EXPECT_LE(mean, c.max_per_step) << "allocations per steady step grew";
  if (c.min_steady_set_steps > 0) {
    EXPECT_GE(steady_set_steps, c.min_steady_set_steps)
        << "too few steady steps without an event or working-set change: little checked";
    // operator new: nothing. Eigen's vectors sized by the working set (np, nz) take their new
    // length at their first use after a change, which may come steps later (a step snapshot,
    // a crossing search): those reallocations are bounded by the recorded count.
    EXPECT_EQ(steady_set_new, 0)
        << "steady steps without an event or working-set change allocate with operator new";
    EXPECT_LE(steady_set_allocations, c.max_steady_set_allocations)
        << "steady steps without an event or working-set change allocate more";
  }
  if (c.smooth_steps_allocate_nothing) {
    EXPECT_GT(smooth_steps, 0) << "no steady step without an event: nothing checked";
    EXPECT_EQ(smooth_allocations, 0) << "steady steps without an event allocate";
  }
}

using Options = std::map<std::string, SettingValue>;
const Options kNoTrajectory = {{"record_trajectory", SettingValue{false}}};

// Bounds: the mean allocations per steady step (malloc included, in the release preset)
// measured with this test's own output, rounded up in the second decimal (the counts are
// deterministic), each case run alone as ctest runs it (per-thread scratch that an earlier case
// grew is not grown again: run together, later cases may count fewer). What remains at events:
// the events themselves, the status decisions and velocity-level problems of a switch, and the
// first meeting of a working set (element systems configured anew, sparsity detection of a
// mode's functions, solvers made for a new size). The crowd's element systems change their
// working set (near-active filter) and pattern with the agents' approach and contacts, which
// makes new layouts, plans and factorization patterns at those steps (30 of fesd_crowd's 91
// steady steps, 33 of timestepping_crowd's 440); its steps with neither an event nor a
// working-set change make no allocation with operator new (asserted), and 35 and 4 Eigen
// reallocations in all (vectors taking the new set's length at their first use after it).
// Fixed-step runs reserve their results (elements) for the grid, error-controlled runs for
// their first 1024 steps (beyond, they grow by doubling). The rectifier's dense output is off:
// each output point stores its state and multipliers in the result.
Options With(Options options, const std::string& key, SettingValue value) {
  options[key] = std::move(value);
  return options;
}

INSTANTIATE_TEST_SUITE_P(
    Integrators, AllocationTest,
    testing::Values(
        Case{"fesd_F1", "F1", "fesd", With(kNoTrajectory, "h", 0.1), 16.28, true},
        Case{"fesd_S3", "S3", "fesd", With(kNoTrajectory, "h", 0.1), 3.79, true},
        Case{"fesd_H1", "H1", "fesd", With(kNoTrajectory, "h", 0.1), 1.85, true},
        Case{"fesd_rectifier", "rectifier", "fesd",
             With(With(kNoTrajectory, "h", 1e-4), "output_dt", 0.0), 12.04, true},
        Case{"fesd_crowd", "crowd:N=16", "fesd", With(kNoTrajectory, "h", 0.1), 517.36, false, 12,
             35},
        Case{"fesd_adaptive_F1", "F1", "fesd", kNoTrajectory, 23.29, true},
        Case{"fesd_adaptive_S3", "S3", "fesd", With(kNoTrajectory, "h_max", 0.05), 3.99, true},
        Case{"timestepping_S3", "S3", "timestepping", kNoTrajectory, 0.08, true},
        Case{"timestepping_rectifier", "rectifier", "timestepping", With(kNoTrajectory, "h", 2e-5),
             0.32, true},
        Case{"timestepping_crowd", "crowd:N=16", "timestepping", kNoTrajectory, 31.31, false, 164,
             4},
        Case{"radau_hopf", "hopf", "radau", kNoTrajectory, 0, true},
        Case{"ida_S3", "S3", "ida", {{"record_steps", SettingValue{false}}}, 0.72, true}),
    [](const testing::TestParamInfo<Case>& param) { return param.param.name; });

}  // namespace
}  // namespace moreau
