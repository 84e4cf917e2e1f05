#include "seqloc/pipeline/job_pool.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace seqloc::pipeline {

void run_jobs(std::size_t jobs, int threads, const std::function<void(std::size_t)>& job) {
  const auto workers = std::max<std::size_t>(1, std::min(jobs, static_cast<std::size_t>(std::max(1, threads))));
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex mutex;  // guards error
  auto work = [&] {
    try {
      for (std::size_t j = next++; j < jobs && !failed; j = next++) job(j);
    } catch (...) {
      std::lock_guard lock(mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
  };
  {
    std::vector<std::jthread> pool;
    for (std::size_t w = 1; w < workers; ++w) pool.emplace_back(work);
    work();
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace seqloc::pipeline
