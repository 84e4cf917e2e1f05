#pragma once
// A localized route as a ROS 2 bag (docs/ros.md): a folder that rosbag2 opens (`ros2 bag info`,
// `ros2 bag play`) and Foxglove reads, holding one MCAP file in the ROS 2 profile and the
// metadata.yaml rosbag2 expects beside it. Per frame, at the frame's timestamp:
//
//   /seqloc/pose         geometry_msgs/msg/PoseWithCovarianceStamped  in the local ENU frame
//   /seqloc/fix          sensor_msgs/msg/NavSatFix                     WGS84, covariance in ENU at the fix
//   /seqloc/diagnostics  diagnostic_msgs/msg/DiagnosticArray           mass within 5 m, second mode, flags
//   /seqloc/frame        std_msgs/msg/String                           the route's frame id (frames.csv)
//   /seqloc/truth/pose   geometry_msgs/msg/PoseStamped                 ground truth, frames with a true heading
//   /seqloc/truth/fix    sensor_msgs/msg/NavSatFix                     ground truth, frames with a true position
//
// The local frame is the east-north-up tangent plane of the WGS84 ellipsoid at an origin (height
// 0): x east, y north, z up, in metres. Its name and origin are in the MCAP file's Metadata record
// "seqloc" and in metadata.yaml's custom_data. The region CRS's grid axes are turned into it at
// each pose (the meridian convergence there, conventions.md section 1).

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "seqloc/io/results.hpp"

namespace seqloc::ros {

struct BagOptions {
  /// The name of the local east-north-up frame: every pose's header.frame_id.
  std::string frame_id = "seqloc_enu";
  /// The vehicle's frame: the NavSatFix messages' header.frame_id (REP 105's base_link).
  std::string base_frame = "base_link";
  /// The ENU frame's origin (latitude, longitude in degrees). Unset: the route's first ground
  /// truth position where it has one (the same for every mode), else its first pose.
  std::optional<std::array<double, 2>> origin_deg;
  /// Validates the names (non-empty) and the origin (a latitude within +-90, a finite longitude).
  void validate() const;
};

/// The variance (m^2, rad^2) given to what seqloc does not estimate: height, roll and pitch. A
/// fusion stack should not fuse them from seqloc at all (docs/ros.md).
inline constexpr double kUnmeasuredVariance = 1e6;

struct BagSummary {
  std::filesystem::path mcap;  ///< the MCAP file inside the bag folder
  std::uint64_t messages = 0;
  std::array<double, 2> origin_deg{};
};

/// Writes the bag of a route's result into the folder `dir` (created, or replaced whole once the
/// new one is complete; named after it: DIR/<dir name>_0.mcap and DIR/metadata.yaml).
/// Every pose must carry its uncertainty (the modes with a belief); throws UsageError naming the
/// mode otherwise, DataError for a timestamp that is no ROS time, IoError when writing fails.
BagSummary write_route_bag(const std::filesystem::path& dir, const io::RouteResult& result,
                           const BagOptions& options = {});

/// A pose in a bag's local frame: what /seqloc/pose and /seqloc/fix carry of it.
struct LocalPose {
  std::array<double, 3> position{};  ///< m: x east, y north, z up of the frame
  double yaw_rad = 0;                ///< the heading, counter-clockwise from the frame's x axis (REP 103)
  /// The position covariance (xx, xy, yy in m^2): along the true east and north at the pose (the
  /// fix's), and along the frame's x and y (the pose's). The region CRS's grid axes differ from
  /// both by the meridian convergence, the frame's from the pose's by the tangent planes' turn.
  std::array<double, 3> fix_covariance{}, frame_covariance{};
};
/// `pose` (with its uncertainty) in the frame at `origin_deg` (latitude, longitude).
[[nodiscard]] LocalPose to_local_frame(const io::FramePose& pose, const std::array<double, 2>& origin_deg);

/// Whether a mode's poses carry an uncertainty, so that write_route_bag takes its results.
[[nodiscard]] bool has_uncertainty(const io::RouteResult& result);

}  // namespace seqloc::ros
