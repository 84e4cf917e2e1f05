#include "seqloc/ros/route_bag.hpp"

#include <GeographicLib/LocalCartesian.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <set>
#include <vector>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/ros/mcap_writer.hpp"
#include "seqloc/ros/messages.hpp"

namespace seqloc::ros {
namespace {

using Matrix2 = std::array<std::array<double, 2>, 2>;

Matrix2 multiply(const Matrix2& a, const Matrix2& b) {
  Matrix2 c{};
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
  return c;
}

Matrix2 transposed(const Matrix2& a) { return {{{a[0][0], a[1][0]}, {a[0][1], a[1][1]}}}; }

// R S R^T: a covariance S taken into the axes R maps onto.
Matrix2 rotate_covariance(const Matrix2& r, const Matrix2& s) { return multiply(multiply(r, s), transposed(r)); }

// The grid axes of the region CRS in the true east-north axes at a point whose meridian
// convergence is gamma (compass = grid + gamma, conventions.md section 1): a grid vector turns
// clockwise by gamma.
Matrix2 grid_to_true(double gamma_deg) {
  const double c = std::cos(gamma_deg * core::kDegToRad), s = std::sin(gamma_deg * core::kDegToRad);
  return {{{c, s}, {-s, c}}};
}

// The local ENU frame at the origin, and where a point and its axes land in it.
class LocalFrame {
 public:
  explicit LocalFrame(const std::array<double, 2>& origin_deg) : enu_(origin_deg[0], origin_deg[1], 0.0) {}

  struct At {
    std::array<double, 3> position{};
    Matrix2 axes{};  ///< true east-north at the point -> the frame's x, y (the tangent planes' turn)
  };
  [[nodiscard]] At at(double lat_deg, double lon_deg) const {
    At a;
    std::vector<double> m(9);  // the point's own ENU axes in the frame's, row-major
    enu_.Forward(lat_deg, lon_deg, 0.0, a.position[0], a.position[1], a.position[2], m);
    a.axes = {{{m[0], m[1]}, {m[3], m[4]}}};
    return a;
  }
  // A pose with its uncertainty: covariance about the estimate, grid axes -> true east-north at the
  // pose -> the frame.
  [[nodiscard]] LocalPose pose(const io::FramePose& p) const {
    const auto& u = *p.uncertainty;
    const At a = at(p.lat_deg, p.lon_deg);
    const Matrix2 grid{{{u.cov_xx_m2, u.cov_xy_m2}, {u.cov_xy_m2, u.cov_yy_m2}}};
    const double gamma = core::wrap180(p.compass_heading_deg - p.grid_heading_deg);
    const Matrix2 at_fix = rotate_covariance(grid_to_true(gamma), grid);
    const Matrix2 local = rotate_covariance(a.axes, at_fix);
    return {a.position,
            yaw_rad(a, p.compass_heading_deg),
            {at_fix[0][0], at_fix[0][1], at_fix[1][1]},
            {local[0][0], local[0][1], local[1][1]}};
  }
  // The yaw (counter-clockwise from the frame's x axis, REP 103) of a compass heading at a point.
  [[nodiscard]] static double yaw_rad(const At& a, double compass_deg) {
    const double b = compass_deg * core::kDegToRad;
    const double east = std::sin(b), north = std::cos(b);
    return std::atan2(a.axes[1][0] * east + a.axes[1][1] * north, a.axes[0][0] * east + a.axes[0][1] * north);
  }

 private:
  GeographicLib::LocalCartesian enu_;
};

std::string degrees(double v) {
  char s[32];
  std::snprintf(s, sizeof s, "%.9f", v);
  return s;
}

// The origin, to 1e-9 degrees (0.1 mm): the frame is built on exactly the value its metadata states.
std::array<double, 2> origin_of(const io::RouteResult& r, const BagOptions& o) {
  std::array<double, 2> origin{r.poses.front().lat_deg, r.poses.front().lon_deg};
  if (o.origin_deg) {
    origin = *o.origin_deg;
  } else {
    const auto truth = std::find_if(r.poses.begin(), r.poses.end(), [](const auto& p) { return p.truth; });
    if (truth != r.poses.end()) origin = {truth->truth->lat_deg, truth->truth->lon_deg};
  }
  for (double& v : origin) v = std::stod(degrees(v));
  return origin;
}

std::string number(double v) {
  char s[32];
  std::snprintf(s, sizeof s, "%.10g", v);
  return s;
}

// What is true of the whole bag: the frame, its origin, the route.
McapMap bag_metadata(const io::RouteResult& r, const BagOptions& o, const std::array<double, 2>& origin) {
  std::set<std::string> regions;
  for (const auto& p : r.poses) regions.insert(p.region);
  std::string region_list;
  for (const auto& name : regions) region_list += (region_list.empty() ? "" : ",") + name;
  return {{"frame_id", o.frame_id},
          {"frame",
           "east-north-up tangent plane of the WGS84 ellipsoid at the origin (height 0 m); x east, y north, "
           "z up, metres"},
          {"origin_lat_deg", degrees(origin[0])},
          {"origin_lon_deg", degrees(origin[1])},
          {"origin_height_m", "0"},
          {"base_frame", o.base_frame},
          {"route", r.route},
          {"mode", io::mode_name(r.mode)},
          {"regions", region_list},
          {"unmeasured_variance", number(kUnmeasuredVariance)},
          {"writer", "seqloc " SEQLOC_VERSION}};
}

std::string yes_no(bool b) { return b ? "true" : "false"; }

DiagnosticArray diagnostics(const io::FramePose& p, const io::RouteResult& r, const Header& header) {
  const auto& u = *p.uncertainty;
  DiagnosticStatus s;
  s.name = std::string("seqloc/") + io::mode_name(r.mode);
  s.hardware_id = r.route;
  s.level = u.multimodal ? DiagnosticStatus::kWarn : DiagnosticStatus::kOk;
  s.message = u.multimodal ? "multimodal: another place holds " + number(std::round(u.second_mode_share * 1000) / 10) +
                                 " % of the belief"
                           : "one mode";
  s.values = {{"frame", p.frame},
              {"mass_within_5m", number(u.mass_within_5m)},
              {"second_mode_share", number(u.second_mode_share)},
              {"multimodal", yes_no(u.multimodal)},
              {"heading_sd_deg", number(u.heading_sd_deg)},
              {"relocalized", yes_no(p.relocalized)},
              {"entropy", number(p.entropy)},
              {"etu_weight", number(p.etu_weight)},
              {"volume_power", number(p.volume_power)},
              {"region", p.region}};
  return {Header{header.stamp, ""}, {std::move(s)}};
}

// The estimate: the pose in the local frame with its covariance, and the fix with its own.
void add_estimate(McapWriter& w, const std::array<std::uint16_t, 2>& ch, const io::FramePose& p,
                  const LocalFrame& frame, const BagOptions& o, const Header& stamp_only) {
  const auto& u = *p.uncertainty;
  const LocalPose local = frame.pose(p);
  PoseWithCovarianceStamped pose;
  pose.header = {stamp_only.stamp, o.frame_id};
  pose.pose.position = local.position;
  pose.pose.orientation = quaternion_of_yaw(local.yaw_rad);
  pose.covariance[0] = local.frame_covariance[0];
  pose.covariance[1] = pose.covariance[6] = local.frame_covariance[1];
  pose.covariance[7] = local.frame_covariance[2];
  pose.covariance[14] = pose.covariance[21] = pose.covariance[28] = kUnmeasuredVariance;  // z, roll, pitch
  const double yaw_sd = u.heading_sd_deg * core::kDegToRad;
  pose.covariance[35] = yaw_sd * yaw_sd;
  const std::uint64_t t = nanoseconds(stamp_only.stamp);
  w.add_message(ch[0], t, t, encode(pose));

  NavSatFix fix;
  fix.header = {stamp_only.stamp, o.base_frame};
  fix.latitude = p.lat_deg;
  fix.longitude = p.lon_deg;
  fix.altitude = std::numeric_limits<double>::quiet_NaN();  // not estimated (NavSatFix: NaN)
  const auto& c = local.fix_covariance;
  fix.position_covariance = {c[0], c[1], 0, c[1], c[2], 0, 0, 0, kUnmeasuredVariance};
  // The horizontal block is the belief's own; the vertical is a stand-in, hence "approximated".
  fix.position_covariance_type = NavSatFix::kCovarianceApproximated;
  w.add_message(ch[1], t, t, encode(fix));
}

// The ground truth where the frame has it: a fix, and a pose where the heading is known too.
void add_truth(McapWriter& w, const std::array<std::uint16_t, 2>& ch, const io::FramePose& p, const LocalFrame& frame,
               const BagOptions& o, const Header& stamp_only) {
  const std::uint64_t t = nanoseconds(stamp_only.stamp);
  NavSatFix fix;
  fix.header = {stamp_only.stamp, o.base_frame};
  fix.latitude = p.truth->lat_deg;
  fix.longitude = p.truth->lon_deg;
  fix.altitude = std::numeric_limits<double>::quiet_NaN();
  fix.position_covariance_type = NavSatFix::kCovarianceUnknown;
  w.add_message(ch[1], t, t, encode(fix));
  if (!p.truth->compass_heading_deg) return;
  const LocalFrame::At at = frame.at(p.truth->lat_deg, p.truth->lon_deg);
  PoseStamped pose;
  pose.header = {stamp_only.stamp, o.frame_id};
  pose.pose.position = at.position;
  pose.pose.orientation = quaternion_of_yaw(LocalFrame::yaw_rad(at, *p.truth->compass_heading_deg));
  w.add_message(ch[0], t, t, encode(pose));
}

// A channel of a message type; each type's schema is added once, on its first channel.
class Channels {
 public:
  explicit Channels(McapWriter& w) : w_(w) {}
  template <class Message>
  std::uint16_t add(std::string_view topic) {
    auto [it, added] = schemas_.try_emplace(Message::kType, 0);
    if (added) it->second = w_.add_schema(Message::kType, "ros2msg", Message::kDefinition);
    return w_.add_channel(it->second, topic, "cdr");
  }

 private:
  McapWriter& w_;
  std::map<std::string_view, std::uint16_t> schemas_;
};

struct Topic {
  std::string name;
  std::string_view type;
  std::uint16_t id = 0;
};

std::string yaml_string(std::string_view s) {
  std::string q = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') {
      q += '\\';
      q += c;
    } else if (c == '\n') {
      q += "\\n";
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char e[8];
      std::snprintf(e, sizeof e, "\\x%02x", static_cast<unsigned char>(c));
      q += e;
    } else {
      q += c;
    }
  }
  return q + "\"";
}

// rosbag2's metadata.yaml (its version 5 layout): what `ros2 bag info` shows and `ros2 bag play`
// needs to open the folder.
std::string metadata_yaml(const std::string& file, const std::vector<Topic>& topics, const McapWriter& w,
                          std::uint64_t start_ns, std::uint64_t end_ns, const McapMap& custom) {
  std::uint64_t total = 0;
  for (const auto& t : topics) total += w.message_count(t.id);
  const std::string start = std::to_string(start_ns), duration = std::to_string(end_ns - start_ns);
  std::string y = "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n";
  y += "  duration:\n    nanoseconds: " + duration + "\n";
  y += "  starting_time:\n    nanoseconds_since_epoch: " + start + "\n";
  y += "  message_count: " + std::to_string(total) + "\n  topics_with_message_count:\n";
  for (const auto& t : topics) {
    y += "    - topic_metadata:\n        name: " + yaml_string(t.name) + "\n        type: " + std::string(t.type) +
         "\n        serialization_format: cdr\n        offered_qos_profiles: \"\"\n      message_count: " +
         std::to_string(w.message_count(t.id)) + "\n";
  }
  y += "  compression_format: \"\"\n  compression_mode: \"\"\n";
  y += "  relative_file_paths:\n    - " + yaml_string(file) + "\n";
  y += "  files:\n    - path: " + yaml_string(file) +
       "\n      starting_time:\n        nanoseconds_since_epoch: " + start +
       "\n      duration:\n        nanoseconds: " + duration + "\n      message_count: " + std::to_string(total) + "\n";
  y += "  custom_data:\n";
  for (const auto& [k, v] : custom) y += "    " + k + ": " + yaml_string(v) + "\n";
  return y;
}

}  // namespace

void BagOptions::validate() const {
  if (frame_id.empty()) throw UsageError("bag frame id: must not be empty");
  if (base_frame.empty()) throw UsageError("bag base frame: must not be empty");
  if (origin_deg && (!(std::abs((*origin_deg)[0]) <= 90) || !std::isfinite((*origin_deg)[1]))) {
    throw UsageError("bag origin: " + number((*origin_deg)[0]) + "," + number((*origin_deg)[1]) +
                     " is not a latitude within +-90 and a longitude");
  }
}

LocalPose to_local_frame(const io::FramePose& pose, const std::array<double, 2>& origin_deg) {
  if (!pose.uncertainty) throw UsageError("frame " + pose.frame + ": no uncertainty to take into a local frame");
  return LocalFrame(origin_deg).pose(pose);
}

bool has_uncertainty(const io::RouteResult& result) {
  if (result.poses.empty()) return false;
  for (const auto& p : result.poses) {
    if (!p.uncertainty) return false;
  }
  return true;
}

BagSummary write_route_bag(const std::filesystem::path& dir, const io::RouteResult& result, const BagOptions& options) {
  options.validate();
  if (!has_uncertainty(result)) {
    throw UsageError(std::string("route ") + result.route + ", mode " + io::mode_name(result.mode) +
                     ": its poses carry no uncertainty (only the modes with a belief do: online, seqloc, smooth), "
                     "so it has no bag");
  }
  BagSummary summary;
  summary.origin_deg = origin_of(result, options);
  const LocalFrame frame(summary.origin_deg);
  McapWriter w("ros2", "seqloc " SEQLOC_VERSION);
  std::vector<Topic> topics{{"/seqloc/pose", PoseWithCovarianceStamped::kType},
                            {"/seqloc/fix", NavSatFix::kType},
                            {"/seqloc/diagnostics", DiagnosticArray::kType},
                            {"/seqloc/frame", StringMessage::kType}};
  Channels channels(w);
  topics[0].id = channels.add<PoseWithCovarianceStamped>(topics[0].name);
  topics[1].id = channels.add<NavSatFix>(topics[1].name);
  topics[2].id = channels.add<DiagnosticArray>(topics[2].name);
  topics[3].id = channels.add<StringMessage>(topics[3].name);
  const bool with_truth = std::any_of(result.poses.begin(), result.poses.end(), [](const auto& p) { return p.truth; });
  if (with_truth) {
    topics.push_back({"/seqloc/truth/pose", PoseStamped::kType, channels.add<PoseStamped>("/seqloc/truth/pose")});
    topics.push_back({"/seqloc/truth/fix", NavSatFix::kType, channels.add<NavSatFix>("/seqloc/truth/fix")});
  }
  const McapMap metadata = bag_metadata(result, options, summary.origin_deg);
  w.add_metadata("seqloc", metadata);
  std::uint64_t start_ns = std::numeric_limits<std::uint64_t>::max(), end_ns = 0;
  for (const auto& p : result.poses) {
    Header stamp;
    try {
      stamp.stamp = time_of_seconds(p.timestamp_s);
    } catch (const DataError& e) {
      throw DataError("route " + result.route + ", frame " + p.frame + ": " + e.what());
    }
    const std::uint64_t t = nanoseconds(stamp.stamp);
    start_ns = std::min(start_ns, t);
    end_ns = std::max(end_ns, t);
    add_estimate(w, {topics[0].id, topics[1].id}, p, frame, options, stamp);
    w.add_message(topics[2].id, t, t, encode(diagnostics(p, result, stamp)));
    w.add_message(topics[3].id, t, t, encode(StringMessage{p.frame}));
    if (p.truth) add_truth(w, {topics[4].id, topics[5].id}, p, frame, options, stamp);
  }
  const std::string file = dir.filename().string() + "_0.mcap";
  const std::string yaml = metadata_yaml(file, topics, w, start_ns, end_ns, metadata);
  for (const auto& t : topics) summary.messages += w.message_count(t.id);
  const std::string bytes = w.finish();

  // The folder staged beside `dir`, then put in place whole.
  const std::filesystem::path staged = core::staging_directory(dir);
  try {
    std::error_code ec;
    std::filesystem::create_directories(staged, ec);
    if (ec) throw IoError(staged.string() + ": cannot create: " + ec.message());
    core::write_file(staged / file, bytes);
    core::write_file(staged / "metadata.yaml", yaml);
    core::commit_directory(staged, dir);
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove_all(staged, ignored);
    throw;
  }
  summary.mcap = dir / file;
  return summary;
}

}  // namespace seqloc::ros
