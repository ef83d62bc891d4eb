#include "thread_pool.hpp"

#include <algorithm>
#include <exception>

#include "moreau/core/clock.hpp"

namespace moreau::internal {

namespace {
// Chunks per thread: enough that a worker which starts late (a wake-up takes some
// microseconds) or runs slower leaves little for the others to wait for, few enough that
// claiming them (one atomic operation each) costs nothing next to a chunk of blocks.
constexpr int kChunksPerThread = 8;
// Spins of the caller waiting for chunks in flight before it yields its core (one chunk lasts
// microseconds; yielding keeps oversubscribed machines, more threads than cores, moving).
constexpr int kSpinsBeforeYield = 2000;

constexpr std::uint64_t kChunkMask = 0xffffffffu;

// Chunk `index` of `chunks` contiguous chunks of [0, n).
void Range(int n, int chunks, int index, int* begin, int* end) {
  const long long size = n;
  *begin = static_cast<int>(size * index / chunks);
  *end = static_cast<int>(size * (index + 1) / chunks);
}

inline void CpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}
}  // namespace

ThreadPool::ThreadPool(int threads) {
  for (int i = 1; i < std::max(1, threads); ++i) workers_.emplace_back([this, i] { Work(i); });
}

ThreadPool::~ThreadPool() {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  start_.notify_all();
  for (std::thread& worker : workers_) worker.join();
}

int ThreadPool::Resolve(int threads) {
  if (threads > 0) return threads;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

bool ThreadPool::RunChunks(const Loop& loop, int thread) {
  in_flight_.fetch_add(1);
  bool ran = false;
  std::uint64_t next = next_chunk_.load();
  for (;;) {
    if ((next >> 32) != loop.generation || static_cast<int>(next & kChunkMask) >= loop.chunks) {
      break;  // another loop's, or every chunk claimed
    }
    if (!next_chunk_.compare_exchange_weak(next, next + 1)) continue;  // `next` reloaded
    const int chunk = static_cast<int>(next & kChunkMask);
    int begin = 0, end = 0;
    Range(loop.n, loop.chunks, chunk, &begin, &end);
    ran = true;
    try {
      (*loop.body)(begin, end, thread);
    } catch (...) {
      {
        const std::lock_guard<std::mutex> lock(error_mutex_);
        if (!error_ || chunk < error_chunk_) {
          error_ = std::current_exception();
          error_chunk_ = chunk;
        }
      }
      // No chunk starts after a throw (this thread's state may be half-written, and the loop's
      // result is the exception). Chunks are claimed in index order, so every chunk below this
      // one is claimed already and runs to its end: the lowest chunk that throws is the same
      // whatever the timing.
      next_chunk_.store((static_cast<std::uint64_t>(loop.generation) << 32) |
                        static_cast<std::uint64_t>(loop.chunks));
      break;
    }
    next = next_chunk_.load();
  }
  in_flight_.fetch_sub(1);
  return ran;
}

void ThreadPool::ParallelFor(int n, const std::function<void(int, int, int)>& body) {
  const int parts = threads();
  if (parts == 1 || n <= 1) {
    if (n > 0) body(0, n, 0);
    return;
  }
  Loop loop;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    loop.body = &body;
    loop.n = n;
    loop.chunks = std::min(n, parts * kChunksPerThread);
    loop.generation = loop_.generation + 1;
    loop_ = loop;  // (error_ is null: the last loop took its exception)
    // Published last: from here on the chunks of this loop can be claimed.
    next_chunk_.store(static_cast<std::uint64_t>(loop.generation) << 32);
  }
  start_.notify_all();
  RunChunks(loop, 0);
  // Every chunk is claimed; wait for those in flight on workers. A worker that claimed one
  // counted itself in in_flight_ before its claim, which precedes the claim this thread saw
  // exhausted, so it is seen here (all operations sequentially consistent).
  for (int spins = 0; in_flight_.load() != 0; ++spins) {
    if (spins < kSpinsBeforeYield) {
      CpuRelax();
    } else {
      std::this_thread::yield();
    }
  }
  std::exception_ptr error;
  {
    const std::lock_guard<std::mutex> lock(error_mutex_);
    error = error_;
    error_ = nullptr;
  }
  if (error) std::rethrow_exception(error);
}

void ThreadPool::Work(int index) {
  std::uint32_t seen = 0;
  for (;;) {
    Loop loop;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_.wait(lock, [&] { return stop_ || loop_.generation != seen; });
      if (stop_) return;
      loop = loop_;
      seen = loop.generation;
    }
    const double start = ThreadCpuSeconds();
    if (RunChunks(loop, index)) worker_seconds_.fetch_add(ThreadCpuSeconds() - start);
  }
}

}  // namespace moreau::internal
