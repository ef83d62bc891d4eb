#pragma once
// A fixed pool of worker threads for the data-parallel loops of large scenes (evaluation of
// model functions made of blocks, docs/sparse-derivatives.md "Functions made of blocks"). Private
// to moreau.
//
// ParallelFor splits [0, n) into contiguous ranges, one per thread (the caller computes the
// first), and returns when all are done. Work is assigned by range, never by whoever is free,
// so which thread computes what is a function of n and the thread count alone; callers make
// results independent of the thread count by writing every result to its own place (or per
// worker, then combining in a fixed order). Workers measure the CPU time they spend in tasks
// (worker_cpu_seconds), which integrators add to their runs' cpu_seconds (RunClock).

#include <atomic>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace moreau::internal {

// Loops over the blocks of a function made of blocks (its sparse derivatives, its interval
// enclosures) with fewer blocks than this run on the calling thread: a parallel loop costs some
// microseconds of synchronization, a block's evaluation tens of nanoseconds.
inline constexpr int kParallelMinBlocks = 1024;

class ThreadPool {
 public:
  // `threads` >= 1 threads in all: the caller and threads - 1 workers.
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int threads() const { return static_cast<int>(workers_.size()) + 1; }
  // body(begin, end, thread) for the thread-th of threads() contiguous ranges of [0, n)
  // (ranges of equal length up to one; empty ranges are not run). Not reentrant: body must not
  // call ParallelFor of the same pool.
  void ParallelFor(int n, const std::function<void(int begin, int end, int thread)>& body);
  // CPU time the workers spent in bodies since construction (the caller's share is its own).
  double worker_cpu_seconds() const { return worker_seconds_.load(); }

  // The number of threads a `threads` option asks for: the value if positive, else every
  // hardware thread (std::thread::hardware_concurrency, at least 1).
  static int Resolve(int threads);

 private:
  void Work(int index);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(int, int, int)>* body_ = nullptr;
  int n_ = 0;
  long generation_ = 0;  // incremented per ParallelFor: workers run each generation once
  int pending_ = 0;      // workers still running the current generation
  bool stop_ = false;
  std::exception_ptr worker_error_;  // the first (lowest range) exception of a generation
  int worker_error_index_ = 0;
  std::atomic<double> worker_seconds_{0.0};
};

}  // namespace moreau::internal
