#pragma once
// `seqloc localize` as a library call: route folders read and checked against one or more region
// caches, every mode run on every route, and the run output folder written whole (io's
// RunFolderWriter) or not at all. The command parses its options into a LocalizeRun and hands
// over; anything else that wants localize's whole job (a tool, a test) calls the same.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "seqloc/io/results.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/ros/route_bag.hpp"

namespace seqloc::pipeline {

/// Odometry noise added to every route before localizing (perturb_odometry), KITTI style.
struct OdometryNoise {
  double translation_pct = 0;
  double rotation_deg_per_m = 0;
  std::uint64_t seed = 1;
  [[nodiscard]] bool any() const { return translation_pct > 0 || rotation_deg_per_m > 0; }
};

/// What one localize run takes.
struct LocalizeRun {
  std::vector<std::filesystem::path> regions;  ///< region caches or folders of them (RegionCatalog)
  std::vector<std::filesystem::path> routes;   ///< route folders
  std::filesystem::path output;                ///< the run output folder, written whole
  std::vector<io::Mode> modes{io::Mode::seqloc};
  LocalizeOptions options;
  std::filesystem::path calibration;  ///< a calibration.json applied to options (empty: none)
  io::RouteLimits limits;
  io::Shard shard;
  OdometryNoise noise;
  /// Also a ROS 2 bag per route and mode with a belief (OUT/<route>/<mode>/bag/, docs/ros.md).
  std::optional<ros::BagOptions> bags;
};

/// How it went.
struct LocalizeRunReport {
  io::MetricsByMode metrics;  ///< the recall table's rows (io::format_table)
  std::size_t routes = 0;     ///< this shard's
  std::size_t regions = 0;
  long long frames = 0;  ///< the routes' frames (each run once per mode)
  std::size_t frames_made = 0, frames_spilled = 0, peak_frame_memory_bytes = 0;
  std::size_t bags = 0;  ///< ROS 2 bags written
};

/// Progress and notes of a run, all optional: `note` gets a line for the log, `frames` the frames
/// done and the total over all modes (called from worker threads, one at a time).
struct LocalizeRunEvents {
  std::function<void(const std::string&)> note;
  std::function<void(long long done, long long total)> frames;
};

/// Reads and checks everything first (the calibration, the regions, every route of every shard,
/// so that a shard's route names and errors do not depend on which shard runs), then localizes
/// this shard's routes in every mode and commits `run.output` whole. Throws seqloc::Error with
/// nothing written on any failure.
LocalizeRunReport run_localize(LocalizeRun run, const LocalizeRunEvents& events = {});

}  // namespace seqloc::pipeline
