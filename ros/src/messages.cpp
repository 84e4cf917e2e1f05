#include "seqloc/ros/messages.hpp"

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "seqloc/core/error.hpp"

namespace seqloc::ros {
namespace {

// The definitions a schema carries. Types used by a field are named in full (package/Type) and
// follow the message's own fields, each after the separator rosbag2 writes.
#define SEQLOC_MSG_SEPARATOR "\n================================================================================\nMSG: "

#define SEQLOC_HEADER_DEFINITION               \
  SEQLOC_MSG_SEPARATOR                         \
      "std_msgs/Header\n"                      \
      "builtin_interfaces/Time stamp\n"        \
      "string frame_id\n" SEQLOC_MSG_SEPARATOR \
      "builtin_interfaces/Time\n"              \
      "int32 sec\n"                            \
      "uint32 nanosec\n"

#define SEQLOC_POSE_DEFINITION                                      \
  SEQLOC_MSG_SEPARATOR                                              \
      "geometry_msgs/Pose\n"                                        \
      "geometry_msgs/Point position\n"                              \
      "geometry_msgs/Quaternion orientation\n" SEQLOC_MSG_SEPARATOR \
      "geometry_msgs/Point\n"                                       \
      "float64 x\n"                                                 \
      "float64 y\n"                                                 \
      "float64 z\n" SEQLOC_MSG_SEPARATOR                            \
      "geometry_msgs/Quaternion\n"                                  \
      "float64 x 0\n"                                               \
      "float64 y 0\n"                                               \
      "float64 z 0\n"                                               \
      "float64 w 1\n"

// CDR as ROS 2 sends it: the encapsulation header CDR_LE (0x00 0x01) with options 0, then each
// primitive little-endian at an offset (counted after the header) that is a multiple of its size;
// a string is a uint32 length counting its terminating NUL, its bytes and the NUL; a fixed-size
// array is its elements with no length.
class CdrWriter {
 public:
  CdrWriter() { bytes_.assign("\x00\x01\x00\x00", 4); }
  template <class T>
  CdrWriter& put(T v) {
    align(sizeof(T));
    char raw[sizeof(T)];
    std::memcpy(raw, &v, sizeof(T));  // little-endian hosts only (static_assert below)
    bytes_.append(raw, sizeof(T));
    return *this;
  }
  CdrWriter& string(std::string_view s) {
    put(static_cast<std::uint32_t>(s.size() + 1));
    bytes_.append(s);
    bytes_.push_back('\0');
    return *this;
  }
  template <std::size_t N>
  CdrWriter& doubles(const std::array<double, N>& a) {
    for (const double v : a) put(v);
    return *this;
  }
  CdrWriter& header(const Header& h) { return put(h.stamp.sec).put(h.stamp.nanosec).string(h.frame_id); }
  CdrWriter& pose(const Pose& p) { return doubles(p.position).doubles(p.orientation); }
  [[nodiscard]] std::string take() { return std::move(bytes_); }

 private:
  void align(std::size_t n) {
    const std::size_t offset = bytes_.size() - 4;
    bytes_.append((n - offset % n) % n, '\0');
  }
  std::string bytes_;
};

static_assert(std::endian::native == std::endian::little, "CdrWriter writes host-order bytes as CDR_LE");

}  // namespace

const std::string_view PoseWithCovarianceStamped::kDefinition =
    "std_msgs/Header header\n"
    "geometry_msgs/PoseWithCovariance pose\n" SEQLOC_HEADER_DEFINITION SEQLOC_MSG_SEPARATOR
    "geometry_msgs/PoseWithCovariance\n"
    "geometry_msgs/Pose pose\n"
    "float64[36] covariance\n" SEQLOC_POSE_DEFINITION;

const std::string_view PoseStamped::kDefinition =
    "std_msgs/Header header\n"
    "geometry_msgs/Pose pose\n" SEQLOC_HEADER_DEFINITION SEQLOC_POSE_DEFINITION;

const std::string_view NavSatFix::kDefinition =
    "std_msgs/Header header\n"
    "sensor_msgs/NavSatStatus status\n"
    "float64 latitude\n"
    "float64 longitude\n"
    "float64 altitude\n"
    "float64[9] position_covariance\n"
    "uint8 COVARIANCE_TYPE_UNKNOWN=0\n"
    "uint8 COVARIANCE_TYPE_APPROXIMATED=1\n"
    "uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN=2\n"
    "uint8 COVARIANCE_TYPE_KNOWN=3\n"
    "uint8 position_covariance_type\n" SEQLOC_HEADER_DEFINITION SEQLOC_MSG_SEPARATOR
    "sensor_msgs/NavSatStatus\n"
    "int8 STATUS_NO_FIX=-1\n"
    "int8 STATUS_FIX=0\n"
    "int8 STATUS_SBAS_FIX=1\n"
    "int8 STATUS_GBAS_FIX=2\n"
    "int8 status\n"
    "uint16 SERVICE_GPS=1\n"
    "uint16 SERVICE_GLONASS=2\n"
    "uint16 SERVICE_COMPASS=4\n"
    "uint16 SERVICE_GALILEO=8\n"
    "uint16 service\n";

const std::string_view StringMessage::kDefinition = "string data\n";

const std::string_view DiagnosticArray::kDefinition =
    "std_msgs/Header header\n"
    "diagnostic_msgs/DiagnosticStatus[] status\n" SEQLOC_HEADER_DEFINITION SEQLOC_MSG_SEPARATOR
    "diagnostic_msgs/DiagnosticStatus\n"
    "byte OK=0\n"
    "byte WARN=1\n"
    "byte ERROR=2\n"
    "byte STALE=3\n"
    "byte level\n"
    "string name\n"
    "string message\n"
    "string hardware_id\n"
    "diagnostic_msgs/KeyValue[] values\n" SEQLOC_MSG_SEPARATOR
    "diagnostic_msgs/KeyValue\n"
    "string key\n"
    "string value\n";

#undef SEQLOC_POSE_DEFINITION
#undef SEQLOC_HEADER_DEFINITION
#undef SEQLOC_MSG_SEPARATOR

Time time_of_seconds(double seconds) {
  const double ns = std::round(seconds * 1e9);
  if (!std::isfinite(seconds) || ns < 0 || ns >= 2147483648.0 * 1e9) {
    throw DataError("timestamp " + std::to_string(seconds) +
                    " s cannot be a ROS time (it must be finite, >= 0 and below 2^31 s)");
  }
  const auto total = static_cast<std::uint64_t>(ns);
  return {static_cast<std::int32_t>(total / 1'000'000'000), static_cast<std::uint32_t>(total % 1'000'000'000)};
}

std::uint64_t nanoseconds(Time t) { return static_cast<std::uint64_t>(t.sec) * 1'000'000'000 + t.nanosec; }

std::string encode(const PoseWithCovarianceStamped& m) {
  return CdrWriter().header(m.header).pose(m.pose).doubles(m.covariance).take();
}

std::string encode(const PoseStamped& m) { return CdrWriter().header(m.header).pose(m.pose).take(); }

std::string encode(const NavSatFix& m) {
  return CdrWriter()
      .header(m.header)
      .put(m.status)
      .put(m.service)
      .put(m.latitude)
      .put(m.longitude)
      .put(m.altitude)
      .doubles(m.position_covariance)
      .put(m.position_covariance_type)
      .take();
}

std::string encode(const DiagnosticArray& m) {
  CdrWriter w;
  w.header(m.header).put(static_cast<std::uint32_t>(m.status.size()));  // a sequence: its length, then its elements
  for (const auto& s : m.status) {
    w.put(s.level).string(s.name).string(s.message).string(s.hardware_id);
    w.put(static_cast<std::uint32_t>(s.values.size()));
    for (const auto& kv : s.values) w.string(kv.key).string(kv.value);
  }
  return w.take();
}

std::string encode(const StringMessage& m) { return CdrWriter().string(m.data).take(); }

std::array<double, 4> quaternion_of_yaw(double yaw_rad) { return {0, 0, std::sin(yaw_rad / 2), std::cos(yaw_rad / 2)}; }

}  // namespace seqloc::ros
