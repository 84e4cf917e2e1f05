// The route simulator: frames lie on the cache's roads with headings along them, the odometry
// integrates to the ground truth, crops stay within the GPS error, the same seed gives the same
// files; and clean observations of a real urban region, scored by the matcher and localized,
// come back at the truth (simulator, matcher and localize agree on every convention).

#include <cmath>
#include <cstring>
#include <fstream>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/backbone_calibration.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/match_routes.hpp"
#include "seqloc/render/render.hpp"
#include "seqloc/sim/simulate.hpp"
#include "support/test_support.hpp"

namespace seqloc::sim {
namespace {

struct Simulated {
  test::ScratchDir dir;
  std::filesystem::path cache;
};

// The cache of a shared region, built once per test binary run.
const std::filesystem::path& region_cache(const std::string& name) {
  static std::map<std::string, std::filesystem::path> built;
  static test::ScratchDir dir;
  auto it = built.find(name);
  if (it == built.end()) {
    ingest::PreprocessOptions options;
    options.input = test::osm_extract(name + ".osm.pbf");
    options.output = dir / (name + ".gpkg");
    ingest::preprocess_region(options);
    it = built.emplace(name, options.output).first;
  }
  return it->second;
}

double wrap180(double d) {
  d = std::fmod(d + 180.0, 360.0);
  return (d < 0 ? d + 360.0 : d) - 180.0;
}

TEST(Simulate, FramesFollowTheRoadsAndTheOdometryIntegratesToTheTruth) {
  raster::CacheReader cache(region_cache("north-bayreuth"));
  test::ScratchDir out;
  sim::SimulateOptions options;
  options.routes = 3;
  options.frames = 40;
  options.seed = 9;
  sim::simulate_routes(cache, options, out / "routes");
  for (const auto& entry : std::filesystem::directory_iterator(out.path())) {
    EXPECT_EQ(entry.path().filename(), "routes") << "left behind: " << entry.path();
  }
  const auto roads = cache.roads();
  const auto projection = cache.metadata().projection();
  for (int r = 0; r < options.routes; ++r) {
    const io::Route route = io::read_route(out / "routes" / ("route_00" + std::to_string(r)));
    ASSERT_EQ(route.frames.size(), 40u);
    ASSERT_TRUE(route.frames[0].gps);
    double x = 0, y = 0, heading = 0;  // integrated odometry, grid frame
    for (std::size_t i = 0; i < route.frames.size(); ++i) {
      const auto& f = route.frames[i];
      ASSERT_TRUE(f.truth && f.truth->heading_deg && f.crop_grid && !f.observation.empty());
      double gamma = 0;
      const auto t = projection.forward(f.truth->where, gamma);
      const double grid_heading = *f.truth->heading_deg - gamma;
      // On a road segment, heading along it (either direction of the way).
      double best = 1e9, along = 1e9;
      for (const auto& road : roads) {
        for (std::size_t k = 1; k < road.points.size(); ++k) {
          const auto& a = road.points[k - 1];
          const auto& b = road.points[k];
          const double dx = b.x_m - a.x_m, dy = b.y_m - a.y_m, len2 = dx * dx + dy * dy;
          if (len2 == 0) continue;
          const double s = std::clamp(((t.x_m - a.x_m) * dx + (t.y_m - a.y_m) * dy) / len2, 0.0, 1.0);
          const double d = std::hypot(a.x_m + s * dx - t.x_m, a.y_m + s * dy - t.y_m);
          best = std::min(best, d);
          if (d < 0.01) {  // at a vertex, either segment may be the one driven
            const double dir = std::atan2(dx, dy) * 180 / M_PI;
            along =
                std::min({along, std::abs(wrap180(grid_heading - dir)), std::abs(wrap180(grid_heading - dir - 180))});
          }
        }
      }
      EXPECT_LT(best, 0.01) << route.name << " frame " << i;
      EXPECT_LT(along, 0.01) << route.name << " frame " << i;
      // The crop is within the GPS error of the truth.
      EXPECT_LE(std::hypot(f.crop_grid->x_m - t.x_m, f.crop_grid->y_m - t.y_m), options.gps_error_m + 0.01);
      if (i == 0) {
        x = t.x_m;
        y = t.y_m;
        heading = grid_heading;
      } else {
        const double th = heading * M_PI / 180;
        x += f.odometry.forward_m * std::sin(th) - f.odometry.left_m * std::cos(th);
        y += f.odometry.forward_m * std::cos(th) + f.odometry.left_m * std::sin(th);
        heading -= f.odometry.yaw_deg;
        const double step = std::hypot(f.odometry.forward_m, f.odometry.left_m);
        EXPECT_LE(step, options.max_spacing_m + 1e-3);
      }
      EXPECT_LT(std::hypot(x - t.x_m, y - t.y_m), 0.02) << route.name << " frame " << i;
      EXPECT_LT(std::abs(wrap180(heading - grid_heading)), 0.01) << route.name << " frame " << i;
    }
  }
}

TEST(Simulate, TheSameSeedWritesTheSameFiles) {
  raster::CacheReader cache(region_cache("monaco"));
  test::ScratchDir out;
  sim::SimulateOptions options;
  options.routes = 2;
  options.frames = 8;
  sim::simulate_routes(cache, options, out / "a");
  sim::simulate_routes(cache, options, out / "b");
  options.seed = 2;
  sim::simulate_routes(cache, options, out / "c");
  for (const char* file : {"route_001/frames.csv", "route_001/observations/000005.png", "route_000/route.json"}) {
    EXPECT_EQ(test::read_file(out / "a" / file), test::read_file(out / "b" / file)) << file;
  }
  EXPECT_NE(test::read_file(out / "a/route_001/frames.csv"), test::read_file(out / "c/route_001/frames.csv"));
}

// A ring road 300 m square with houses along it, as a synthetic map (local metres = grid metres).
osm::SyntheticMap ring_map() {
  osm::SyntheticMap map(47.5, 10.5);
  const auto a = map.node({-150, -150}), b = map.node({150, -150}), c = map.node({150, 150}), d = map.node({-150, 150});
  map.way_through({a, b, c, d, a}, {{"highway", "tertiary"}});
  for (int k = 0; k <= 6; ++k) {
    const double t = -120.0 + 40.0 * k;
    for (const auto& [x, y] : {std::pair{t, -165.0}, std::pair{165.0, t}, std::pair{t, 165.0}, std::pair{-165.0, t}}) {
      map.way({{x - 4, y - 4}, {x + 4, y - 4}, {x + 4, y + 4}, {x - 4, y + 4}}, {{"building", "house"}}, true);
    }
  }
  return map;
}

std::filesystem::path ring_cache(const osm::SyntheticMap& map, const test::ScratchDir& dir, const std::string& name) {
  map.write(dir / (name + ".osm.pbf"));
  ingest::PreprocessOptions options;
  options.input = dir / (name + ".osm.pbf");
  options.output = dir / (name + ".gpkg");
  options.bbox = osm::GeoBox{10.5 - 0.003, 47.5 - 0.002, 10.5 + 0.003, 47.5 + 0.002};
  ingest::preprocess_region(options);
  return options.output;
}

TEST(Simulate, AFrameDrawsItsOwnNoiseSoAMapEditChangesOnlyTheFramesThatSeeIt) {
  // The same seed over two maps that differ by one tree beside the first route: every frame that
  // cannot see the tree must come out byte for byte the same. With one random stream for the whole
  // run, the frame that saw the tree drew other numbers, and every later frame of every route
  // changed with it (a one-pixel fix of the rasterizer reshuffled the whole benchmark).
  test::ScratchDir dir;
  sim::SimulateOptions options;
  options.routes = 2;
  options.frames = 24;
  options.seed = 5;
  options.camera.wrong_frame = 0;  // a wrong frame may look at the tree from anywhere
  osm::SyntheticMap map = ring_map();
  raster::CacheReader plain(ring_cache(map, dir, "plain"));
  sim::simulate_routes(plain, options, dir / "a");
  const io::Route first = io::read_route(dir / "a" / "route_000");
  const auto tree_at = plain.metadata().projection().forward(first.frames[8].truth->where);
  map.node({tree_at.x_m + 3, tree_at.y_m}, {{"natural", "tree"}});
  raster::CacheReader edited(ring_cache(map, dir, "edited"));
  sim::simulate_routes(edited, options, dir / "b");

  int same = 0, differ = 0;
  for (const char* route : {"route_000", "route_001"}) {
    EXPECT_EQ(test::read_file(dir / "a" / route / "frames.csv"), test::read_file(dir / "b" / route / "frames.csv"));
    const io::Route r = io::read_route(dir / "a" / route);
    for (std::size_t i = 0; i < r.frames.size(); ++i) {
      const auto name = r.frames[i].observation.filename();
      const bool equal = test::read_file(dir / "a" / route / "observations" / name) ==
                         test::read_file(dir / "b" / route / "observations" / name);
      const auto at = plain.metadata().projection().forward(r.frames[i].truth->where);
      const double distance = std::hypot(at.x_m - tree_at.x_m - 3, at.y_m - tree_at.y_m);
      // Seen only within the camera's range, plus its pose error (1.5 m and 4 degrees of jitter).
      if (distance > options.camera.range_m * std::sqrt(2.0) + 10) {
        EXPECT_TRUE(equal) << route << " frame " << i << " is " << distance << " m from the tree";
      }
      (equal ? same : differ) += 1;
    }
  }
  EXPECT_GT(differ, 0) << "the tree must be seen by some frame, or the test shows nothing";
  EXPECT_GT(same, 30);
}

TEST(Simulate, CleanObservationsAreLocalizedAtTheTruth) {
  raster::CacheReader cache(region_cache("monaco"));
  test::ScratchDir out;
  sim::SimulateOptions options;
  options.routes = 1;
  options.frames = 12;
  options.seed = 4;
  auto& c = options.camera;
  c.class_miss = c.cell_dropout = c.spurious_blobs = c.jitter_m = c.jitter_deg = c.wrong_frame = 0;
  sim::simulate_routes(cache, options, out / "routes");
  const io::Route route = io::read_route(out / "routes/route_000");
  pipeline::LocalizeOptions lo;
  lo.filter.width = lo.filter.height = 192;
  lo.filter.threads = lo.matcher.threads = 2;
  const auto single = pipeline::localize_route(route, cache, lo, io::Mode::single);
  int within = 0;
  for (const auto& p : single.poses) {
    within += *p.position_error_m < 1.0 && *p.heading_error_deg < 3.0;
  }
  // Urban, noise-free, 15 m panorama: nearly every frame alone is exact to a cell or two.
  EXPECT_GE(within, 10) << "of 12";
  lo.keep_beliefs = true;  // what the likelihood figure draws
  const auto seqloc = pipeline::localize_route(route, cache, lo, io::Mode::seqloc);
  EXPECT_LT(*seqloc.poses.back().position_error_m, 1.0);
  EXPECT_LT(*seqloc.poses.back().heading_error_deg, 3.0);

  // The pictures of that route.
  render::RenderOptions ro;
  ro.frame = 6;
  ro.beliefs_dir = out / "run" / route.name / "seqloc";
  std::filesystem::create_directories(ro.beliefs_dir);
  io::write_route_outputs(ro.beliefs_dir, seqloc);
  const auto files =
      render::render_route(cache, route, {{"single", single.poses}, {"seqloc", seqloc.poses}}, ro, out / "figures");
  ASSERT_EQ(files.size(), 4u);  // likelihood_6, entropy_route, overview, error_over_time
  EXPECT_EQ(files[2].filename(), "overview.png");
  for (const auto& f : files) {
    const auto bytes = test::read_file(f);
    EXPECT_GT(bytes.size(), 1000u) << f;
    EXPECT_EQ(bytes.substr(1, 3), "PNG") << f;
  }
}

TEST(Match, VolumeRoutesGiveTheObservationRoutesPosesInEveryMode) {
  // The matcher's volumes written as a volume route (float16 (H, W, N) log-probabilities, crops in
  // grid metres) and localized again: the same poses, to the bit, in every mode.
  raster::CacheReader cache(region_cache("north-bayreuth"));
  test::ScratchDir out;
  sim::SimulateOptions options;
  options.routes = 1;
  options.frames = 8;
  options.seed = 12;
  sim::simulate_routes(cache, options, out / "routes");
  const io::Route observed = io::read_route(out / "routes/route_000");
  pipeline::LocalizeOptions lo;
  lo.filter.width = lo.filter.height = 128;
  lo.filter.threads = lo.matcher.threads = 2;
  write_volume_route(observed, cache, lo, out / "volumes/route_000");
  const io::Route stored = io::read_route(out / "volumes/route_000");
  ASSERT_EQ(stored.frames.size(), observed.frames.size());
  EXPECT_EQ(stored.volume_kind, filter::VolumeValues::log_prob);
  for (std::size_t i = 0; i < stored.frames.size(); ++i) {
    ASSERT_TRUE(stored.frames[i].observation.empty());
    const io::NpyVolume npy(stored.frames[i].volume);
    EXPECT_EQ(npy.type(), filter::VolumeType::float16);
    EXPECT_EQ(npy.height(), lo.matcher.size);
    EXPECT_EQ(npy.bins(), lo.matcher.headings);
    ASSERT_TRUE(stored.frames[i].truth.has_value());
    EXPECT_EQ(stored.frames[i].truth->where.lat_deg, observed.frames[i].truth->where.lat_deg);
  }
  for (const io::Mode mode : {io::Mode::single, io::Mode::offline, io::Mode::online, io::Mode::seqloc}) {
    const auto a = pipeline::localize_route(observed, cache, lo, mode);
    const auto b = pipeline::localize_route(stored, cache, lo, mode);
    ASSERT_EQ(a.poses.size(), b.poses.size());
    for (std::size_t i = 0; i < a.poses.size(); ++i) {
      EXPECT_EQ(a.poses[i].x_m, b.poses[i].x_m) << io::mode_name(mode) << " frame " << i;
      EXPECT_EQ(a.poses[i].y_m, b.poses[i].y_m) << io::mode_name(mode) << " frame " << i;
      EXPECT_EQ(a.poses[i].compass_heading_deg, b.poses[i].compass_heading_deg)
          << io::mode_name(mode) << " frame " << i;
      EXPECT_EQ(a.poses[i].volume_power, b.poses[i].volume_power) << io::mode_name(mode) << " frame " << i;
    }
  }
}

TEST(Calibrate, TheFittedTemperatureFollowsAKnownSharpeningExactly) {
  // The matcher's volumes written as a volume route, then the same route with every
  // log-probability doubled (float16 times 2 is exact): temperature 2T with the same blur and
  // floor turns the doubled volumes into the same calibrated ones, so the fit must be 2T.
  raster::CacheReader cache(region_cache("north-bayreuth"));
  test::ScratchDir out;
  sim::SimulateOptions options;
  options.routes = 1;
  options.frames = 8;
  options.seed = 14;
  sim::simulate_routes(cache, options, out / "routes");
  pipeline::LocalizeOptions lo;
  lo.filter.threads = lo.matcher.threads = 2;
  write_volume_route(io::read_route(out / "routes/route_000"), cache, lo, out / "once/route_000");
  write_volume_route(io::read_route(out / "routes/route_000"), cache, lo, out / "twice/route_000");
  const io::Route twice = io::read_route(out / "twice/route_000");
  for (const auto& f : twice.frames) {
    const io::NpyVolume npy(f.volume);
    std::vector<std::uint16_t> halves(static_cast<std::size_t>(npy.height()) * npy.width() * npy.bins());
    std::memcpy(halves.data(), npy.data(), halves.size() * sizeof(std::uint16_t));
    for (auto& h : halves) h = filter::float_to_half(2 * filter::half_to_float(h));
    const std::string bytes = io::encode_npy_float16(npy.height(), npy.width(), npy.bins(), halves.data());
    std::ofstream(f.volume, std::ios::binary) << bytes;
  }
  const auto a = fit_backbone_calibration({io::read_route(out / "once/route_000")}, cache, lo);
  const auto b = fit_backbone_calibration({io::read_route(out / "twice/route_000")}, cache, lo);
  ASSERT_EQ(a.best.frames, 8u);
  ASSERT_LT(a.best.temperature, 8.0) << "2T must be on the grid for the test to say anything";
  EXPECT_DOUBLE_EQ(b.best.temperature, 2 * a.best.temperature);
  EXPECT_EQ(b.best.calibration.blur_cells, a.best.calibration.blur_cells);
  EXPECT_EQ(b.best.calibration.floor, a.best.calibration.floor);
  EXPECT_NEAR(b.best.nll, a.best.nll, 0.02);
  EXPECT_LT(a.best.nll, a.best.uniform_nll) << "the matcher's volumes beat a uniform volume";
  EXPECT_LE(a.best.nll, a.as_given_nll) << "the volumes as given are one point of the grid";
  EXPECT_LE(b.best.nll, b.as_given_nll);

  // The file localize reads: the fit, and clear errors for what is not one.
  const auto file = out / "calibration.json";
  std::ofstream(file) << calibration_json(b);
  pipeline::LocalizeOptions applied;
  apply_calibration_file(file, applied);
  EXPECT_EQ(applied.volume_temperature, b.best.temperature);
  EXPECT_EQ(applied.volume_calibration.floor, b.best.calibration.floor);
  std::ofstream(file) << R"({"format": "seqloc-calibration", "version": 1, "temperature": -1, "blur_cells": 0,
                            "blur_bins": 0, "floor": 0})";
  EXPECT_THROW(apply_calibration_file(file, applied), DataError);
  std::ofstream(file) << R"({"format": "something else"})";
  try {
    apply_calibration_file(file, applied);
    ADD_FAILURE() << "a file of another format was read";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("calibration.json"), std::string::npos) << e.what();
  }
}

TEST(Simulate, RefusesBadOptionsAndARegionWithoutRoads) {
  sim::SimulateOptions options;
  options.frames = 1;
  EXPECT_THROW(options.validate(), UsageError);
  options = {};
  options.camera.class_miss = 1.5;
  EXPECT_THROW(options.validate(), UsageError);
  options = {};
  options.max_spacing_m = 1;
  EXPECT_THROW(options.validate(), UsageError);
}

}  // namespace
}  // namespace seqloc::sim
