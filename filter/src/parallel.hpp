#pragma once
// A minimal fork-join loop over index ranges (the filter depends on Eigen and the standard
// library only).

#include <algorithm>
#include <thread>
#include <vector>

namespace seqloc::filter::detail {

/// Calls body(begin, end, worker) on `threads` contiguous chunks of [0, n), in parallel.
template <class Body>
void parallel_chunks(int n, int threads, Body&& body) {
  threads = std::max(1, std::min(threads, n));
  if (threads == 1) {
    body(0, n, 0);
    return;
  }
  std::vector<std::jthread> workers;
  workers.reserve(static_cast<std::size_t>(threads - 1));
  for (int t = 1; t < threads; ++t) {
    workers.emplace_back([&body, n, threads, t] { body(n * t / threads, n * (t + 1) / threads, t); });
  }
  body(0, n / threads, 0);
}

}  // namespace seqloc::filter::detail
