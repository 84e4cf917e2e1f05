#pragma once
// The run output folder of `seqloc localize` (docs/route-format.md, "Outputs"), owned here as one
// writer and one reader that localize, evaluate, render and the Python module share:
//
//   OUT/summary.json                       the run's metrics per mode and its routes
//   OUT/<route>/<mode>/poses.csv           one row per frame (RFC 4180: ids may hold commas)
//   OUT/<route>/<mode>/track.geojson       RFC 7946: the estimated and true tracks, a point per frame
//   OUT/<route>/<mode>/trajectory.tum      and groundtruth.tum, for evo
//   OUT/<route>/<mode>/metrics.json        the route's recall and errors
//   OUT/<route>/<mode>/beliefs.npy, .csv   with --beliefs: each frame's belief over position,
//   OUT/<route>/<mode>/likelihoods.npy     and the frame's own likelihood in the same window
//
// The writer stages the folder beside OUT and puts it in place whole (core::commit_directory).

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "seqloc/io/npy.hpp"
#include "seqloc/io/results.hpp"

namespace seqloc::io {

/// Metrics per mode (by mode name) over all the routes given.
using MetricsByMode = std::map<std::string, Metrics>;

/// The recall table (position @1/3/5 m, heading @1/3/5 deg, errors), one row per mode.
[[nodiscard]] std::string format_table(const MetricsByMode& metrics);

/// Writes a run folder: each result into a staging folder beside `root`, then summary.json and the
/// folder into place at once by commit(). A writer destroyed before commit() removes what it
/// staged, and `root` is left as it was.
class RunFolderWriter {
 public:
  explicit RunFolderWriter(std::filesystem::path root);
  ~RunFolderWriter();
  RunFolderWriter(const RunFolderWriter&) = delete;
  RunFolderWriter& operator=(const RunFolderWriter&) = delete;

  /// Writes OUT/<route>/<mode>/ for one result and returns where it staged that folder (for more
  /// files of the same result, such as its ROS 2 bag). Throws IoError naming the file.
  std::filesystem::path add(const RouteResult& result);

  /// summary.json over every result added (`routes`: the run's route names), then the folder in
  /// place of `root`. Returns the metrics per mode that summary.json holds.
  MetricsByMode commit(const std::vector<std::string>& routes);

 private:
  std::filesystem::path root_, staged_;
  std::map<std::string, std::vector<FramePose>> poses_by_mode_;
  bool committed_ = false;
};

/// Writes the files of one route and mode into `dir` (which must exist).
void write_route_outputs(const std::filesystem::path& dir, const RouteResult& result);

/// summary.json of a run; `honesty`: each mode's uncertainty calibration, where it has one.
void write_summary(const std::filesystem::path& path, const MetricsByMode& metrics,
                   const std::vector<std::string>& routes,
                   const std::map<std::string, UncertaintyCalibration>& honesty = {});

/// Reads a poses.csv written by write_route_outputs. Throws DataError naming the file and line.
[[nodiscard]] std::vector<FramePose> read_poses_csv(const std::filesystem::path& path);

/// A poses.csv of a run and the mode it holds (the name of its folder).
struct PosesFile {
  std::filesystem::path path;
  std::string mode;
};

/// The poses.csv files in or under `folders`: each a whole run folder (OUT), a route's folder
/// (OUT/<route>) or a mode's folder (OUT/<route>/<mode>), in any mix; a file reached twice counts
/// once. Throws DataError for a folder that is not one, or when none holds a poses.csv.
[[nodiscard]] std::vector<PosesFile> find_poses_files(const std::vector<std::filesystem::path>& folders);

/// The metrics per mode of poses.csv files (the recall table of `seqloc evaluate`).
[[nodiscard]] MetricsByMode evaluate_poses_files(const std::vector<PosesFile>& files);

/// What `localize --beliefs` kept for a route and mode: beliefs.npy, (frames, height, width)
/// float32, each frame window's origin in beliefs.csv, and each frame's own likelihood in that
/// window in likelihoods.npy (same shape).
class KeptBeliefs {
 public:
  /// Reads `dir` (OUT/<route>/<mode>). Throws DataError naming the file when they are missing or
  /// do not match a route of `frames` frames.
  KeptBeliefs(const std::filesystem::path& dir, std::size_t frames);
  [[nodiscard]] int width() const { return npy_.extent(2); }
  [[nodiscard]] int height() const { return npy_.extent(1); }
  /// Frame `frame`'s belief over position, height x width, row-major.
  [[nodiscard]] std::vector<double> marginal(std::size_t frame) const;
  /// Frame `frame`'s own likelihood over position in its window, height x width, row-major. Throws
  /// DataError naming likelihoods.npy when the run did not keep it.
  [[nodiscard]] std::vector<double> likelihood(std::size_t frame) const;
  /// The region pixel of frame `frame`'s window cell (0, 0).
  [[nodiscard]] const std::array<std::int64_t, 2>& origin(std::size_t frame) const { return origins_.at(frame); }

 private:
  NpyArray npy_;                            ///< (frames, height, width)
  std::optional<NpyArray> likelihoods_;     ///< the same shape, when the run kept it
  std::filesystem::path likelihoods_path_;  ///< where it was looked for, when it was not
  std::vector<std::array<std::int64_t, 2>> origins_;
};

/// A run folder read back.
class RunFolder {
 public:
  explicit RunFolder(std::filesystem::path root) : root_(std::move(root)) {}
  [[nodiscard]] const std::filesystem::path& root() const { return root_; }
  /// OUT/<route>/<mode>.
  [[nodiscard]] std::filesystem::path mode_dir(const std::string& route, Mode mode) const {
    return root_ / route / mode_name(mode);
  }
  /// Whether the run has results for `route` (its folder exists).
  [[nodiscard]] bool has_route(const std::string& route) const;
  /// The poses of every mode the run has for `route` (any of kModes), in kModes' order.
  [[nodiscard]] std::vector<std::pair<Mode, std::vector<FramePose>>> route_poses(const std::string& route) const;
  /// Whether localize kept the beliefs of `route` in `mode` (--beliefs).
  [[nodiscard]] bool has_beliefs(const std::string& route, Mode mode) const;

 private:
  std::filesystem::path root_;
};

}  // namespace seqloc::io
