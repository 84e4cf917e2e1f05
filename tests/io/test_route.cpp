// Route directories: a valid route reads back field by field; every malformed route.json or
// frames.csv row is one error naming the file and line.

#include <fstream>

#include <gtest/gtest.h>

#include "seqloc/io/route.hpp"
#include "support/test_support.hpp"

namespace seqloc::io {
namespace {

const char* kJson =
    R"({"format": "seqloc-route", "version": 1, "name": "valley", "volume_kind": "log_prob", "cell_m": 0.5})";
const char* kHeader =
    "frame,timestamp,volume,crop_lat,crop_lon,odo_forward_m,odo_left_m,odo_yaw_deg,gps_lat,gps_lon,"
    "gps_sigma_m,gt_lat,gt_lon,gt_heading_deg";

struct RouteDir {
  test::ScratchDir dir;
  RouteDir(const std::string& json, const std::string& csv) {
    std::ofstream(dir / "route.json") << json;
    std::ofstream(dir / "frames.csv") << csv;
    for (const char* v : {"v0.npy", "v1.npy", "v2.npy", "a,b.npy"}) std::ofstream(dir / v) << "x";
  }
};

std::string rows(std::initializer_list<const char*> lines) {
  std::string s = std::string(kHeader) + "\n";
  for (const char* l : lines) s += std::string(l) + "\n";
  return s;
}

TEST(Route, ReadsAValidRoute) {
  RouteDir r(kJson, "\xEF\xBB\xBF" + rows({"0,10.0,v0.npy,47.95,11.25,0,0,0,47.9501,11.2502,32,47.95,11.25,90",
                                           "1,10.5,v1.npy,47.9501,11.25,5.0,0.1,-2.5,,,,47.9501,11.25,88\r", "",
                                           "2,11.0,\"a,b.npy\",47.9502,11.25,5.0,0.0,0.0,,,,47.9502,11.25,"}));
  const io::Route route = io::read_route(r.dir.path());
  EXPECT_EQ(route.name, "valley");
  EXPECT_EQ(route.volume_kind, core::VolumeValues::log_prob);
  ASSERT_EQ(route.frames.size(), 3u);
  const auto& f0 = route.frames[0];
  EXPECT_EQ(f0.line, 2);
  EXPECT_EQ(f0.frame, "0");
  EXPECT_EQ(f0.volume, r.dir / "v0.npy");
  ASSERT_TRUE(f0.crop_geo.has_value());
  EXPECT_DOUBLE_EQ(f0.crop_geo->lat_deg, 47.95);
  ASSERT_TRUE(f0.gps.has_value());
  EXPECT_DOUBLE_EQ(f0.gps->sigma_m, 32);
  ASSERT_TRUE(f0.truth && f0.truth->heading_deg);
  EXPECT_DOUBLE_EQ(*f0.truth->heading_deg, 90);
  const auto& f1 = route.frames[1];
  EXPECT_FALSE(f1.gps.has_value());
  EXPECT_DOUBLE_EQ(f1.odometry.forward_m, 5.0);
  EXPECT_DOUBLE_EQ(f1.odometry.left_m, 0.1);
  EXPECT_DOUBLE_EQ(f1.odometry.yaw_deg, -2.5);
  EXPECT_EQ(route.frames[2].line, 5) << "the blank line counts";
  EXPECT_EQ(route.frames[2].volume, r.dir / "a,b.npy");
  EXPECT_FALSE(route.frames[2].truth->heading_deg.has_value());
}

TEST(Route, GapsInTimestampsAreAllowedAndJudgedOverTheRealInterval) {
  // An hour without frames, then 150 m of odometry: 0.04 m/s, plausible. The same step one
  // second after the previous frame would be 150 m/s, beyond the limit.
  RouteDir gap(kJson, rows({"0,0,v0.npy,47.95,11.25,0,0,0,,,,,,", "1,3600,v1.npy,47.95,11.25,150,0,0,,,,,,"}));
  const io::Route route = io::read_route(gap.dir.path());
  ASSERT_EQ(route.frames.size(), 2u);
  EXPECT_DOUBLE_EQ(route.frames[1].timestamp_s, 3600);
  RouteDir fast(kJson, rows({"0,0,v0.npy,47.95,11.25,0,0,0,,,,,,", "1,1,v1.npy,47.95,11.25,150,0,0,,,,,,"}));
  EXPECT_THROW((void)io::read_route(fast.dir.path()), DataError);
}

TEST(Route, GridCropsAndProbVolumes) {
  RouteDir r(R"({"format": "seqloc-route", "version": 1, "volume_kind": "prob"})",
             "frame,timestamp,volume,crop_x,crop_y,odo_forward_m,odo_left_m,odo_yaw_deg\n"
             "a,0,v0.npy,-120.5,33.25,0,0,0\nb,1,v1.npy,-115.5,33.25,5,0,0\n");
  const io::Route route = io::read_route(r.dir.path());
  EXPECT_EQ(route.volume_kind, core::VolumeValues::prob);
  EXPECT_EQ(route.name, r.dir.path().filename().string());
  ASSERT_TRUE(route.frames[1].crop_grid.has_value());
  EXPECT_DOUBLE_EQ(route.frames[1].crop_grid->x_m, -115.5);
}

void expect_error(const std::string& json, const std::string& csv, const std::string& fragment,
                  const io::RouteLimits& limits = {}) {
  RouteDir r(json, csv);
  try {
    (void)io::read_route(r.dir.path(), limits);
    FAIL() << "no error, expected '" << fragment << "'";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(r.dir.path().string()), std::string::npos) << e.what();
  }
}

TEST(Route, BadRouteJson) {
  const std::string csv = rows({"0,0,v0.npy,47.95,11.25,0,0,0,,,,,,"});
  expect_error("{not json", csv, "route.json: not valid JSON");
  expect_error(R"({"format": "other", "version": 1})", csv, R"("format" must be "seqloc-route")");
  expect_error(R"({"format": "seqloc-route", "version": 2})", csv, "\"version\" must be 1");
  expect_error(R"({"format": "seqloc-route", "version": 1, "volume_kind": "logits"})", csv,
               R"("volume_kind" must be "log_prob" or "prob")");
  expect_error(R"({"format": "seqloc-route", "version": 1, "cell_m": 0})", csv, "\"cell_m\" must be > 0");
  // Members of the wrong JSON type (found by fuzz/route.cpp: json::value threw a type_error that
  // escaped as an unexplained exception).
  expect_error(R"({"format": 0.5, "version": 1})", csv, "route.json: \"format\" must be a string");
  expect_error(R"({"format": "seqloc-route", "version": 1, "volume_kind": 3})", csv,
               "\"volume_kind\" must be a string");
  expect_error(R"({"format": "seqloc-route", "version": 1, "name": []})", csv, "\"name\" must be a string");
  expect_error(R"([1, 2])", csv, "route.json: not a JSON object");
  expect_error(R"({"format": "seqloc-route", "version": 4294967297})", csv, "\"version\" must be 1");
  // Unknown keys: a misspelt key would otherwise be a silent default.
  expect_error(R"({"format": "seqloc-route", "version": 1, "volume_knd": "prob"})", csv,
               "route.json: unknown key \"volume_knd\" (known: format, version, name, volume_kind, cell_m, layout, "
               "simulated)");
  expect_error(R"({"format": "seqloc-route", "version": 1, "layout": "WHN"})", csv,
               R"(route.json: "layout" must be "HWN" or "NHW", not "WHN")");
  expect_error(R"({"format": "seqloc-route", "version": 1, "layout": 3})", csv, "\"layout\" must be a string");
}

TEST(Route, BadFramesCsvRowsNameTheLine) {
  const char* ok0 = "0,0,v0.npy,47.95,11.25,0,0,0,,,,,,";
  expect_error(kJson, "frame,timestamp,volume,crop_lat,crop_lon,odo_forwrd_m,odo_left_m,odo_yaw_deg\n",
               "frames.csv:1: unknown column 'odo_forwrd_m'");
  expect_error(kJson, "frame,timestamp,volume,crop_lat,crop_lon,odo_left_m,odo_yaw_deg\n",
               "frames.csv:1: missing column 'odo_forward_m'");
  expect_error(kJson, "frame,timestamp,volume,observation,crop_x,crop_y,odo_forward_m,odo_left_m,odo_yaw_deg\n",
               "exactly one of the columns 'volume' and 'observation'");
  expect_error(kJson, "frame,timestamp,volume,crop_lat,crop_x,odo_forward_m,odo_left_m,odo_yaw_deg\n",
               "either 'crop_lat, crop_lon' or 'crop_x, crop_y'");
  expect_error(kJson, rows({ok0, "1,1,v1.npy,47.95,11.25,5,0,0,,,"}), "frames.csv:3: 11 fields, but the header has 14");
  expect_error(kJson, rows({"0,abc,v0.npy,47.95,11.25,0,0,0,,,,,,"}), "frames.csv:2: timestamp 'abc' is not a finite");
  expect_error(kJson, rows({ok0, "1,1,v1.npy,nan,11.25,5,0,0,,,,,,"}), "frames.csv:3: crop_lat 'nan'");
  expect_error(kJson, rows({ok0, "1,1,v1.npy,47.95,11.25,5,0,0,,,,,,", "2,0.5,v2.npy,47.95,11.25,5,0,0,,,,,,"}),
               "frames.csv:4: timestamp 0.5 does not come after the previous frame's (line 3)");
  expect_error(kJson, rows({ok0, "1,1,v1.npy,47.95,11.25,250,0,0,,,,,,"}), "frames.csv:3: odometry step of 250 m");
  expect_error(kJson, rows({ok0, "1,0.1,v1.npy,47.95,11.25,20,0,0,,,,,,"}), "200 m/s, above the limit of 70 m/s");
  expect_error(kJson, rows({ok0, "1,1,v1.npy,47.95,11.25,5,0,170,,,,,,"}), "odometry yaw of 170 degrees");
  io::RouteLimits strict;
  strict.max_step_m = 3;
  expect_error(kJson, rows({ok0, "1,1,v1.npy,47.95,11.25,5,0,0,,,,,,"}), "limit of 3 m", strict);
  expect_error(kJson, rows({ok0, "1,1,v9.npy,47.95,11.25,5,0,0,,,,,,"}),
               "frames.csv:3: volume 'v9.npy' does not exist");
  expect_error(kJson, rows({"0,0,v0.npy,47.95,11.25,1,0,0,,,,,,"}),
               "frames.csv:2: the first frame's odometry must be 0");
  expect_error(kJson, rows({"0,0,v0.npy,47.95,11.25,0,0,0,47.95,11.25,0,,,"}), "gps_sigma_m must be > 0");
  expect_error(kJson, rows({"0,0,v0.npy,95,11.25,0,0,0,,,,,,"}), "outside [-90, 90]");
  expect_error(kJson, rows({"0,0,\"v0.npy,47.95,11.25,0,0,0,,,,,,"}), "frames.csv:2: unterminated quoted field");
  expect_error(kJson, std::string(kHeader) + "\n", "frames.csv: no frames after the header");
  expect_error(kJson, "", "frames.csv: empty");
}

// write_route then read_route gives back every field exactly: numbers that need all 17 digits,
// frame ids that need quoting, GPS on the first frame only, truth with and without heading,
// lat/lon crops, and route.json's members including the simulator's provenance.
TEST(Route, WriteRouteReadsBackExactly) {
  test::ScratchDir dir;
  std::filesystem::create_directories(dir / "out");
  std::ofstream(dir / "a.npy") << "x";
  std::ofstream(dir / "out/b c.npy") << "x";
  io::Route route;
  route.name = "round, trip";
  route.volume_kind = core::VolumeValues::prob;
  route.cell_m = 0.25;
  route.layout = io::VolumeLayout::nhw;
  route.layout_declared = true;
  route.simulated_json = R"({"seed":7,"cache":"x.gpkg"})";
  for (int t = 0; t < 3; ++t) {
    io::RouteFrame f;
    f.frame = t == 1 ? "frame \"1\", quoted" : "f" + std::to_string(t);
    f.timestamp_s = t / 3.0;
    f.volume = t == 2 ? dir / "out/b c.npy" : dir / "a.npy";
    f.crop_geo = osm::GeoPoint{47.1 + t * 1e-7 / 3, -10.5 - t / 7.0};
    f.odometry = t == 0 ? core::Odometry{} : core::Odometry{5.0 / 3, -1e-9, 0.1 + 0.2};
    if (t == 0) f.gps = io::GpsPrior{{47.1, -10.5}, 32.5};
    if (t != 1)
      f.truth =
          io::GroundTruth{{47.1 + 1e-12, -10.5}, t == 0 ? std::optional<double>(359.99999999999994) : std::nullopt};
    route.frames.push_back(f);
  }
  io::write_route(route, dir / "out");
  const io::Route back = io::read_route(dir / "out");
  EXPECT_EQ(back.name, route.name);
  EXPECT_EQ(back.volume_kind, route.volume_kind);
  EXPECT_EQ(back.cell_m, route.cell_m);
  EXPECT_EQ(back.layout, route.layout);
  EXPECT_TRUE(back.layout_declared);
  EXPECT_EQ(back.simulated_json, R"({"cache":"x.gpkg","seed":7})");
  ASSERT_EQ(back.frames.size(), route.frames.size());
  for (std::size_t i = 0; i < route.frames.size(); ++i) {
    const io::RouteFrame &a = route.frames[i], &b = back.frames[i];
    EXPECT_EQ(b.frame, a.frame);
    EXPECT_EQ(b.timestamp_s, a.timestamp_s);
    EXPECT_EQ(std::filesystem::weakly_canonical(b.volume), std::filesystem::weakly_canonical(a.volume));
    ASSERT_TRUE(b.crop_geo && !b.crop_grid);
    EXPECT_EQ(b.crop_geo->lat_deg, a.crop_geo->lat_deg);
    EXPECT_EQ(b.crop_geo->lon_deg, a.crop_geo->lon_deg);
    EXPECT_EQ(b.odometry.forward_m, a.odometry.forward_m);
    EXPECT_EQ(b.odometry.left_m, a.odometry.left_m);
    EXPECT_EQ(b.odometry.yaw_deg, a.odometry.yaw_deg);
    ASSERT_EQ(b.gps.has_value(), a.gps.has_value()) << i;
    if (a.gps) {
      EXPECT_EQ(b.gps->where.lat_deg, a.gps->where.lat_deg);
      EXPECT_EQ(b.gps->sigma_m, a.gps->sigma_m);
    }
    ASSERT_EQ(b.truth.has_value(), a.truth.has_value()) << i;
    if (a.truth) {
      EXPECT_EQ(b.truth->where.lat_deg, a.truth->where.lat_deg);
      EXPECT_EQ(b.truth->where.lon_deg, a.truth->where.lon_deg);
      EXPECT_EQ(b.truth->heading_deg, a.truth->heading_deg);
    }
  }
  // Paths under the route directory are written relative to it, others as given.
  const std::string csv = test::read_file(dir / "out/frames.csv");
  EXPECT_NE(csv.find(",b c.npy,"), std::string::npos) << csv;
  EXPECT_NE(csv.find("," + (dir / "a.npy").string() + ","), std::string::npos) << csv;
  // A frame of another kind than the first cannot be written faithfully: refused, nothing written.
  route.frames[1].crop_geo.reset();
  route.frames[1].crop_grid = osm::GridPoint{1, 2};
  EXPECT_THROW(io::write_route(route, dir / "mixed"), DataError);
  EXPECT_FALSE(std::filesystem::exists(dir / "mixed"));
}

}  // namespace
}  // namespace seqloc::io
