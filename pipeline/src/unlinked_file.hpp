#pragma once
// A temporary file that has no name: created in a directory and unlinked at once, so that its
// space is freed when it is closed, on every way out (the frame store's spill, smooth's checkpoints).

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace seqloc::pipeline::detail {

/// A descriptor of a new unnamed file in `dir` (whose name began with `prefix`), or -1 with errno.
inline int open_unlinked_file(const std::filesystem::path& dir, const std::string& prefix) {
  std::string name = (dir / (prefix + "-XXXXXX")).string();
  const int fd = ::mkstemp(name.data());
  if (fd >= 0) ::unlink(name.c_str());
  return fd;
}

}  // namespace seqloc::pipeline::detail
