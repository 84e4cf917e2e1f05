#include "seqloc/core/thread_pool.hpp"

#include <algorithm>
#include <atomic>
#include <exception>

namespace seqloc::core {

// One call of run(): its tasks, claimed by index by the caller and the helpers it was given.
struct ThreadPool::Batch {
  const std::function<void(std::size_t)>* task = nullptr;
  std::size_t tasks = 0;
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;         ///< guarded by the pool's mutex
  std::size_t helpers_wanted = 0;   ///< guarded by the pool's mutex
  std::size_t helpers_running = 0;  ///< guarded by the pool's mutex
  std::condition_variable helpers_done;

  // Claims and runs tasks until none is left or one failed; the first error is kept.
  void drain(std::mutex& mutex) {
    try {
      for (std::size_t i = next++; i < tasks && !failed; i = next++) (*task)(i);
    } catch (...) {
      std::lock_guard lock(mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
  }
};

ThreadPool& ThreadPool::shared() {
  static ThreadPool pool;
  return pool;
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  for (auto& thread : threads_) thread.join();
}

std::size_t ThreadPool::workers() const {
  std::lock_guard lock(mutex_);
  return threads_.size();
}

void ThreadPool::run(std::size_t tasks, int concurrency, const std::function<void(std::size_t)>& task) {
  if (tasks == 0) return;
  const std::size_t helpers = std::min(tasks, static_cast<std::size_t>(std::max(1, concurrency))) - 1;
  if (helpers == 0) {
    for (std::size_t i = 0; i < tasks; ++i) task(i);
    return;
  }
  auto batch = std::make_shared<Batch>();
  batch->task = &task;
  batch->tasks = tasks;
  {
    std::lock_guard lock(mutex_);
    batch->helpers_wanted = helpers;
    queue_.push_back(batch);
    // Start the threads this batch would wait for: every busy worker stays busy meanwhile.
    while (idle_ < helpers) {
      threads_.emplace_back([this] { work(); });
      ++idle_;
    }
  }
  wake_.notify_all();
  batch->drain(mutex_);
  std::unique_lock lock(mutex_);
  // Helpers not yet arrived are no longer wanted; those running finish the task they hold.
  batch->helpers_wanted = 0;
  std::erase(queue_, batch);
  batch->helpers_done.wait(lock, [&] { return batch->helpers_running == 0; });
  if (batch->error) std::rethrow_exception(batch->error);
}

void ThreadPool::work() {
  std::unique_lock lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
    if (queue_.empty()) return;  // stopping
    const std::shared_ptr<Batch> batch = queue_.front();
    if (--batch->helpers_wanted == 0) queue_.pop_front();
    ++batch->helpers_running;
    --idle_;
    lock.unlock();
    batch->drain(mutex_);
    lock.lock();
    ++idle_;
    if (--batch->helpers_running == 0) batch->helpers_done.notify_all();
  }
}

void run_jobs(std::size_t jobs, int threads, const std::function<void(std::size_t)>& job) {
  ThreadPool::shared().run(jobs, threads, job);
}

}  // namespace seqloc::core
