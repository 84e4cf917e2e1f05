// The shared thread pool: every task once, on the threads asked for, the first error stops the
// rest; threads are started once and kept, and a loop inside a loop finishes.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include "seqloc/core/thread_pool.hpp"

namespace seqloc::core {
namespace {

TEST(ThreadPool, RunsEachJobOnceOnAtMostTheThreadsAsked) {
  for (const int threads : {1, 2, 3, 8}) {
    for (const std::size_t jobs : {std::size_t{0}, std::size_t{1}, std::size_t{5}, std::size_t{100}}) {
      std::vector<std::atomic<int>> runs(jobs);
      std::mutex mutex;
      std::set<std::thread::id> ids;
      run_jobs(jobs, threads, [&](std::size_t j) {
        ++runs[j];
        std::lock_guard lock(mutex);
        ids.insert(std::this_thread::get_id());
      });
      for (std::size_t j = 0; j < jobs; ++j) EXPECT_EQ(runs[j], 1) << "job " << j << " of " << jobs;
      EXPECT_LE(ids.size(), static_cast<std::size_t>(std::min<std::size_t>(jobs, threads)));
      if (threads == 1 && jobs > 0) {
        EXPECT_EQ(*ids.begin(), std::this_thread::get_id()) << "one thread: the caller's";
      }
    }
  }
}

TEST(ThreadPool, TheFirstErrorStopsTheJobsNotStartedAndIsRethrown) {
  for (const int threads : {1, 2, 4}) {
    std::atomic<int> started{0};
    try {
      run_jobs(1000, threads, [&](std::size_t j) {
        ++started;
        if (j == 3) throw std::runtime_error("job 3 failed");
        std::this_thread::sleep_for(std::chrono::milliseconds(20));  // long beside the throw
      });
      ADD_FAILURE() << "no error came out";
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "job 3 failed");
    }
    // Jobs 0-3 started; each other thread may have taken another (or, on a very busy machine, a
    // second) before it saw the failure.
    EXPECT_GE(started, 4);
    EXPECT_LE(started, 4 + 2 * (threads - 1)) << threads << " threads";
  }
}

TEST(ThreadPool, StartsThreadsOnceAndKeepsThem) {
  ThreadPool pool;
  std::atomic<int> sum{0};
  pool.run(8, 4, [&](std::size_t i) { sum += static_cast<int>(i); });
  EXPECT_EQ(sum, 28);
  const std::size_t started = pool.workers();
  EXPECT_GE(started, 1u);
  EXPECT_LE(started, 3u) << "the caller is one of the four";
  for (int call = 0; call < 200; ++call) pool.run(4, 4, [&](std::size_t i) { sum += static_cast<int>(i); });
  EXPECT_EQ(sum, 28 + 200 * 6);
  EXPECT_EQ(pool.workers(), started) << "a call in a loop must not start threads";
}

TEST(ThreadPool, ALoopInsideALoopFinishes) {
  // Every outer task runs an inner parallel loop on the same pool: each caller works its own
  // tasks off, so none waits on a worker that waits on it.
  ThreadPool pool;
  std::vector<std::atomic<int>> cells(16 * 16);
  pool.run(16, 4, [&](std::size_t i) { pool.run(16, 4, [&](std::size_t j) { ++cells[i * 16 + j]; }); });
  for (std::size_t k = 0; k < cells.size(); ++k) EXPECT_EQ(cells[k], 1) << "cell " << k;
}

TEST(ThreadPool, ParallelChunksSplitByTheCountAlone) {
  // The parts depend on n and the chunk count, never on which thread runs them (the filter's
  // results are bit-exact for any number of threads because of it).
  for (const int chunks : {1, 2, 3, 7}) {
    std::mutex mutex;
    std::vector<std::array<int, 3>> parts;
    parallel_chunks(100, chunks, [&](int begin, int end, int chunk) {
      std::lock_guard lock(mutex);
      parts.push_back({begin, end, chunk});
    });
    std::sort(parts.begin(), parts.end(), [](const auto& a, const auto& b) { return a[2] < b[2]; });
    ASSERT_EQ(parts.size(), static_cast<std::size_t>(chunks));
    for (int c = 0; c < chunks; ++c) {
      EXPECT_EQ(parts[static_cast<std::size_t>(c)][0], 100 * c / chunks);
      EXPECT_EQ(parts[static_cast<std::size_t>(c)][1], 100 * (c + 1) / chunks);
    }
  }
}

}  // namespace
}  // namespace seqloc::core
