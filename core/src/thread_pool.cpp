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
  std::atomic<std::size_t> finished{0};  ///< tasks run (or skipped after a failure) to their end
  std::exception_ptr error;              ///< guarded by the pool's mutex
  std::size_t helpers_wanted = 0;        ///< guarded by the pool's mutex
  std::condition_variable all_finished;  ///< with the pool's mutex

  // Claims tasks until every one is claimed, running each (skipping those claimed after a failure,
  // whose first error is kept). The caller waits for the tasks, never for a helper: one that
  // arrives after the last claim leaves without touching anything but `next`.
  // `busy` (a helper's): the pool's count of workers running a task, raised while this one does.
  void drain(std::mutex& mutex, std::atomic<std::size_t>* busy = nullptr) {
    for (std::size_t i = next++; i < tasks; i = next++) {
      if (busy) ++*busy;
      if (!failed) {
        try {
          (*task)(i);
        } catch (...) {
          std::lock_guard lock(mutex);
          if (!error) error = std::current_exception();
          failed = true;
        }
      }
      if (busy) --*busy;
      if (++finished == tasks) {
        std::lock_guard lock(mutex);
        all_finished.notify_all();
      }
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
    // Every helper wanted has an idle worker of its own: loops running side by side (the filter's
    // step and the next frame's preparation) each get the threads they ask for, as when each
    // started its own, and no thread is started while enough stand idle.
    // A worker that is not running a task is idle or on its way back to the queue (it took a
    // slot of a batch whose tasks were all claimed): either way it will take a slot soon.
    wanted_ += helpers;
    while (threads_.size() - busy_ < wanted_) threads_.emplace_back([this] { work(); });
  }
  wake_.notify_all();
  batch->drain(mutex_);
  std::unique_lock lock(mutex_);
  // Helpers not yet arrived are no longer wanted; those running finish the task they hold.
  wanted_ -= batch->helpers_wanted;
  batch->helpers_wanted = 0;
  std::erase(queue_, batch);
  batch->all_finished.wait(lock, [&] { return batch->finished == batch->tasks; });
  if (batch->error) std::rethrow_exception(batch->error);
}

void ThreadPool::work() {
  std::unique_lock lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
    if (queue_.empty()) return;  // stopping
    const std::shared_ptr<Batch> batch = queue_.front();
    if (--batch->helpers_wanted == 0) queue_.pop_front();
    --wanted_;
    lock.unlock();
    batch->drain(mutex_, &busy_);  // the batch stays alive here through its shared_ptr
    lock.lock();
  }
}

void run_jobs(std::size_t jobs, int threads, const std::function<void(std::size_t)>& job) {
  ThreadPool::shared().run(jobs, threads, job);
}

}  // namespace seqloc::core
