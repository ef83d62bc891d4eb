#include "thread_pool.hpp"

#include <algorithm>
#include <exception>

#include "moreau/core/clock.hpp"

namespace moreau::internal {

namespace {
// Range `index` of `parts` contiguous ranges of [0, n).
void Range(int n, int parts, int index, int* begin, int* end) {
  const long long size = n;
  *begin = static_cast<int>(size * index / parts);
  *end = static_cast<int>(size * (index + 1) / parts);
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

void ThreadPool::ParallelFor(int n, const std::function<void(int, int, int)>& body) {
  const int parts = threads();
  if (parts == 1 || n <= 1) {
    if (n > 0) body(0, n, 0);
    return;
  }
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    body_ = &body;
    n_ = n;
    pending_ = parts - 1;
    ++generation_;
  }
  start_.notify_all();
  int begin = 0, end = 0;
  Range(n, parts, 0, &begin, &end);
  std::exception_ptr error;
  try {
    if (begin < end) body(begin, end, 0);
  } catch (...) {
    error = std::current_exception();
  }
  std::unique_lock<std::mutex> lock(mutex_);
  done_.wait(lock, [this] { return pending_ == 0; });
  body_ = nullptr;
  // A model function that throws (bad input) throws on the calling thread, whichever thread
  // met it first in range order.
  if (!error) error = worker_error_;
  worker_error_ = nullptr;
  if (error) std::rethrow_exception(error);
}

void ThreadPool::Work(int index) {
  long seen = 0;
  for (;;) {
    const std::function<void(int, int, int)>* body = nullptr;
    int n = 0;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_.wait(lock, [&] { return stop_ || generation_ != seen; });
      if (stop_) return;
      seen = generation_;
      body = body_;
      n = n_;
    }
    int begin = 0, end = 0;
    Range(n, threads(), index, &begin, &end);
    std::exception_ptr error;
    if (begin < end) {
      const double start = ThreadCpuSeconds();
      try {
        (*body)(begin, end, index);
      } catch (...) {
        error = std::current_exception();
      }
      worker_seconds_.fetch_add(ThreadCpuSeconds() - start);
    }
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (error && (!worker_error_ || index < worker_error_index_)) {
        worker_error_ = error;
        worker_error_index_ = index;
      }
      --pending_;
    }
    done_.notify_one();
  }
}

}  // namespace moreau::internal
