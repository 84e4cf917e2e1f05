// The ROS 2 bag writer's parts against answers known without it: CDR bytes laid out by hand from
// the encoding's rules, the MCAP framing and CRCs recomputed here with zlib, and the local frame
// against analytic cases (a meridian convergence of 30 degrees, a point 1 km north on the
// ellipsoid from GeographicLib's geodesic). check_bags.py reads whole bags with others' readers.
#include <gtest/gtest.h>
#include <zlib.h>
#include <GeographicLib/Geodesic.hpp>

#include <cmath>
#include <cstring>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/ros/mcap_writer.hpp"
#include "seqloc/ros/messages.hpp"
#include "seqloc/ros/route_bag.hpp"
#include "support/test_support.hpp"

namespace seqloc::ros {
namespace {

template <class T>
T read_at(const std::string& bytes, std::size_t offset) {
  T v;
  std::memcpy(&v, bytes.data() + offset, sizeof(T));
  return v;
}

TEST(Cdr, AStringIsItsLengthWithTheNulThenItsBytesAfterTheEncapsulationHeader) {
  const std::string bytes = encode(StringMessage{"a,b"});
  EXPECT_EQ(bytes, std::string("\x00\x01\x00\x00\x04\x00\x00\x00"
                               "a,b\x00",
                               12));
}

TEST(Cdr, NavSatFixAlignsEachFieldToItsSizeAfterTheHeader) {
  NavSatFix fix;
  fix.header = {{7, 9}, "x"};
  fix.status = -1;
  fix.service = 3;
  fix.latitude = 47.5;
  fix.longitude = 11.25;
  fix.altitude = -2;
  fix.position_covariance = {1, 2, 3, 4, 5, 6, 7, 8, 9};
  fix.position_covariance_type = NavSatFix::kCovarianceKnown;
  const std::string b = encode(fix);
  // Offsets below count from after the 4-byte header: sec 0, nanosec 4, the string's length 8,
  // "x\0" 12..13, status 14, service 16 (aligned to 2), latitude 24 (aligned to 8).
  constexpr std::size_t h = 4;
  EXPECT_EQ(read_at<std::int32_t>(b, h + 0), 7);
  EXPECT_EQ(read_at<std::uint32_t>(b, h + 4), 9u);
  EXPECT_EQ(read_at<std::uint32_t>(b, h + 8), 2u);
  EXPECT_EQ(b.substr(h + 12, 2), std::string("x\0", 2));
  EXPECT_EQ(read_at<std::int8_t>(b, h + 14), -1);
  EXPECT_EQ(read_at<std::uint16_t>(b, h + 16), 3);
  EXPECT_EQ(read_at<double>(b, h + 24), 47.5);
  EXPECT_EQ(read_at<double>(b, h + 32), 11.25);
  EXPECT_EQ(read_at<double>(b, h + 40), -2);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(read_at<double>(b, h + 48 + 8 * i), i + 1);
  EXPECT_EQ(read_at<std::uint8_t>(b, h + 120), 3);
  EXPECT_EQ(b.size(), h + 121);
}

TEST(RosTime, SecondsToTimeAndBackToNanoseconds) {
  const Time t = time_of_seconds(12.345678901);
  EXPECT_EQ(t.sec, 12);
  EXPECT_EQ(t.nanosec, 345678901u);
  EXPECT_EQ(nanoseconds(t), 12'345'678'901u);
  EXPECT_THROW((void)time_of_seconds(-0.5), DataError);
  EXPECT_THROW((void)time_of_seconds(std::nan("")), DataError);
  EXPECT_THROW((void)time_of_seconds(3e9), DataError);
}

std::uint32_t zlib_crc(std::string_view s) {
  return static_cast<std::uint32_t>(crc32(0, reinterpret_cast<const Bytef*>(s.data()), static_cast<uInt>(s.size())));
}

TEST(Mcap, FramingOffsetsAndCrcsAreTheSpecs) {
  McapWriter w("ros2", "test", 64);  // small chunks: several of them
  const auto schema = w.add_schema("std_msgs/msg/String", "ros2msg", "string data\n");
  const auto channel = w.add_channel(schema, "/t", "cdr");
  for (int i = 0; i < 10; ++i) w.add_message(channel, 100 + i, 100 + i, encode(StringMessage{std::to_string(i)}));
  w.add_metadata("m", {{"k", "v"}});
  EXPECT_EQ(w.message_count(channel), 10u);
  const std::string f = w.finish();
  const std::string magic("\x89MCAP0\r\n", 8);
  ASSERT_GT(f.size(), 2 * magic.size() + 30);
  EXPECT_EQ(f.substr(0, 8), magic);
  EXPECT_EQ(f.substr(f.size() - 8), magic);
  // The footer: opcode 0x02, length 20, summary start, summary offset start, summary CRC.
  const std::size_t footer = f.size() - 8 - 29;
  EXPECT_EQ(f[footer], 0x02);
  EXPECT_EQ(read_at<std::uint64_t>(f, footer + 1), 20u);
  const auto summary = read_at<std::uint64_t>(f, footer + 9);
  const auto offsets = read_at<std::uint64_t>(f, footer + 17);
  EXPECT_EQ(read_at<std::uint32_t>(f, footer + 25),
            zlib_crc(std::string_view(f).substr(summary, footer + 25 - summary)));
  EXPECT_EQ(f[summary], 0x03);  // the summary starts with the schema
  EXPECT_EQ(f[offsets], 0x0E);  // a summary offset record
  // DataEnd just before the summary, holding the CRC of everything before it.
  const std::size_t data_end = summary - 13;
  EXPECT_EQ(f[data_end], 0x0F);
  EXPECT_EQ(read_at<std::uint32_t>(f, data_end + 9), zlib_crc(std::string_view(f).substr(0, data_end)));
  // Each summary offset record points at a group of records of its opcode.
  for (std::size_t at = offsets; at < footer; at += 9 + read_at<std::uint64_t>(f, at + 1)) {
    ASSERT_EQ(f[at], 0x0E);
    const auto op = static_cast<char>(f[at + 9]);
    EXPECT_EQ(f[read_at<std::uint64_t>(f, at + 10)], op);
  }
  EXPECT_THROW((void)w.finish(), std::logic_error);
}

io::FramePose pose_at(double lat, double lon, double gamma_deg, double compass_deg) {
  io::FramePose p;
  p.frame = "f";
  p.lat_deg = lat;
  p.lon_deg = lon;
  p.compass_heading_deg = compass_deg;
  p.grid_heading_deg = core::wrap360(compass_deg - gamma_deg);
  p.uncertainty = io::FramePose::Uncertainty{4, 0, 1, 2, 0.5, 0, false};
  return p;
}

TEST(LocalFrame, GridAxesTurnByTheConvergenceIntoTrueEastNorth) {
  // Grid north at compass 30 degrees: the grid's x axis (variance 4) points along compass 120,
  // its y axis (variance 1) along compass 30. In east-north, a unit vector at compass b is
  // (sin b, cos b); the covariance is 4 u u^T + 1 v v^T.
  const double b1 = 120 * core::kDegToRad, b2 = 30 * core::kDegToRad;
  const double ue = std::sin(b1), un = std::cos(b1), ve = std::sin(b2), vn = std::cos(b2);
  const LocalPose l = to_local_frame(pose_at(47.9, 11.2, 30, 90), {47.9, 11.2});
  EXPECT_NEAR(l.fix_covariance[0], 4 * ue * ue + ve * ve, 1e-12);
  EXPECT_NEAR(l.fix_covariance[1], 4 * ue * un + ve * vn, 1e-12);
  EXPECT_NEAR(l.fix_covariance[2], 4 * un * un + vn * vn, 1e-12);
  // At the origin the frame's axes are the true ones; a compass heading of 90 (east) is yaw 0.
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(l.frame_covariance[i], l.fix_covariance[i], 1e-12);
  EXPECT_NEAR(l.yaw_rad, 0, 1e-12);
  for (double v : l.position) EXPECT_NEAR(v, 0, 1e-9);
  EXPECT_NEAR(to_local_frame(pose_at(47.9, 11.2, 0, 0), {47.9, 11.2}).yaw_rad, core::kPi / 2, 1e-12);
}

TEST(LocalFrame, APointOneKilometreNorthLiesOnTheFramesYAxisBelowThePlane) {
  double lat = 0, lon = 0;
  GeographicLib::Geodesic::WGS84().Direct(47.9, 11.2, 0, 1000, lat, lon);
  const LocalPose l = to_local_frame(pose_at(lat, lon, 0, 0), {47.9, 11.2});
  EXPECT_NEAR(l.position[0], 0, 1e-6);
  EXPECT_NEAR(l.position[1], 1000, 1e-3);  // chord and arc differ by d^3 / (24 R^2): micrometres
  EXPECT_NEAR(l.position[2], -1000.0 * 1000.0 / (2 * 6.37e6), 2e-3);  // the plane rises d^2 / 2R above the ellipsoid
  // North at that point is north in the frame too (same meridian).
  EXPECT_NEAR(l.yaw_rad, core::kPi / 2, 1e-9);
}

TEST(RouteBag, RefusesPosesWithoutUncertaintyAndBadOptions) {
  test::ScratchDir dir;
  io::RouteResult r;
  r.route = "r";
  r.mode = io::Mode::single;
  r.poses = {pose_at(47.9, 11.2, 0, 0)};
  r.poses[0].uncertainty.reset();
  EXPECT_THROW((void)write_route_bag(dir / "bag", r), UsageError);
  EXPECT_FALSE(std::filesystem::exists(dir / "bag"));
  r.poses = {pose_at(47.9, 11.2, 0, 0)};
  r.poses[0].timestamp_s = -1;
  EXPECT_THROW((void)write_route_bag(dir / "bag", r), DataError);
  EXPECT_FALSE(std::filesystem::exists(dir / "bag"));
  BagOptions o;
  o.origin_deg = std::array<double, 2>{91, 0};
  EXPECT_THROW(o.validate(), UsageError);
  o.origin_deg.reset();
  o.frame_id.clear();
  EXPECT_THROW(o.validate(), UsageError);
}

TEST(RouteBag, WritesTheFolderRosbag2Opens) {
  test::ScratchDir dir;
  io::RouteResult r;
  r.route = "r";
  r.poses = {pose_at(47.9, 11.2, 0.1, 10), pose_at(47.9001, 11.2, 0.1, 10)};
  r.poses[1].timestamp_s = 0.5;
  const BagSummary s = write_route_bag(dir / "bag", r);
  EXPECT_EQ(s.mcap, dir / "bag" / "bag_0.mcap");
  EXPECT_TRUE(std::filesystem::is_regular_file(s.mcap));
  EXPECT_EQ(s.messages, 8u);  // pose, fix, diagnostics, frame name per frame; no ground truth
  EXPECT_EQ(s.origin_deg, (std::array<double, 2>{47.9, 11.2}));  // no truth: the first pose
  const std::string yaml = test::read_file(dir / "bag" / "metadata.yaml");
  EXPECT_NE(yaml.find("message_count: 8\n"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("duration:\n    nanoseconds: 500000000\n"), std::string::npos) << yaml;
  EXPECT_EQ(yaml.find("/seqloc/truth"), std::string::npos) << yaml;
}

}  // namespace
}  // namespace seqloc::ros
