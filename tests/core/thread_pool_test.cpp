// The worker pool of large scenes (lib/core/thread_pool.hpp): every index of a loop runs once,
// on a thread that exists; the first chunk's exception (in index order) reaches the caller
// with no chunk started after it; a loop's body never runs after its ParallelFor returned.
#include "../../lib/core/thread_pool.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <string>
#include <vector>

namespace moreau {
namespace {

TEST(ThreadPoolTest, EveryIndexRunsOnceOnAThreadOfThePool) {
  for (int threads : {1, 2, 3, 5}) {
    internal::ThreadPool pool(threads);
    for (int n : {0, 1, 2, 7, 100, 1000, 10007}) {
      for (int repeat = 0; repeat < 20; ++repeat) {
        std::vector<std::atomic<int>> hits(static_cast<std::size_t>(n));
        std::atomic<int> bad_thread{0}, bad_range{0};
        pool.ParallelFor(n, [&](int begin, int end, int thread) {
          if (thread < 0 || thread >= threads) ++bad_thread;
          if (begin < 0 || begin >= end || end > n) ++bad_range;
          for (int i = begin; i < end; ++i) ++hits[static_cast<std::size_t>(i)];
        });
        int wrong = 0;
        for (const std::atomic<int>& h : hits) wrong += h.load() != 1;
        ASSERT_EQ(wrong, 0) << threads << " threads, n = " << n;
        ASSERT_EQ(bad_thread.load(), 0) << threads << " threads, n = " << n;
        ASSERT_EQ(bad_range.load(), 0) << threads << " threads, n = " << n;
      }
    }
  }
}

// Many short loops one after the other, each with its own state: a worker that wakes late for
// a finished loop must not run its body (it would write to the loop's destroyed vector, which
// the sanitizer build reports, and count twice).
TEST(ThreadPoolTest, ALoopsBodyNeverRunsAfterItsLoopReturned) {
  internal::ThreadPool pool(3);
  std::atomic<long> total{0};
  long expected = 0;
  for (int loop = 0; loop < 20000; ++loop) {
    const int n = 1 + loop % 64;
    std::vector<int> hits(static_cast<std::size_t>(n), 0);
    pool.ParallelFor(n, [&](int begin, int end, int) {
      for (int i = begin; i < end; ++i) ++hits[static_cast<std::size_t>(i)];
      total += end - begin;
    });
    expected += n;
    for (int h : hits) ASSERT_EQ(h, 1) << "loop " << loop;
  }
  EXPECT_EQ(total.load(), expected);
}

// Chunks that throw: the caller gets the exception of the lowest chunk that throws, whichever
// thread met it first, every chunk below it has run to its end, and none starts after a throw
// on the thread that threw; the pool then runs the next loop normally.
TEST(ThreadPoolTest, TheLowestThrowingChunksExceptionReachesTheCaller) {
  for (int threads : {1, 2, 3, 5}) {
    internal::ThreadPool pool(threads);
    const int n = 1000;
    for (int repeat = 0; repeat < 50; ++repeat) {
      std::vector<std::atomic<int>> hits(static_cast<std::size_t>(n));
      std::vector<std::atomic<int>> threw(static_cast<std::size_t>(threads));
      std::atomic<int> started_after_throw{0};
      std::string message;
      try {
        pool.ParallelFor(n, [&](int begin, int end, int thread) {
          if (threw[static_cast<std::size_t>(thread)].load() != 0) ++started_after_throw;
          for (int i = begin; i < end; ++i) ++hits[static_cast<std::size_t>(i)];
          for (int bad : {300, 700, 900}) {  // one chunk (one thread): the lowest first
            if (begin <= bad && bad < end) {
              threw[static_cast<std::size_t>(thread)] = 1;
              throw std::runtime_error(std::to_string(bad));
            }
          }
        });
      } catch (const std::runtime_error& error) {
        message = error.what();
      }
      ASSERT_EQ(message, "300") << threads << " threads";
      int below_missed = 0, repeated = 0;
      for (int i = 0; i < n; ++i) {
        below_missed += i <= 300 && hits[static_cast<std::size_t>(i)].load() != 1;
        repeated += hits[static_cast<std::size_t>(i)].load() > 1;
      }
      ASSERT_EQ(below_missed, 0) << threads << " threads";
      ASSERT_EQ(repeated, 0) << threads << " threads";
      ASSERT_EQ(started_after_throw.load(), 0) << threads << " threads";
    }
    std::atomic<int> after{0};
    pool.ParallelFor(n, [&](int begin, int end, int) { after += end - begin; });
    EXPECT_EQ(after.load(), n) << threads << " threads";
  }
}

}  // namespace
}  // namespace moreau
