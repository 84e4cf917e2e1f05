#include "seqloc/core/files.hpp"

#include <fcntl.h>  // AT_FDCWD
#include <unistd.h>

#include <cerrno>
#include <csignal>  // ::kill (POSIX)
#include <cstdio>   // ::renameat2, RENAME_EXCHANGE (glibc)
#include <cstdlib>
#include <cstring>
#include <fstream>

#include "seqloc/core/error.hpp"

namespace seqloc::core {

void write_file(const std::filesystem::path& path, const std::string& bytes) {
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary);
    out << bytes;
    out.close();
    if (!out) throw IoError(path.string() + ": cannot write");
  }
  commit_file(tmp, path);
}

void commit_file(const std::filesystem::path& partial, const std::filesystem::path& target) {
  std::error_code ec;
  std::filesystem::rename(partial, target, ec);
  if (ec) throw IoError(target.string() + ": cannot move the finished file into place: " + ec.message());
}

void commit_directory(const std::filesystem::path& staged, const std::filesystem::path& target) {
  auto fail = [&](const std::string& why) {
    throw IoError(target.string() + ": cannot move the finished output into place: " + why);
  };
  std::error_code ec;
  if (::renameat2(AT_FDCWD, staged.c_str(), AT_FDCWD, target.c_str(), RENAME_EXCHANGE) == 0) {
    std::filesystem::remove_all(staged, ec);  // the previous folder; a leftover is removed next run
    return;
  }
  const int exchange_error = errno;
  if (exchange_error == ENOENT && std::filesystem::exists(staged, ec)) {
    // No target yet: a plain rename, atomic too.
    std::filesystem::rename(staged, target, ec);
    if (ec) fail(ec.message());
    return;
  }
  if (exchange_error != EINVAL && exchange_error != ENOSYS) fail(std::strerror(exchange_error));
  // A file system without RENAME_EXCHANGE: two renames, with a short window in which `target`
  // is missing and the previous folder sits beside it as TARGET.old.
  const std::filesystem::path old = target.string() + ".old";
  std::filesystem::remove_all(old, ec);
  std::filesystem::rename(target, old, ec);
  if (!ec) std::filesystem::rename(staged, target, ec);
  if (ec) fail(ec.message());
  std::filesystem::remove_all(old, ec);
}

std::filesystem::path staging_directory(const std::filesystem::path& target) {
  const std::string prefix = target.filename().string() + ".partial-";
  std::filesystem::path parent = target.parent_path();
  if (parent.empty()) parent = ".";
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(parent, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
    const auto pid = static_cast<pid_t>(std::stol(digits));
    if (pid != ::getpid() && ::kill(pid, 0) != 0 && errno == ESRCH) std::filesystem::remove_all(entry.path(), ec);
  }
  std::filesystem::path staged = target.string() + ".partial-" + std::to_string(::getpid());
  std::filesystem::remove_all(staged, ec);
  return staged;
}

int open_unlinked_file(const std::filesystem::path& dir, const std::string& prefix) {
  std::string name = (dir / (prefix + "-XXXXXX")).string();
  const int fd = ::mkstemp(name.data());
  if (fd >= 0) ::unlink(name.c_str());
  return fd;
}

}  // namespace seqloc::core
