#pragma once
// A fixed pool of worker threads for the data-parallel loops of large scenes (evaluation of
// model functions made of blocks, docs/sparse-derivatives.md "Functions made of blocks"). Private
// to moreau.
//
// ParallelFor splits [0, n) into contiguous chunks (several per thread) that the caller and the
// workers claim in turn until none is left, and returns when all are done. Which thread runs a
// chunk depends on timing, so callers make results independent of it: every result is written
// to its own place, and per-thread state (workspaces, flags combined by OR) never carries a
// value from one chunk into another's results. The caller starts at once and never sleeps: a
// worker that wakes late finds the chunks taken and costs nothing, and the caller waits (spins)
// only for chunks in flight. Workers measure the CPU time they spend in loops
// (worker_cpu_seconds), which integrators add to their runs' cpu_seconds (RunClock).

#include <atomic>
#include <condition_variable>
#include <cstdint>
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
  // body(begin, end, thread) for contiguous chunks [begin, end) covering [0, n) once each,
  // each on one thread (0 is the caller, 1..threads() - 1 the workers); a thread may run
  // several chunks, or none. Not reentrant: body must not call ParallelFor of the same pool.
  // If a body throws, no further chunk starts (the chunks below it, claimed before it, run to
  // their ends) and the exception of the lowest chunk that threw is rethrown here, whichever
  // thread met it: the same exception whatever the timing.
  void ParallelFor(int n, const std::function<void(int begin, int end, int thread)>& body);
  // CPU time the workers spent in loops since construction (the caller's share is its own).
  double worker_cpu_seconds() const { return worker_seconds_.load(); }

  // The number of threads a `threads` option asks for: the value if positive, else every
  // hardware thread (std::thread::hardware_concurrency, at least 1).
  static int Resolve(int threads);

 private:
  // One ParallelFor: what the workers copy (under mutex_) when they wake for it.
  struct Loop {
    const std::function<void(int, int, int)>* body = nullptr;
    int n = 0;
    int chunks = 0;
    std::uint32_t generation = 0;
  };
  void Work(int index);
  // Claims and runs chunks of `loop` on `thread` until none is left; false if none was run.
  bool RunChunks(const Loop& loop, int thread);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable start_;
  Loop loop_;          // under mutex_: the current loop
  bool stop_ = false;  // under mutex_
  // The next chunk to claim: loop generation in the high 32 bits, chunk index in the low ones.
  // A worker holding an older loop fails to claim, so it never runs a finished loop's body.
  std::atomic<std::uint64_t> next_chunk_{0};
  std::atomic<int> in_flight_{0};  // threads between their first claim attempt and their last
  std::mutex error_mutex_;
  std::exception_ptr error_;  // of the lowest chunk that threw in the current loop
  int error_chunk_ = 0;
  std::atomic<double> worker_seconds_{0.0};
};

}  // namespace moreau::internal
