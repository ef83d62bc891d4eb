// cpu_seconds is CPU time, not elapsed time: runs of every integrator, made while another thread
// of the process spins on the same core, report in total at most the CPU time the process spent
// during them minus what the spinning thread took (the runs' own thread's share), and at most
// the process's CPU time. Elapsed time would report about twice as much: two threads pinned to
// one core each get about half of it.
#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <atomic>
#include <ostream>
#include <string>
#include <thread>

#include "moreau/core/clock.hpp"
#include "moreau/integrators/simulate.hpp"
#include "moreau/scenes/catalog.hpp"

namespace moreau {
namespace {

// Clock reads are not simultaneous (the process's, then the spinning thread's, a few
// microseconds apart) and CPU clocks advance in scheduler ticks of the kernel's accounting
// (sub-microsecond on Linux with CONFIG_VIRT_CPU_ACCOUNTING, up to a tick otherwise).
constexpr double kClockSlack = 2e-3;
// The runs are repeated until they have taken this much CPU time, so that the halving by the
// spinner (the elapsed time they would report) is well above the slack.
constexpr double kMinRunCpuSeconds = 20 * kClockSlack;

double ThreadClockSeconds(pthread_t thread) {
  clockid_t clock{};
  if (pthread_getcpuclockid(thread, &clock) != 0) return -1.0;
  timespec now{};
  clock_gettime(clock, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

// Pins the calling thread to one CPU for the scope of the object (restores the old set).
class PinToOneCpu {
 public:
  PinToOneCpu() {
    ok_ = pthread_getaffinity_np(pthread_self(), sizeof(old_), &old_) == 0;
    const int cpu = sched_getcpu();
    ok_ = ok_ && cpu >= 0;
    if (!ok_) return;
    CPU_ZERO(&one_);
    CPU_SET(cpu, &one_);
    ok_ = pthread_setaffinity_np(pthread_self(), sizeof(one_), &one_) == 0;
  }
  ~PinToOneCpu() {
    if (ok_) pthread_setaffinity_np(pthread_self(), sizeof(old_), &old_);
  }
  bool ok() const { return ok_; }
  const cpu_set_t& set() const { return one_; }

 private:
  bool ok_ = false;
  cpu_set_t old_{}, one_{};
};

struct Case {
  std::string integrator, scene;
};
void PrintTo(const Case& c, std::ostream* out) { *out << c.integrator << " on " << c.scene; }

class CpuTimeTest : public testing::TestWithParam<Case> {};

TEST_P(CpuTimeTest, CpuSecondsIsTheRunsOwnCpuTimeWhileAnotherThreadSpins) {
  const Case& c = GetParam();
  const Scene scene = MakeScene(c.scene);
  const SimulationSettings settings{c.integrator, {}};  // the defaults
  PinToOneCpu pin;
  ASSERT_TRUE(pin.ok()) << "could not pin the test thread to one CPU";
  std::atomic<bool> started{false}, stop{false};
  const cpu_set_t one = pin.set();
  std::thread spinner([&] {
    pthread_setaffinity_np(pthread_self(), sizeof(one), &one);
    started = true;
    while (!stop.load(std::memory_order_relaxed)) {
    }
  });
  while (!started) std::this_thread::yield();
  const pthread_t spinner_handle = spinner.native_handle();
  const double process0 = ProcessCpuSeconds();
  const double spinner0 = ThreadClockSeconds(spinner_handle);
  const double thread0 = ThreadCpuSeconds();
  double cpu_seconds = 0.0, wall_seconds = 0.0;
  int runs = 0;
  bool success = true;
  std::string message;
  while (success && ThreadCpuSeconds() - thread0 < kMinRunCpuSeconds) {
    const SimulationResult result = Simulate(scene, settings);
    success = result.success;
    message = result.message;
    cpu_seconds += result.cpu_seconds;
    wall_seconds += result.wall_seconds;
    ++runs;
    // Each run's CPU time is positive, and covered by its elapsed time (one thread computes).
    EXPECT_GT(result.cpu_seconds, 0.0);
    EXPECT_GE(result.wall_seconds + kClockSlack, result.cpu_seconds);
  }
  const double process1 = ProcessCpuSeconds();
  const double spinner1 = ThreadClockSeconds(spinner_handle);
  stop = true;
  spinner.join();
  ASSERT_TRUE(success) << message;
  ASSERT_GE(spinner0, 0.0);
  const double process = process1 - process0;
  const double own = process - (spinner1 - spinner0);  // this thread's CPU during the runs
  EXPECT_LE(cpu_seconds, process) << "process CPU time during " << runs << " runs";
  EXPECT_LE(cpu_seconds, own + kClockSlack)
      << runs << " runs; their thread had " << own << " s of CPU time, the spinning thread "
      << spinner1 - spinner0 << " s, elapsed " << wall_seconds << " s";
}

INSTANTIATE_TEST_SUITE_P(Integrators, CpuTimeTest,
                         testing::Values(Case{"radau", "hopf"}, Case{"fesd", "F1"},
                                         Case{"timestepping", "S3"}, Case{"ida", "S3"},
                                         Case{"alpha", "hopf"}),
                         [](const testing::TestParamInfo<Case>& param) {
                           return param.param.integrator;
                         });

}  // namespace
}  // namespace moreau
