#pragma once
// Shared by the fuzz targets: inputs that the code under test reads from a path are handed over
// as anonymous in-memory files (memfd), so a fuzz run never touches the disk and never leaves
// files behind, yet exercises exactly the code a user's file goes through (open, fstat, mmap).

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>

namespace seqloc::fuzz {

class MemoryFile {
 public:
  MemoryFile(const std::uint8_t* data, std::size_t size) : fd_(::memfd_create("seqloc-fuzz", MFD_CLOEXEC)) {
    if (fd_ < 0) {
      std::perror("memfd_create");
      std::abort();
    }
    std::size_t written = 0;
    while (written < size) {
      const ssize_t n = ::write(fd_, data + written, size - written);
      if (n <= 0) {
        std::perror("write");
        std::abort();
      }
      written += static_cast<std::size_t>(n);
    }
  }
  ~MemoryFile() { ::close(fd_); }
  MemoryFile(const MemoryFile&) = delete;
  MemoryFile& operator=(const MemoryFile&) = delete;

  /// A path that opens this file (the process's own descriptor).
  [[nodiscard]] std::filesystem::path path() const { return "/proc/self/fd/" + std::to_string(fd_); }

 private:
  int fd_;
};

/// A directory under /tmp for one fuzz process (mkdtemp), removed with everything in it when the
/// object is destroyed.
class ScratchDir {
 public:
  explicit ScratchDir(const char* name) {
    std::string pattern = std::string("/tmp/seqloc-fuzz-") + name + "-XXXXXX";
    if (!::mkdtemp(pattern.data())) {
      std::perror("mkdtemp");
      std::abort();
    }
    path_ = pattern;
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;

  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

/// Splits an input at the first occurrence of `separator`: (before, after); after is empty when
/// the separator is missing. Lets one fuzz input carry two files.
inline std::pair<std::string_view, std::string_view> split_once(std::string_view input, std::string_view separator) {
  const std::size_t at = input.find(separator);
  if (at == std::string_view::npos) return {input, {}};
  return {input.substr(0, at), input.substr(at + separator.size())};
}

}  // namespace seqloc::fuzz
