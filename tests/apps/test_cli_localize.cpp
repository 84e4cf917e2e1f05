// seqloc localize and seqloc evaluate from the command line: the files, the table, exit codes,
// and nothing written when an input is bad.

#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "seqloc/io/run_folder.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc {
namespace {

using test::run_seqloc;

// A cache of an east-west track, and a route driving it with delta volumes at the truth.
struct Fixture {
  test::ScratchDir dir;
  std::filesystem::path cache, route;

  explicit Fixture(bool with_nan = false, const std::string& id_prefix = "") {
    osm::SyntheticMap map(47.5, 10.5);
    map.way({{-200, 0.25}, {200, 0.25}}, {{"highway", "track"}});
    map.write(dir / "map.osm.pbf", 60);
    cache = dir / "region.gpkg";
    const auto r = run_seqloc({"preprocess", (dir / "map.osm.pbf").string(), "-o", cache.string()});
    if (r.exit_code != 0) throw std::runtime_error(r.err);
    const auto projection = raster::CacheReader(cache).metadata().projection();
    route = dir / "route";
    std::filesystem::create_directories(route);
    std::ofstream(route / "route.json") << R"({"format": "seqloc-route", "version": 1, "name": "east"})";
    std::ofstream csv(route / "frames.csv");
    csv.precision(17);
    csv << "frame,timestamp,volume,crop_x,crop_y,odo_forward_m,odo_left_m,odo_yaw_deg,gt_lat,gt_lon,gt_heading_deg\n";
    for (int t = 0; t < 8; ++t) {
      const double x = -20.25 + 5.0 * t, y = 0.25;
      std::vector<float> v(15 * 15 * 64, -std::numeric_limits<float>::infinity());
      v[(7 * 15 + 7) * 64 + 16] = 0;  // the truth: the centre cell, heading 90
      if (with_nan && t == 5) v[100] = std::nanf("");
      test::write_npy_float32(route / ("v" + std::to_string(t) + ".npy"), 15, 15, 64, v);
      double gamma = 0;
      const auto gt = projection.reverse({x, y}, gamma);
      // An id with a comma is quoted, as RFC 4180 has it ("" for a quote inside).
      if (id_prefix.empty()) {
        csv << t;
      } else {
        csv << '"' << id_prefix << t << '"';
      }
      csv << "," << t << ",v" << t << ".npy," << x << "," << y << "," << (t ? 5 : 0) << ",0,0," << gt.lat_deg << ","
          << gt.lon_deg << "," << 90 + gamma << "\n";
    }
  }
};

// A TUM trajectory file by the rules evo documents: a line per pose, "timestamp tx ty tz qx qy qz
// qw" separated by spaces, lines starting with '#' are comments.
std::vector<std::array<double, 8>> read_tum(const std::filesystem::path& path) {
  std::vector<std::array<double, 8>> poses;
  std::ifstream in(path);
  EXPECT_TRUE(in) << path;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::array<double, 8> pose{};
    for (double& value : pose) EXPECT_TRUE(fields >> value) << path << ": " << line;
    std::string extra;
    EXPECT_FALSE(fields >> extra) << path << ": more than 8 fields: " << line;
    poses.push_back(pose);
  }
  return poses;
}

std::vector<std::string> args(const Fixture& f, const std::filesystem::path& out, std::vector<std::string> extra) {
  std::vector<std::string> a{"localize", f.cache.string(), f.route.string(), "-o", out.string(), "--window", "64",
                             "--headings", "64"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

TEST(CliLocalize, WritesEveryFileAndTheTable) {
  Fixture f;
  const auto out = f.dir / "out";
  const auto r = run_seqloc(args(f, out, {"--mode", "all"}));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  for (const char* mode : {"seqloc", "online", "single", "offline"}) {
    const auto dir = out / "east" / mode;
    ASSERT_TRUE(std::filesystem::exists(dir / "poses.csv")) << mode;
    const std::string poses = test::read_file(dir / "poses.csv");
    EXPECT_EQ(std::count(poses.begin(), poses.end(), '\n'), 9) << "header + 8 frames";
    const auto track = nlohmann::json::parse(test::read_file(dir / "track.geojson"));
    EXPECT_EQ(track["type"], "FeatureCollection");
    EXPECT_EQ(track["features"][0]["geometry"]["type"], "LineString");
    EXPECT_EQ(track["features"][0]["geometry"]["coordinates"].size(), 8u);
    const double lon = track["features"][2]["geometry"]["coordinates"][0];
    EXPECT_NEAR(lon, 10.5, 0.01) << "RFC 7946 order: [lon, lat]";
    const std::string tum = test::read_file(dir / "trajectory.tum");
    EXPECT_EQ(std::count(tum.begin(), tum.end(), '\n'), 8);
    // Heading east: yaw 0 from the x axis, so qz = 0 and qw = 1.
    EXPECT_NE(tum.find(" 0 0 0 0.000000000 1.000000000"), std::string::npos) << tum.substr(0, 200);
    // groundtruth.tum, read by the TUM rules evo documents, holds the fixture's truth at the
    // estimate's timestamps: x = -20.25 + 5 t, y = 0.25, heading east.
    const auto truth = read_tum(dir / "groundtruth.tum");
    const auto estimate = read_tum(dir / "trajectory.tum");
    ASSERT_EQ(truth.size(), 8u) << mode;
    ASSERT_EQ(estimate.size(), 8u) << mode;
    for (std::size_t t = 0; t < truth.size(); ++t) {
      EXPECT_EQ(truth[t][0], estimate[t][0]) << "the same timestamps";
      EXPECT_NEAR(truth[t][0], static_cast<double>(t), 1e-9);
      EXPECT_NEAR(truth[t][1], -20.25 + 5.0 * static_cast<double>(t), 1e-3) << mode << " frame " << t;
      EXPECT_NEAR(truth[t][2], 0.25, 1e-3) << mode << " frame " << t;
      EXPECT_NEAR(std::hypot(truth[t][6], truth[t][7]), 1.0, 1e-6) << "a unit quaternion";
      EXPECT_NEAR(truth[t][6], 0.0, 1e-6) << "yaw 0: heading east";
    }
    // track.geojson: the ground-truth line next to the estimate's, and each frame's truth.
    ASSERT_GE(track["features"].size(), 2u + 8u);
    EXPECT_EQ(track["features"][0]["properties"]["track"], "estimate");
    const auto& truth_line = track["features"][1];
    EXPECT_EQ(truth_line["properties"]["track"], "ground_truth");
    ASSERT_EQ(truth_line["geometry"]["coordinates"].size(), 8u);
    const auto& frame3 = track["features"][2 + 3];
    EXPECT_EQ(frame3["properties"]["truth"], truth_line["geometry"]["coordinates"][3]);
    EXPECT_TRUE(frame3["properties"].contains("position_error_m"));
    EXPECT_TRUE(frame3["properties"].contains("lateral_error_m"));
    const auto metrics = nlohmann::json::parse(test::read_file(dir / "metrics.json"));
    EXPECT_EQ(metrics["position_recall_pct"]["1m"], 100.0) << mode;
    EXPECT_EQ(metrics["heading_recall_pct"]["1deg"], 100.0) << mode;
  }
  EXPECT_TRUE(std::filesystem::exists(out / "summary.json"));
  EXPECT_NE(r.out.find("R@1m"), std::string::npos) << r.out;
  for (const char* mode : {"seqloc ", "online ", "single ", "offline "}) {
    const auto row = r.out.find(mode);
    ASSERT_NE(row, std::string::npos) << r.out;
    EXPECT_NE(r.out.substr(row, 60).find("100.0"), std::string::npos) << r.out;
  }
  // evaluate recomputes the same table from the files; from the route's folder too, and from
  // mode folders (one row each), and a file named twice counts once.
  const auto e = run_seqloc({"evaluate", out.string()});
  ASSERT_EQ(e.exit_code, 0) << e.err;
  EXPECT_EQ(e.out, r.out.substr(0, r.out.find("wrote ")));
  const auto by_route = run_seqloc({"evaluate", (out / "east").string(), out.string()});
  ASSERT_EQ(by_route.exit_code, 0) << by_route.err;
  EXPECT_EQ(by_route.out, e.out);
  const auto two_modes = run_seqloc({"evaluate", (out / "east/seqloc").string(), (out / "east/single").string()});
  ASSERT_EQ(two_modes.exit_code, 0) << two_modes.err;
  EXPECT_NE(two_modes.out.find("seqloc "), std::string::npos) << two_modes.out;
  EXPECT_NE(two_modes.out.find("single "), std::string::npos) << two_modes.out;
  EXPECT_EQ(two_modes.out.find("online "), std::string::npos) << two_modes.out;
  const auto nothing = run_seqloc({"evaluate", (f.dir / "route").string()});
  EXPECT_EQ(nothing.exit_code, 1);
  EXPECT_NE(nothing.err.find("no poses.csv"), std::string::npos) << nothing.err;
}

TEST(CliLocalize, RoutesSideBySideGiveTheSameFiles) {
  Fixture f;
  const auto parallel = f.dir / "parallel", serial = f.dir / "serial";
  std::vector<std::string> two{"localize", f.cache.string(), f.route.string(), f.route.string(), "--window", "64",
                               "--headings", "64", "--mode", "all"};
  auto p = two, s = two;
  p.insert(p.end(), {"-o", parallel.string(), "--threads", "2"});
  s.insert(s.end(), {"-o", serial.string(), "--threads", "1"});
  ASSERT_EQ(run_seqloc(p).exit_code, 0);
  ASSERT_EQ(run_seqloc(s).exit_code, 0);
  for (const char* route : {"east", "east-2"}) {
    for (const char* mode : {"seqloc", "online", "single", "offline"}) {
      EXPECT_EQ(test::read_file(parallel / route / mode / "poses.csv"), test::read_file(serial / route / mode / "poses.csv"))
          << route << "/" << mode;
    }
  }
  EXPECT_EQ(test::read_file(parallel / "summary.json"), test::read_file(serial / "summary.json"));
}

// --shard I/N takes every N-th route (in sorted order) from the I-th; the shards' folders are the
// one run's, file for file, and `evaluate` over the shards prints the one run's table.
TEST(CliLocalize, ShardsMergedEqualOneRun) {
  Fixture f;
  const std::vector<std::string> three{"localize", f.cache.string(), f.route.string(), f.route.string(),
                                       f.route.string(), "--window", "64", "--headings", "64", "--mode", "all"};
  auto run = [&](const std::filesystem::path& out, std::vector<std::string> extra) {
    auto a = three;
    a.insert(a.end(), {"-o", out.string()});
    a.insert(a.end(), extra.begin(), extra.end());
    return run_seqloc(a);
  };
  const auto whole = f.dir / "whole", s0 = f.dir / "s0", s1 = f.dir / "s1";
  const auto w = run(whole, {});
  ASSERT_EQ(w.exit_code, 0) << w.err;
  ASSERT_EQ(run(s0, {"--shard", "0/2"}).exit_code, 0);
  ASSERT_EQ(run(s1, {"--shard", "1/2"}).exit_code, 0);
  const std::map<std::string, std::filesystem::path> owner{{"east", s0}, {"east-2", s1}, {"east-3", s0}};
  for (const auto& [route, shard] : owner) {
    const auto other = shard == s0 ? s1 : s0;
    EXPECT_FALSE(std::filesystem::exists(other / route)) << route;
    for (const char* mode : {"seqloc", "online", "single", "offline"}) {
      EXPECT_EQ(test::read_file(shard / route / mode / "poses.csv"), test::read_file(whole / route / mode / "poses.csv"))
          << route << "/" << mode;
    }
  }
  const auto merged = run_seqloc({"evaluate", s0.string(), s1.string()});
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  EXPECT_EQ(merged.out, w.out.substr(0, w.out.find("wrote ")));
  for (const char* bad : {"2/2", "1", "-1/2", "0/0", "a/b"}) {
    const auto r = run(f.dir / "bad", {"--shard", bad});
    EXPECT_EQ(r.exit_code, 2) << bad;
    EXPECT_NE(r.err.find("--shard"), std::string::npos) << r.err;
  }
}

TEST(CliLocalize, BadVolumeStopsTheRunWithNothingWritten) {
  Fixture f(/*with_nan=*/true);
  const auto out = f.dir / "out";
  const auto r = run_seqloc(args(f, out, {}));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("NaN at cell 100"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
  for (const auto& entry : std::filesystem::directory_iterator(f.dir.path())) {
    EXPECT_EQ(entry.path().filename().string().find("out.partial"), std::string::npos) << "temporary folder left";
  }
}

TEST(CliLocalize, UsageErrorsAndOverwrite) {
  Fixture f;
  const auto out = f.dir / "out";
  ASSERT_EQ(run_seqloc(args(f, out, {"--mode", "single"})).exit_code, 0);
  const auto again = run_seqloc(args(f, out, {}));
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_NE(again.err.find("already exists; pass --overwrite"), std::string::npos) << again.err;
  const auto replaced = run_seqloc(args(f, out, {"--overwrite"}));
  EXPECT_EQ(replaced.exit_code, 0) << replaced.err;
  EXPECT_TRUE(std::filesystem::exists(out / "east" / "seqloc" / "poses.csv"));
  EXPECT_FALSE(std::filesystem::exists(out / "east" / "single")) << "the old folder was replaced whole";
  EXPECT_EQ(run_seqloc(args(f, f.dir / "x", {"--mode", "offline-ish"})).exit_code, 2);
  EXPECT_EQ(run_seqloc(args(f, f.dir / "x", {"--odometry-noise", "2"})).exit_code, 2);
  const auto bad_lag = run_seqloc(args(f, f.dir / "x", {"--lag", "-2"}));
  EXPECT_EQ(bad_lag.exit_code, 2);
  EXPECT_NE(bad_lag.err.find("--lag"), std::string::npos) << bad_lag.err;
  // A lag is reported with the poses it gave.
  const auto lagged = run_seqloc(args(f, f.dir / "lagged", {"--lag", "2"}));
  ASSERT_EQ(lagged.exit_code, 0) << lagged.err;
  EXPECT_NE(test::read_file(f.dir / "lagged" / "east" / "seqloc" / "metrics.json").find("\"lag\": 2"), std::string::npos);
  const auto bad_epsilon = run_seqloc(args(f, f.dir / "x", {"--epsilon", "2"}));
  EXPECT_EQ(bad_epsilon.exit_code, 2);
  EXPECT_NE(bad_epsilon.err.find("mgr_epsilon = 2"), std::string::npos) << bad_epsilon.err;
  EXPECT_EQ(run_seqloc({"localize", "--help"}).exit_code, 0);
  EXPECT_EQ(run_seqloc({"evaluate", "--help"}).exit_code, 0);
}

// Frame ids with commas (frames.csv quotes them) come back whole in poses.csv, in evaluate's
// table and in render's pictures; and render draws the overview of an output that holds smooth's
// poses alone.
TEST(CliLocalize, QuotedIdsWithCommasAndASmoothOnlyOutputGoThroughEvaluateAndRender) {
  Fixture f(/*with_nan=*/false, "cam,");
  const auto out = f.dir / "out";
  const auto r = run_seqloc(args(f, out, {"--mode", "smooth"}));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto poses = io::read_poses_csv(out / "east" / "smooth" / "poses.csv");
  ASSERT_EQ(poses.size(), 8u);
  for (std::size_t t = 0; t < poses.size(); ++t) EXPECT_EQ(poses[t].frame, "cam," + std::to_string(t));
  EXPECT_NE(test::read_file(out / "east" / "smooth" / "poses.csv").find("\"cam,3\","), std::string::npos)
      << "written quoted";

  const auto evaluated = run_seqloc({"evaluate", out.string()});
  ASSERT_EQ(evaluated.exit_code, 0) << evaluated.err;
  EXPECT_NE(evaluated.out.find("smooth"), std::string::npos) << evaluated.out;

  const auto figures = f.dir / "figures";
  const auto rendered = run_seqloc({"render", f.cache.string(), f.route.string(), "-o", figures.string(), "--localized",
                                    out.string(), "--window", "64", "--threads", "1"});
  ASSERT_EQ(rendered.exit_code, 0) << rendered.err;
  EXPECT_TRUE(std::filesystem::exists(figures / "overview.png")) << "smooth's overview: " << rendered.out;
  EXPECT_TRUE(std::filesystem::exists(figures / "error_over_time.png")) << rendered.out;
}

TEST(OdometryNoise, DeterministicZeroMeanAndScaledWithTheStep) {
  io::Route route;
  route.frames.resize(20001);
  for (std::size_t i = 1; i < route.frames.size(); ++i) route.frames[i].odometry = {10.0, 0.0, 0.0};
  io::Route a = route, b = route;
  pipeline::perturb_odometry(a, 2.0, 0.01, 7);
  pipeline::perturb_odometry(b, 2.0, 0.01, 7);
  double sum_f = 0, sum_f2 = 0, sum_y2 = 0;
  for (std::size_t i = 1; i < a.frames.size(); ++i) {
    EXPECT_EQ(a.frames[i].odometry.forward_m, b.frames[i].odometry.forward_m);
    const double df = a.frames[i].odometry.forward_m - 10.0;
    sum_f += df;
    sum_f2 += df * df;
    sum_y2 += a.frames[i].odometry.yaw_deg * a.frames[i].odometry.yaw_deg;
  }
  const double n = 20000;
  // sigma_t = 2 % of 10 m = 0.2 m; sigma_r = 0.01 deg/m * 10 m = 0.1 deg. 20,000 samples: the
  // sample mean is within 4 standard errors (0.2 / sqrt(n) * 4 = 0.0057 m), the sd within 3 %.
  EXPECT_NEAR(sum_f / n, 0.0, 0.0057);
  EXPECT_NEAR(std::sqrt(sum_f2 / n), 0.2, 0.006);
  EXPECT_NEAR(std::sqrt(sum_y2 / n), 0.1, 0.003);
  EXPECT_EQ(a.frames[0].odometry.forward_m, 0.0) << "the first frame has no motion";
}

}  // namespace
}  // namespace seqloc
