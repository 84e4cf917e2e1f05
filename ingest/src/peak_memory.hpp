#pragma once
// The process's peak resident memory, per stage: Linux keeps the high-water mark (VmHWM) and
// lets a process reset it (writing 5 to /proc/self/clear_refs, Linux 4.0 and later).

#include <malloc.h>

#include <fstream>
#include <optional>
#include <string>

namespace seqloc::ingest::detail {

/// A memory figure of /proc/self/status ("VmHWM:", "VmRSS:") in MB; nothing where Linux's /proc
/// is not there.
[[nodiscard]] inline std::optional<double> status_mb(const std::string& wanted) {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == wanted) {
      double kb = 0;
      if (status >> kb) return kb / 1024.0;
      return std::nullopt;
    }
    status.ignore(1 << 12, '\n');
  }
  return std::nullopt;
}

/// Peak resident memory in MB since the start or the last reset.
[[nodiscard]] inline std::optional<double> peak_rss_mb() { return status_mb("VmHWM:"); }
/// Resident memory in MB now.
[[nodiscard]] inline std::optional<double> rss_mb() { return status_mb("VmRSS:"); }

/// Hands memory freed to the allocator back to the system (glibc keeps freed small blocks
/// otherwise), so that a later stage's resident memory is its own.
inline void release_free_memory() { ::malloc_trim(0); }

/// Starts a new high-water mark at the current resident memory (no effect where not supported).
inline void reset_peak_rss() {
  std::ofstream clear_refs("/proc/self/clear_refs");
  clear_refs << "5";
}

}  // namespace seqloc::ingest::detail
