#pragma once
// The ROS 2 messages seqloc records, as plain structs, each with its type name and its definition
// in the "ros2msg" form a bag's schema carries (the type's fields, then every type it uses after a
// line of 80 '=' and "MSG: package/Type"), and encode(), which gives the message's bytes in CDR
// (little-endian, XCDR1, behind the 4-byte encapsulation header) as rmw implementations send them.
//
// Field layouts follow the ROS 2 interface definitions (std_msgs, builtin_interfaces,
// geometry_msgs, sensor_msgs of common_interfaces): every field in order, none left out, so that
// any reader decodes the bytes with the definitions it has.

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace seqloc::ros {

/// builtin_interfaces/msg/Time.
struct Time {
  std::int32_t sec = 0;
  std::uint32_t nanosec = 0;
};
/// The Time of `seconds` (>= 0, < 2^31), rounded to the nanosecond. Throws DataError otherwise.
[[nodiscard]] Time time_of_seconds(double seconds);
/// Nanoseconds since the epoch of a Time (an MCAP log time).
[[nodiscard]] std::uint64_t nanoseconds(Time t);

/// std_msgs/msg/Header.
struct Header {
  Time stamp;
  std::string frame_id;
};

/// geometry_msgs/msg/Pose: a position and a unit quaternion (x, y, z, w).
struct Pose {
  std::array<double, 3> position{};
  std::array<double, 4> orientation{0, 0, 0, 1};
};

/// geometry_msgs/msg/PoseWithCovarianceStamped. The covariance is 6 x 6 row-major over
/// (x, y, z, rotation about x, about y, about z), in the header's frame.
struct PoseWithCovarianceStamped {
  static constexpr std::string_view kType = "geometry_msgs/msg/PoseWithCovarianceStamped";
  static const std::string_view kDefinition;
  Header header;
  Pose pose;
  std::array<double, 36> covariance{};
};

/// geometry_msgs/msg/PoseStamped.
struct PoseStamped {
  static constexpr std::string_view kType = "geometry_msgs/msg/PoseStamped";
  static const std::string_view kDefinition;
  Header header;
  Pose pose;
};

/// sensor_msgs/msg/NavSatFix (with its sensor_msgs/msg/NavSatStatus). The position covariance is
/// 3 x 3 row-major in east, north, up at the fix, in m^2.
struct NavSatFix {
  static constexpr std::string_view kType = "sensor_msgs/msg/NavSatFix";
  static const std::string_view kDefinition;
  static constexpr std::int8_t kStatusFix = 0;
  static constexpr std::uint8_t kCovarianceUnknown = 0, kCovarianceApproximated = 1, kCovarianceDiagonalKnown = 2,
                                kCovarianceKnown = 3;
  Header header;
  std::int8_t status = kStatusFix;
  std::uint16_t service = 0;  ///< which GNSS constellations: none, seqloc is not one
  double latitude = 0, longitude = 0, altitude = 0;
  std::array<double, 9> position_covariance{};
  std::uint8_t position_covariance_type = kCovarianceUnknown;
};

/// std_msgs/msg/String.
struct StringMessage {
  static constexpr std::string_view kType = "std_msgs/msg/String";
  static const std::string_view kDefinition;
  std::string data;
};

/// diagnostic_msgs/msg/KeyValue.
struct KeyValue {
  std::string key, value;
};
/// diagnostic_msgs/msg/DiagnosticStatus.
struct DiagnosticStatus {
  static constexpr std::uint8_t kOk = 0, kWarn = 1, kError = 2, kStale = 3;
  std::uint8_t level = kOk;
  std::string name, message, hardware_id;
  std::vector<KeyValue> values;
};
/// diagnostic_msgs/msg/DiagnosticArray.
struct DiagnosticArray {
  static constexpr std::string_view kType = "diagnostic_msgs/msg/DiagnosticArray";
  static const std::string_view kDefinition;
  Header header;
  std::vector<DiagnosticStatus> status;
};

[[nodiscard]] std::string encode(const PoseWithCovarianceStamped& m);
[[nodiscard]] std::string encode(const DiagnosticArray& m);
[[nodiscard]] std::string encode(const PoseStamped& m);
[[nodiscard]] std::string encode(const NavSatFix& m);
[[nodiscard]] std::string encode(const StringMessage& m);

/// The unit quaternion of a rotation by `yaw_rad` about +z (counter-clockwise seen from above).
[[nodiscard]] std::array<double, 4> quaternion_of_yaw(double yaw_rad);

}  // namespace seqloc::ros
