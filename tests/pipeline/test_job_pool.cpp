// run_jobs: every job once, on the threads asked for, and the first error stops the rest.

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include "seqloc/pipeline/job_pool.hpp"

namespace seqloc::pipeline {
namespace {

TEST(JobPool, RunsEachJobOnceOnAtMostTheThreadsAsked) {
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

TEST(JobPool, TheFirstErrorStopsTheJobsNotStartedAndIsRethrown) {
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

}  // namespace
}  // namespace seqloc::pipeline
