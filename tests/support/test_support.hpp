#pragma once
// Helpers shared by the tests: scratch directories, running the seqloc binary, real data paths.

#include <filesystem>
#include <string>
#include <vector>

namespace seqloc::test {

/// A fresh empty directory for the running test, removed when the object goes out of scope
/// (kept when SEQLOC_KEEP_TMP is set, for debugging).
class ScratchDir {
 public:
  ScratchDir();
  ~ScratchDir();
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  [[nodiscard]] std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

struct CommandResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

/// Runs the seqloc binary with `args` (no shell), capturing its output.
CommandResult run_seqloc(const std::vector<std::string>& args);

/// ../shared/data/osm/NAME, or an empty path when the shared data is not there.
std::filesystem::path shared_osm(const std::string& name);

std::string read_file(const std::filesystem::path& path);

}  // namespace seqloc::test
