#pragma once
// Outputs that are whole or absent: a file written under a temporary name and renamed over its
// path, a folder staged beside its target and exchanged with it in one step, and a scratch file
// with no name at all. Bad input never leaves half an output behind.

#include <filesystem>
#include <string>

namespace seqloc::core {

/// Writes a file whole (text or bytes): to a temporary name beside it, then renamed over `path`.
/// Throws IoError naming the file.
void write_file(const std::filesystem::path& path, const std::string& bytes);

/// Moves the finished file `partial` onto `target` in one step (a rename within a file system), so
/// that `target` is at every instant the previous file or the new one, never part of one. The one
/// place a file is committed; write_file() commits through it. Throws IoError naming `target`.
void commit_file(const std::filesystem::path& partial, const std::filesystem::path& target);

/// Puts the complete folder `staged` in place of `target`. An existing target is exchanged with it
/// in one atomic step (renameat2 RENAME_EXCHANGE), so that at every instant, even across a kill -9,
/// `target` is either the previous complete folder or the new one; the previous one (now under
/// the staged name) is then removed. Throws IoError naming the folder.
void commit_directory(const std::filesystem::path& staged, const std::filesystem::path& target);

/// The staging folder of this process for `target` ("TARGET.partial-PID"), after removing those
/// that killed runs left behind (the PID in their name no longer runs).
[[nodiscard]] std::filesystem::path staging_directory(const std::filesystem::path& target);

/// A descriptor of a new file in `dir` that has no name (created as PREFIX-XXXXXX and unlinked at
/// once), so that its space is freed when it is closed, on every way out; or -1 with errno.
[[nodiscard]] int open_unlinked_file(const std::filesystem::path& dir, const std::string& prefix);

}  // namespace seqloc::core
