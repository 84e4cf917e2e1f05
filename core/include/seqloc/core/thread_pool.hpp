#pragma once
// The process's parallel loops. ThreadPool (run_jobs: localize's (route, mode) jobs, render's
// modes) starts its threads when first needed and keeps them; a loop hands its tasks to idle
// workers and takes part itself, so that a loop inside a loop cannot deadlock (the caller always
// works its own tasks off). parallel_chunks (the filter's, the matcher's and the calibration's
// short loops) starts a thread per part instead: measured faster there (docs/development.md,
// "Threads").

#include <algorithm>
#include <atomic>
#include <concepts>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace seqloc::core {

/// Worker threads when the user names none: the machine's cores (1 when unknown, at most 64).
[[nodiscard]] inline int default_threads() {
  const unsigned n = std::thread::hardware_concurrency();
  return n == 0 ? 1 : static_cast<int>(std::min(n, 64u));
}

class ThreadPool {
 public:
  /// The process's pool (created on first use, its threads joined at exit).
  [[nodiscard]] static ThreadPool& shared();

  ThreadPool() = default;
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  /// Runs task(0) ... task(tasks - 1), each once and in index order of their start, on at most
  /// `concurrency` threads at a time, the calling thread one of them; returns when all have
  /// ended. The first exception a task throws stops further tasks from starting and is rethrown
  /// once the running ones have ended.
  void run(std::size_t tasks, int concurrency, const std::function<void(std::size_t)>& task);

  /// Worker threads started so far.
  [[nodiscard]] std::size_t workers() const;

 private:
  struct Batch;
  void work();

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::shared_ptr<Batch>> queue_;  ///< batches that still want helpers
  std::vector<std::thread> threads_;
  std::atomic<std::size_t> busy_{0};  ///< workers running a task
  std::size_t wanted_ = 0;            ///< helpers the queued batches still want (at most the workers not busy)
  bool stopping_ = false;
};

/// Calls body(begin, end, chunk) on `chunks` contiguous parts of [0, n) (fewer when n is
/// smaller), in parallel: part c is [n * c / chunks, n * (c + 1) / chunks) (computed in n's type),
/// so the split depends on n and chunks alone, never on which thread runs a part. The calling
/// thread runs part 0 and a thread of its own runs each other part: measured, this beats the
/// shared pool for the filter's short loops when two of them run side by side (the step and the
/// next frame's preparation), where a pool's hand-offs cost more than starting the threads
/// (docs/development.md, "Threads").
template <std::integral Index, class Body>
void parallel_chunks(Index n, int chunks, Body&& body) {
  const auto parts = static_cast<Index>(std::max(1, chunks));
  const Index count = n < parts ? std::max(n, Index{1}) : parts;
  if (count == 1) {
    body(Index{0}, n, 0);
    return;
  }
  std::vector<std::jthread> workers;
  workers.reserve(static_cast<std::size_t>(count) - 1);
  for (Index t = 1; t < count; ++t) {
    workers.emplace_back([&body, n, count, t] { body(n * t / count, n * (t + 1) / count, static_cast<int>(t)); });
  }
  body(Index{0}, n / count, 0);
}

/// Runs job(0) ... job(jobs - 1), each once, on min(threads, jobs) threads of the shared pool
/// (the calling thread one of them); jobs start in index order. The first exception a job throws
/// stops further jobs from starting; it is rethrown once the running ones have ended.
void run_jobs(std::size_t jobs, int threads, const std::function<void(std::size_t)>& job);

}  // namespace seqloc::core
