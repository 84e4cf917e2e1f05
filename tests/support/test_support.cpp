#include "support/test_support.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <gtest/gtest.h>

#include "seqloc/io/npy.hpp"

namespace seqloc::test {

ScratchDir::ScratchDir() {
  static std::atomic<int> counter{0};
  const char* base = std::getenv("SEQLOC_TEST_TMP");
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "scratch";
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  path_ = std::filesystem::path(base ? base : "/tmp/seqloc-tests") /
          (name + "." + std::to_string(getpid()) + "." + std::to_string(counter++));
  std::filesystem::remove_all(path_);
  std::filesystem::create_directories(path_);
}

ScratchDir::~ScratchDir() {
  if (!std::getenv("SEQLOC_KEEP_TMP")) {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
}

namespace {

// posix_spawn with stdin from /dev/null and stdout/stderr to the given files.
pid_t spawn(const std::string& program, const std::vector<std::string>& args, const std::string& out,
            const std::string& err) {
  std::vector<std::string> storage{program};
  storage.insert(storage.end(), args.begin(), args.end());
  std::vector<char*> argv;
  argv.reserve(storage.size() + 1);
  for (auto& a : storage) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  return rc == 0 ? pid : -1;
}

}  // namespace

CommandResult run_program(const std::string& program, const std::vector<std::string>& args) {
  ScratchDir capture;
  const auto out_path = capture / "stdout", err_path = capture / "stderr";
  CommandResult result;
  const pid_t pid = spawn(program, args, out_path.string(), err_path.string());
  if (pid < 0) {
    ADD_FAILURE() << "cannot start " << program;
    return result;
  }
  int status = 0;
  waitpid(pid, &status, 0);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  result.out = read_file(out_path);
  result.err = read_file(err_path);
  return result;
}

CommandResult run_seqloc(const std::vector<std::string>& args) { return run_program(SEQLOC_BINARY, args); }

int start_seqloc(const std::vector<std::string>& args) { return spawn(SEQLOC_BINARY, args, "/dev/null", "/dev/null"); }

std::filesystem::path osm_extract(const std::string& name) {
  const auto path = std::filesystem::path(SEQLOC_OSM_DATA) / name;
  if (!std::filesystem::exists(path)) {
    throw std::runtime_error(path.string() +
                             ": not found (the extracts ship in data/osm/; a checkout without them is broken)");
  }
  return path;
}

void write_npy_float32(const std::filesystem::path& path, int h, int w, int n, const std::vector<float>& values) {
  std::ofstream(path, std::ios::binary) << io::encode_npy_float32(h, w, n, values.data());
}

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace seqloc::test
