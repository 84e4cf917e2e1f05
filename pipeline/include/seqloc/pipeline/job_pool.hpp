#pragma once
// The job pool of batch localization: seqloc localize's (route, mode) jobs, the benchmark's
// configurations, render's modes.

#include <cstddef>
#include <functional>

namespace seqloc::pipeline {

/// Runs job(0) ... job(jobs - 1), each once, on min(threads, jobs) threads (the calling thread is
/// one of them); jobs start in index order. The first exception a job throws stops further jobs
/// from starting; it is rethrown once the running ones have ended.
void run_jobs(std::size_t jobs, int threads, const std::function<void(std::size_t)>& job);

}  // namespace seqloc::pipeline
