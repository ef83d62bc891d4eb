#pragma once
/// @file
/// Clocks for run statistics: CPU time of a thread and of the process, and wall time.
///
/// Integrators report `cpu_seconds` as CPU time (RunClock), not elapsed time: on a loaded or
/// shared machine wall time counts other processes' work. Worker threads that compute on a
/// run's behalf add their own thread CPU time to the run's clock (RunClock::AddWorkerSeconds),
/// so a run's CPU time is never the process's (which also counts threads doing unrelated
/// work) and never less than the work done for it.

#include <atomic>

namespace moreau {

/// CPU time consumed by the calling thread, in seconds (POSIX CLOCK_THREAD_CPUTIME_ID).
double ThreadCpuSeconds();
/// CPU time consumed by all threads of the process, in seconds (CLOCK_PROCESS_CPUTIME_ID).
double ProcessCpuSeconds();
/// Monotonic wall-clock time in seconds from an arbitrary origin (std::chrono::steady_clock).
double WallSeconds();

/// The clocks of one run, started at construction: the CPU time of the thread that made it
/// plus the CPU time that worker threads reported for the run, and the elapsed wall time.
/// CpuSeconds() must be read on the thread that made the clock; AddWorkerSeconds may be
/// called from any thread.
class RunClock {
 public:
  RunClock() : thread_start_(ThreadCpuSeconds()), wall_start_(moreau::WallSeconds()) {}
  /// Adds CPU time that another thread spent on this run.
  void AddWorkerSeconds(double seconds) { worker_seconds_.fetch_add(seconds); }
  /// CPU time of the run so far: this thread's since construction plus the workers'.
  double CpuSeconds() const { return ThreadCpuSeconds() - thread_start_ + worker_seconds_.load(); }
  /// Wall time since construction.
  double WallSeconds() const { return moreau::WallSeconds() - wall_start_; }

 private:
  double thread_start_;
  double wall_start_;
  std::atomic<double> worker_seconds_{0.0};
};

}  // namespace moreau
