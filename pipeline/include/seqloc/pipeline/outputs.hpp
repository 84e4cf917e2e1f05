#pragma once
// The files `seqloc localize` writes (conventions.md sections 1 and 7), per route and mode:
// poses.csv, track.geojson (RFC 7946), trajectory.tum (for evo), metrics.json; and for a run,
// summary.json and the printed recall table. `seqloc evaluate` reads poses.csv back.

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "seqloc/pipeline/localize.hpp"

namespace seqloc::pipeline {

/// Writes a file whole (text or bytes): to a temporary name beside it, then renamed over `path`. Throws
/// DataError naming the file.
void write_file(const std::filesystem::path& path, const std::string& bytes);

/// Puts the complete folder `staged` in place of `target`. An existing target is exchanged with it
/// in one atomic step (renameat2 RENAME_EXCHANGE), so that at every instant, even across a kill -9,
/// `target` is either the previous complete folder or the new one; the previous one (now under
/// the staged name) is then removed. Throws DataError naming the folder.
void commit_directory(const std::filesystem::path& staged, const std::filesystem::path& target);

/// The staging folder of this process for `target` ("TARGET.partial-PID"), after removing those
/// that killed runs left behind (the PID in their name no longer runs).
[[nodiscard]] std::filesystem::path staging_directory(const std::filesystem::path& target);

/// Writes the four files of one route and mode into `dir` (which must exist).
void write_route_outputs(const std::filesystem::path& dir, const RouteResult& result);

/// Metrics per mode over all the routes given.
using MetricsByMode = std::map<std::string, Metrics>;

/// The recall table (position @1/3/5 m, heading @1/3/5 deg, errors), one row per mode.
[[nodiscard]] std::string format_table(const MetricsByMode& metrics);
/// summary.json of a run.
void write_summary(const std::filesystem::path& path, const MetricsByMode& metrics, const std::vector<std::string>& routes);

/// Reads a poses.csv written by write_route_outputs (for `seqloc evaluate`).
[[nodiscard]] std::vector<FramePose> read_poses_csv(const std::filesystem::path& path);

}  // namespace seqloc::pipeline
