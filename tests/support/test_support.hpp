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

/// Runs a program with `args` (no shell) to completion, capturing its output.
CommandResult run_program(const std::string& program, const std::vector<std::string>& args);
/// Runs the seqloc binary.
CommandResult run_seqloc(const std::vector<std::string>& args);
/// Starts the seqloc binary in the background (output discarded); returns its pid, or -1.
int start_seqloc(const std::vector<std::string>& args);

/// data/osm/NAME (data/osm/SOURCES.md); std::runtime_error when it is not there.
std::filesystem::path osm_extract(const std::string& name);

std::string read_file(const std::filesystem::path& path);

/// Writes a float32 .npy file of shape (h, w, n) (NumPy's format 1.0).
void write_npy_float32(const std::filesystem::path& path, int h, int w, int n, const std::vector<float>& values);

}  // namespace seqloc::test
