// Localizing routes end to end against caches built from synthetic maps, with volumes whose
// answer is known: a delta at the true pose must give zero error in every mode.

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <random>
#include <set>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/region_window.hpp"
#include "support/test_support.hpp"

namespace seqloc::pipeline::localize_tests {
namespace {

constexpr int kSide = 15, kBins = 64;  // volumes: odd side, so the centre cell is the crop centre

// A float32 .npy volume with all its mass in one cell (log-prob 0, -inf elsewhere).
void write_delta(const std::filesystem::path& path, int v, int u, int bin) {
  std::vector<float> values(kSide * kSide * kBins, -std::numeric_limits<float>::infinity());
  values[static_cast<std::size_t>((v * kSide + u) * kBins + bin)] = 0;
  test::write_npy_float32(path, kSide, kSide, kBins, values);
}

struct Region {
  test::ScratchDir dir;
  std::filesystem::path cache;
};

// A cache of a synthetic map centred on (lat0, lon0) with an east-west road at y = 0 from x0 to x1.
std::unique_ptr<Region> make_region(double lat0, double lon0, double x0, double x1, double half_lon, double half_lat) {
  auto r = std::make_unique<Region>();
  osm::SyntheticMap map(lat0, lon0);
  map.way({{x0, 0.25}, {x1, 0.25}}, {{"highway", "track"}});
  map.write(r->dir / "map.osm.pbf");
  ingest::PreprocessOptions options;
  options.input = r->dir / "map.osm.pbf";
  options.output = r->dir / "region.gpkg";
  options.bbox = osm::GeoBox{lon0 - half_lon, lat0 - half_lat, lon0 + half_lon, lat0 + half_lat};
  ingest::preprocess_region(options);
  r->cache = options.output;
  return r;
}

LocalizeOptions small_options() {
  LocalizeOptions o;
  o.filter.width = o.filter.height = 64;
  o.filter.headings = kBins;
  return o;
}

long status_kb(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) == 0) return std::stol(line.substr(std::strlen(key)));
  }
  return -1;
}

// A route of `frames` frames driving east at 5 m per frame from x0, delta volumes at the truth.
io::Route straight_route(const test::ScratchDir& dir, const osm::RegionProjection& projection, double x0, int frames) {
  std::ofstream(dir / "route.json") << R"({"format": "seqloc-route", "version": 1, "name": "long"})";
  std::ofstream csv(dir / "frames.csv");
  csv.precision(17);
  csv << "frame,timestamp,volume,crop_x,crop_y,odo_forward_m,odo_left_m,odo_yaw_deg,gt_lat,gt_lon,gt_heading_deg\n";
  write_delta(dir / "v.npy", 7, 7, 16);  // the same file for every frame
  for (int t = 0; t < frames; ++t) {
    const double x = x0 + 5.0 * t, y = 0.25;
    double gamma = 0;
    const auto gt = projection.reverse({x, y}, gamma);
    csv << t << "," << t * 0.4 << ",v.npy," << x << "," << y << "," << (t ? 5 : 0) << ",0,0," << gt.lat_deg << ","
        << gt.lon_deg << "," << 90 + gamma << "\n";
  }
  csv.close();
  return io::read_route(dir.path());
}

TEST(Localize, DeltaAtTheTruthGivesZeroErrorInEveryMode) {
  const auto region = make_region(47.5, 10.5, -200, 200, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  const auto projection = cache.metadata().projection();
  // The vehicle drives east along the road, 5 m per frame, on cell centres (x = 0.25 + k / 2).
  test::ScratchDir dir;
  const int frames = 16;
  const io::Route route = straight_route(dir, projection, -40.25, frames);
  for (const io::Mode mode :
       {io::Mode::seqloc, io::Mode::online, io::Mode::single, io::Mode::offline, io::Mode::smooth}) {
    const io::RouteResult result = localize_route(route, cache, small_options(), mode);
    ASSERT_EQ(result.poses.size(), static_cast<std::size_t>(frames));
    for (const auto& p : result.poses) {
      // Exact but for MGR's eps * q mass around the peak, which moves PAS's mean by < 1e-4 m here.
      EXPECT_LT(*p.position_error_m, 1e-3) << io::mode_name(mode) << " frame " << p.frame;
      EXPECT_LT(*p.heading_error_deg, 1e-6) << io::mode_name(mode) << " frame " << p.frame;
    }
    if (mode == io::Mode::seqloc || mode == io::Mode::online || mode == io::Mode::smooth) {
      EXPECT_GT(result.recentres, 0) << "75 m of driving in a 32 m window";
    }
  }
}

TEST(Localize, VolumeTemperatureTempersEveryFrameBeforeTheFilter) {
  const auto region = make_region(47.5, 10.5, -200, 200, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  test::ScratchDir dir;
  const io::Route route = straight_route(dir, cache.metadata().projection(), -40.25, 4);
  // Replace the shared delta by a spread volume peaking at the truth.
  std::vector<float> values(kSide * kSide * kBins);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> noise(-2.0f, 0.0f);
  for (auto& x : values) x = noise(rng);
  values[static_cast<std::size_t>((7 * kSide + 7) * kBins + 16)] = 3.0f;
  test::write_npy_float32(dir / "v.npy", kSide, kSide, kBins, values);
  LocalizeOptions options = small_options();
  const io::RouteResult plain = localize_route(route, cache, options, io::Mode::single);
  options.volume_temperature = 0.25;  // p^4
  const io::RouteResult sharp = localize_route(route, cache, options, io::Mode::single);
  options.volume_temperature = 4.0;  // p^(1/4)
  const io::RouteResult flat = localize_route(route, cache, options, io::Mode::single);
  for (std::size_t t = 0; t < plain.poses.size(); ++t) {
    EXPECT_LT(sharp.poses[t].entropy, plain.poses[t].entropy - 0.05);
    EXPECT_GT(flat.poses[t].entropy, plain.poses[t].entropy + 0.005);
    EXPECT_LT(*sharp.poses[t].position_error_m, 1e-3) << "tempering keeps the argmax";
    EXPECT_LT(*flat.poses[t].position_error_m, 1e-3);
  }
  options.volume_temperature = 0;
  EXPECT_THROW(options.validate(), filter::FilterError);
}

// A delta route the way a backbone would write one: lat/lon crops centred on the truth (so off the
// cell lattice), moves of 1.3 m and turns of one heading bin, each volume a single cell at the
// truth. Every mode must find it; offline once lost it (a constant 90 m error) because bilinear
// warping of log-probabilities turned the sub-cell-shifted peaks into log(0), after which only
// cells no frame observes were left.
TEST(Localize, SubCellDeltaRouteIsFoundByEveryMode) {
  const auto region = make_region(47.5, 10.5, -200, 200, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  const auto projection = cache.metadata().projection();
  test::ScratchDir dir;
  std::ofstream(dir / "route.json") << R"({"format": "seqloc-route", "version": 1, "name": "delta"})";
  std::ofstream csv(dir / "frames.csv");
  csv.precision(17);
  csv << "frame,timestamp,volume,crop_lat,crop_lon,odo_forward_m,odo_left_m,odo_yaw_deg,gt_lat,gt_lon,gt_heading_deg\n";
  const double bin_deg = 360.0 / kBins;
  const std::vector<double> turns{0, 1, 1, 1, 0, 0, -1, -1, 0, 0, 1, 0, 0, 0};  // in bins, left positive
  double x = -20.3, y = 3.1, compass = 90.0;
  for (std::size_t t = 0; t < turns.size(); ++t) {
    const double step = t == 0 ? 0.0 : 1.3;
    const double yaw = turns[t] * bin_deg;
    if (t > 0) {
      // Move along the previous heading, then turn (the odometry of conventions.md section 1).
      x += step * std::sin(compass * M_PI / 180.0);
      y += step * std::cos(compass * M_PI / 180.0);
      compass = std::fmod(compass - yaw + 360.0, 360.0);
    }
    const auto where = projection.reverse({x, y});
    const std::string name = "v" + std::to_string(t) + ".npy";
    write_delta(dir / name, 7, 7, static_cast<int>(std::lround(compass / bin_deg)) % kBins);
    csv << t << "," << static_cast<double>(t) * 0.2 << "," << name << "," << where.lat_deg << "," << where.lon_deg << "," << step
        << ",0," << (t == 0 ? 0.0 : yaw) << "," << where.lat_deg << "," << where.lon_deg << "," << compass << "\n";
  }
  csv.close();
  const io::Route route = io::read_route(dir.path());
  for (const io::Mode mode :
       {io::Mode::single, io::Mode::offline, io::Mode::online, io::Mode::seqloc, io::Mode::smooth}) {
    const io::RouteResult result = localize_route(route, cache, small_options(), mode);
    ASSERT_EQ(result.poses.size(), turns.size());
    for (const auto& p : result.poses) {
      // The window's cells are 0.5 m: the nearest cell to a truth off the lattice is < 0.36 m away.
      EXPECT_LT(*p.position_error_m, 0.5) << io::mode_name(mode) << " frame " << p.frame;
      EXPECT_LT(*p.heading_error_deg, bin_deg / 2) << io::mode_name(mode) << " frame " << p.frame;
    }
  }
}

TEST(Localize, TheWindowFollowsCropsTheEstimateLostTrackOf) {
  // The odometry claims the vehicle stands still while it drives 75 m east: the estimate stays
  // behind (cells outside a 3.5 m crop keep the 1/M level of conventions.md, so an old strong
  // belief outweighs a small crop for a while), and the crops at the truth would leave the 32 m
  // window for good (errors up to 75 m) unless the window went to them. With the rule the error
  // stays within the window's half width.
  const auto region = make_region(47.5, 10.5, -200, 200, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  test::ScratchDir dir;
  io::Route route = straight_route(dir, cache.metadata().projection(), -40.25, 16);
  for (auto& f : route.frames) f.odometry = {};
  for (const io::Mode mode : {io::Mode::seqloc, io::Mode::online}) {
    const io::RouteResult result = localize_route(route, cache, small_options(), mode);
    for (const auto& p : result.poses)
      EXPECT_LT(*p.position_error_m, 16.0) << io::mode_name(mode) << " frame " << p.frame;
    EXPECT_GT(result.recentres, 0);
  }
}

TEST(Localize, HeadingsAreCompassHeadingsFarFromTheCentre) {
  // 11.3 km east of the region centre at 47.5 N the meridian convergence is 0.11 degrees.
  const double lat0 = 47.5, lon0 = 10.5;
  const auto region = make_region(lat0, lon0, 11000, 11400, 0.16, 0.003);
  raster::CacheReader cache(region->cache);
  const auto projection = cache.metadata().projection();
  double gamma = 0;
  const auto crop = projection.reverse({11200.25, 0.25}, gamma);
  ASSERT_GT(std::abs(gamma), 0.1) << "the test needs grid and true north to differ";
  // Lat/lon crops are north-up in true north; bin 16 of 64 is compass 90.
  test::ScratchDir dir;
  std::ofstream(dir / "route.json") << R"({"format": "seqloc-route", "version": 1})";
  std::ofstream csv(dir / "frames.csv");
  csv.precision(17);
  csv << "frame,timestamp,volume,crop_lat,crop_lon,odo_forward_m,odo_left_m,odo_yaw_deg\n";
  write_delta(dir / "v.npy", 0, 7, 16);  // 7 cells = 3.5 m true-north of the crop centre
  csv << "0,0,v.npy," << crop.lat_deg << "," << crop.lon_deg << ",0,0,0\n";
  csv.close();
  const io::RouteResult r = localize_route(io::read_route(dir.path()), cache, small_options(), io::Mode::single);
  ASSERT_EQ(r.poses.size(), 1u);
  EXPECT_NEAR(r.poses[0].compass_heading_deg, 90.0, 1e-6);
  // 3.5 m along true north is 3.5 m along grid heading -gamma: 6.7 mm east of grid north here.
  // 1e-5 m of tolerance: crop offsets are taken as grid metres, ignoring the Transverse
  // Mercator scale factor (1 + 1.5e-6 at 11 km, i.e. 5e-6 m over 3.5 m).
  const double g = -gamma * M_PI / 180.0;
  EXPECT_NEAR(r.poses[0].x_m, 11200.25 + 3.5 * std::sin(g), 1e-5);
  EXPECT_NEAR(r.poses[0].y_m, 0.25 + 3.5 * std::cos(g), 1e-5);
  EXPECT_GT(std::abs(3.5 * std::sin(g)), 6e-3) << "the rotation is what this checks";
}

TEST(Outputs, FrameIdsThatAreNotUtf8StillGiveValidJson) {
  // frames.csv is bytes: a frame id in Latin-1 once made nlohmann's dump throw at the very end of
  // a run (found by fuzz/request through the same dump in the server's error answers).
  test::ScratchDir dir;
  io::RouteResult result;
  result.route = "caf\xe9";
  io::FramePose pose;
  pose.frame = "f\xff\xfe" "1";
  result.poses.push_back(pose);
  io::write_route_outputs(dir.path(), result);
  const auto track = nlohmann::json::parse(test::read_file(dir / "track.geojson"));
  EXPECT_NE(track.dump().find("f\xef\xbf\xbd"), std::string::npos) << "the bad bytes become U+FFFD";
}

TEST(Metrics, RecallsMeansMediansAndBodyFrameErrors) {
  std::vector<io::FramePose> poses(4);
  const double position[] = {0.5, 2.0, 4.0, 10.0}, heading[] = {0.5, 0.9, 4.0, 179.0};
  for (int i = 0; i < 4; ++i) {
    poses[static_cast<std::size_t>(i)].position_error_m = position[i];
    poses[static_cast<std::size_t>(i)].heading_error_deg = heading[i];
    poses[static_cast<std::size_t>(i)].lateral_error_m = -position[i] / 2;
    poses[static_cast<std::size_t>(i)].longitudinal_error_m = position[i];
  }
  poses.emplace_back();  // no ground truth: not counted
  const io::Metrics m = io::compute_metrics(poses);
  EXPECT_EQ(m.frames, 4u);
  EXPECT_DOUBLE_EQ(m.position_recall[0], 25);
  EXPECT_DOUBLE_EQ(m.position_recall[1], 50);
  EXPECT_DOUBLE_EQ(m.position_recall[2], 75);
  EXPECT_DOUBLE_EQ(m.heading_recall[0], 50);
  EXPECT_DOUBLE_EQ(m.heading_recall[2], 75);
  EXPECT_DOUBLE_EQ(m.mean_position_error_m, 4.125);
  EXPECT_DOUBLE_EQ(m.median_position_error_m, 3.0);
  EXPECT_DOUBLE_EQ(m.mean_abs_lateral_m, 4.125 / 2);
  EXPECT_DOUBLE_EQ(m.mean_abs_longitudinal_m, 4.125);
}

}  // namespace
}  // namespace seqloc::pipeline::localize_tests

namespace seqloc::pipeline::localize_tests {
namespace {

// Ridge-shaped volumes along a straight road (the paper's failure case of single frames): every
// frame says "somewhere on this road, heading east", with noise along the ridge, but for frame
// kDistinctive, whose volume also says where along it the vehicle is.
constexpr int kRidgeFrames = 24, kDistinctive = 10;
io::Route ridge_route(const test::ScratchDir& dir, const osm::RegionProjection& projection) {
  std::ofstream(dir / "route.json") << R"({"format": "seqloc-route", "version": 1, "name": "ridge"})";
  std::ofstream csv(dir / "frames.csv");
  csv.precision(17);
  csv << "frame,timestamp,volume,crop_x,crop_y,odo_forward_m,odo_left_m,odo_yaw_deg,gt_lat,gt_lon,gt_heading_deg\n";
  std::mt19937 rng(21);
  std::normal_distribution<float> noise(0.0f, 0.6f);
  std::uniform_int_distribution<int> offset(-10, 10);  // crop centre off the truth, along the road
  const int frames = kRidgeFrames, distinctive = kDistinctive, side = 41, centre = 20;
  for (int t = 0; t < frames; ++t) {
    const double x = -100.25 + 5.0 * t, y = 0.25;
    const int shift = offset(rng);  // cells: the truth sits at column centre - shift of the crop
    std::vector<float> v(static_cast<std::size_t>(side * side * kBins));
    for (int row = 0; row < side; ++row)
      for (int col = 0; col < side; ++col)
        for (int j = 0; j < kBins; ++j) {
          const double dj = std::min(std::abs(j - 16), kBins - std::abs(j - 16));
          auto value = static_cast<float>(-(row - centre) * (row - centre) / 2.0 - dj * dj / 2.0);
          if (row == centre) value += noise(rng);  // where along the road: nobody knows
          if (t == distinctive && std::abs(col - (centre - shift)) > 1) value -= 6.0f;
          v[static_cast<std::size_t>((row * side + col) * kBins + j)] = value;
        }
    test::write_npy_float32(dir / ("v" + std::to_string(t) + ".npy"), side, side, kBins, v);
    double gamma = 0;
    const auto gt = projection.reverse({x, y}, gamma);
    csv << t << "," << t << ",v" << t << ".npy," << x + shift * 0.5 << "," << y << "," << (t ? 5 : 0) << ",0,0,"
        << gt.lat_deg << "," << gt.lon_deg << "," << 90 + gamma << "\n";
  }
  csv.close();
  return io::read_route(dir.path());
}

// The ridge route over its region, as each test of it starts.
struct RidgeCase {
  std::unique_ptr<Region> region = make_region(47.5, 10.5, -300, 300, 0.006, 0.002);
  raster::CacheReader cache{region->cache};
  test::ScratchDir dir;
  io::Route route = ridge_route(dir, cache.metadata().projection());
};

LocalizeOptions ridge_options() {
  LocalizeOptions options = small_options();
  options.filter.width = options.filter.height = 96;
  return options;
}

double mean_error(const io::RouteResult& r, int from, int to) {
  double sum = 0;
  for (int t = from; t < to; ++t) sum += *r.poses[static_cast<std::size_t>(t)].position_error_m;
  return sum / (to - from);
}

TEST(Localize, RidgesStayAmbiguousAloneAndConvergeInSequence) {
  RidgeCase ridge;
  const io::Route& route = ridge.route;
  raster::CacheReader& cache = ridge.cache;
  const LocalizeOptions options = ridge_options();
  const int frames = kRidgeFrames, distinctive = kDistinctive;
  auto mean_error_after = [&](const io::RouteResult& r) { return mean_error(r, distinctive + 1, frames); };
  const double single = mean_error_after(localize_route(route, cache, options, io::Mode::single));
  const io::RouteResult seqloc = localize_route(route, cache, options, io::Mode::seqloc);
  const double sequence = mean_error_after(seqloc);
  std::printf("mean error after the distinctive frame: single %.2f m, seqloc %.2f m\n", single, sequence);
  EXPECT_GT(single, 2.0) << "single frames are ambiguous along the ridge";
  EXPECT_LT(sequence, 1.0) << "SeqLoc keeps the position the distinctive frame gave";
  EXPECT_LT(*seqloc.poses[distinctive].position_error_m, 1.0);
}

// Smoothing carries the distinctive frame's evidence back to the frames before it, which the
// filter alone cannot place; a lag of L carries it back L frames.
TEST(Smooth, PlacesTheFramesBeforeTheDistinctiveOneAndLagsCarryItBackLFrames) {
  RidgeCase ridge;
  const io::Route& route = ridge.route;
  raster::CacheReader& cache = ridge.cache;
  LocalizeOptions options = ridge_options();
  const io::RouteResult seqloc = localize_route(route, cache, options, io::Mode::seqloc);
  const io::RouteResult smooth = localize_route(route, cache, options, io::Mode::smooth);
  const double seqloc_before = mean_error(seqloc, 0, kDistinctive), smooth_before = mean_error(smooth, 0, kDistinctive);
  std::printf("mean error before the distinctive frame: seqloc %.2f m, smooth %.2f m\n", seqloc_before, smooth_before);
  // The filter has not seen the distinctive frame yet: its error there is several times smooth's
  // (the ridge's ends still place it to within 1.6 m with the frames as given).
  EXPECT_GT(seqloc_before, 3 * smooth_before) << "the filter has not seen the distinctive frame yet";
  EXPECT_LT(smooth_before, 1.0);
  EXPECT_LT(mean_error(smooth, kDistinctive, kRidgeFrames), 1.0);
  EXPECT_GT(smooth.recentres, 0) << "the window moved: the backward pass retraced its moves";
  options.lag = 5;
  const io::RouteResult lag5 = localize_route(route, cache, options, io::Mode::seqloc);
  EXPECT_EQ(lag5.lag, 5);
  EXPECT_LT(mean_error(lag5, kDistinctive - 5, kRidgeFrames), 1.0) << "frames that see the distinctive one";
  const double lag5_early = mean_error(lag5, 0, kDistinctive - 5), smooth_early = mean_error(smooth, 0, kDistinctive - 5);
  std::printf("frames more than 5 before it: lag 5 %.2f m, smooth %.2f m\n", lag5_early, smooth_early);
  EXPECT_GT(lag5_early, 1.5 * smooth_early) << "frames that do not";
}

// The three ways to the same posterior agree: a lag of at least the route's length is smooth
// (its backward pass over beliefs kept in memory; smooth's over beliefs recomputed from
// checkpoints, three stretches here), a lag of L at frame t is smooth over frames 0 .. t + L, and a
// lag of 0 is the filter itself.
// As given, and with every frame four times too sharp (volume temperature 1/4), where the early
// replay refilters the route's first frames: smooth and the lags take its weightings and beliefs.
class FixedLag : public ::testing::TestWithParam<double> {};

TEST_P(FixedLag, AgreesWithSmoothAndLagZeroWithTheFilter) {
  RidgeCase ridge;
  const io::Route& route = ridge.route;
  raster::CacheReader& cache = ridge.cache;
  LocalizeOptions options = ridge_options();
  options.volume_temperature = GetParam();
  auto expect_same = [](const io::FramePose& a, const io::FramePose& b, const std::string& what) {
    EXPECT_EQ(a.x_m, b.x_m) << what << " frame " << a.frame;
    EXPECT_EQ(a.y_m, b.y_m) << what << " frame " << a.frame;
    EXPECT_EQ(a.grid_heading_deg, b.grid_heading_deg) << what << " frame " << a.frame;
  };
  const io::RouteResult smooth = localize_route(route, cache, options, io::Mode::smooth);
  const io::RouteResult seqloc = localize_route(route, cache, options, io::Mode::seqloc);
  if (GetParam() != 1.0) {
    bool replayed = false;  // a kept frame went in at 1, half an octave or more from a later one's power
    for (std::size_t t = 1; t < 16 && t < seqloc.poses.size(); ++t) {
      replayed = replayed || std::abs(std::log2(seqloc.poses[t].volume_power)) >= 0.5;
    }
    ASSERT_TRUE(replayed) << "the sharpened route replays its first frames";
  }
  options.lag = kRidgeFrames;
  const io::RouteResult whole = localize_route(route, cache, options, io::Mode::seqloc);
  ASSERT_EQ(whole.poses.size(), smooth.poses.size());
  for (std::size_t t = 0; t < smooth.poses.size(); ++t) expect_same(whole.poses[t], smooth.poses[t], "lag >= N vs smooth");
  options.lag = 3;
  const io::RouteResult lag3 = localize_route(route, cache, options, io::Mode::seqloc);
  for (const std::size_t t : {std::size_t{2}, std::size_t{9}, std::size_t{17}}) {
    io::Route head = route;
    head.frames.resize(t + 4);
    options.lag = 0;
    const io::RouteResult truncated = localize_route(head, cache, options, io::Mode::smooth);
    expect_same(lag3.poses[t], truncated.poses[t], "lag 3 vs smooth over frames 0 .. t + 3");
  }
  options.lag = 0;
  const io::RouteResult lag0 = localize_route(route, cache, options, io::Mode::seqloc);
  for (std::size_t t = 0; t < seqloc.poses.size(); ++t) expect_same(lag0.poses[t], seqloc.poses[t], "lag 0 vs seqloc");
  // The last frame has no later frames: smooth gives the filter's pose there (but for the rounding
  // of PAS's weights times a uniform beta).
  EXPECT_NEAR(smooth.poses.back().x_m, seqloc.poses.back().x_m, 1e-9);
  EXPECT_NEAR(smooth.poses.back().y_m, seqloc.poses.back().y_m, 1e-9);
  EXPECT_EQ(smooth.poses.back().grid_heading_deg, seqloc.poses.back().grid_heading_deg);
  options.lag = -1;
  EXPECT_THROW(options.validate(), filter::FilterError);
}

INSTANTIATE_TEST_SUITE_P(Smooth, FixedLag, ::testing::Values(1.0, 0.25),
                         [](const auto& p) { return p.param == 1.0 ? std::string("AsGiven") : std::string("Sharp"); });

}  // namespace
}  // namespace seqloc::pipeline::localize_tests

namespace seqloc::pipeline::localize_tests {
namespace {

TEST(Localize, MemoryStaysConstantAlongA20KmRoute) {
#if defined(__SANITIZE_ADDRESS__)  // GCC
#define SEQLOC_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)  // clang, which does not define GCC's macro before clang 17
#define SEQLOC_UNDER_ASAN 1
#endif
#endif
#if defined(SEQLOC_UNDER_ASAN)
  // ASan keeps freed blocks resident in its quarantine (up to 256 MB by default), so RSS there
  // measures the quarantine, not the program; the developer build runs this check.
  GTEST_SKIP() << "RSS is not the program's memory under AddressSanitizer";
#endif
  const auto region = make_region(47.5, 10.5, -10500, 10500, 0.145, 0.0015);
  raster::CacheReader cache(region->cache, /*lru_tiles=*/16);
  const auto projection = cache.metadata().projection();
  const LocalizeOptions options = small_options();
  test::ScratchDir short_dir, long_dir;
  const io::Route short_route = straight_route(short_dir, projection, -10000.25, 400);  // 2 km
  const io::Route long_route = straight_route(long_dir, projection, -10000.25, 4001);   // 20 km
  const auto short_result = localize_route(short_route, cache, options, io::Mode::seqloc);
  const long after_short = status_kb("VmRSS:");
  const auto long_result = localize_route(long_route, cache, options, io::Mode::seqloc);
  const long after_long = status_kb("VmRSS:");
  std::printf("20 km route: %d re-centres, RSS %ld kB after 2 km, %ld kB after 20 km, peak %ld kB\n",
              long_result.recentres, after_short, after_long, status_kb("VmHWM:"));
  EXPECT_GT(long_result.recentres, 400);
  // The poses themselves (4,000 x ~200 bytes) are the only thing that grows with the route.
  EXPECT_LT(after_long - after_short, 8 * 1024) << "kB";
  double worst = 0;
  for (const auto& p : long_result.poses) worst = std::max(worst, *p.position_error_m);
  EXPECT_LT(worst, 1e-3) << "the window followed the vehicle for 20 km";
  EXPECT_EQ(short_result.poses.size(), 400u);
}

TEST(Localize, ARouteAllowedToLeaveTheRegionKeepsGoingWithoutMap) {
  // The region spans about +-300 m; the route drives from inside to 150 m beyond its east edge.
  // Outside, the road distance is the clamp (no map information), so MGR's prior is flat there.
  // Crops outside the region are refused unless the user allows them (max_crop_outside_m).
  const auto region = make_region(47.5, 10.5, -300, 300, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  const double east_edge = cache.grid().max_x();
  test::ScratchDir dir;
  const io::Route route = straight_route(dir, cache.metadata().projection(), east_edge - 100.25, 50);
  EXPECT_THROW((void)localize_route(route, cache, small_options(), io::Mode::single), DataError);
  auto options = small_options();
  options.max_crop_outside_m = 150;
  for (const io::Mode mode : {io::Mode::seqloc, io::Mode::single}) {
    const auto r = localize_route(route, cache, options, mode);
    ASSERT_EQ(r.poses.size(), 50u);
    EXPECT_GT(r.poses.back().x_m, east_edge + 100) << "the last frames are outside the region";
    for (const auto& p : r.poses) EXPECT_LT(*p.position_error_m, 1e-3) << io::mode_name(mode) << " " << p.frame;
  }
}

// The same random volumes written as (H, W, N) and as (N, H, W) with "layout": "NHW" must give the
// same poses to the last bit; undeclared, an (N, H, W)-looking shape is refused by name.
TEST(VolumeLayout, NhwRoutesMatchHwnRoutesAndUndeclaredNhwIsRefused) {
  const auto region = make_region(47.5, 10.5, -200, 200, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  const auto projection = cache.metadata().projection();
  test::ScratchDir hwn_dir, nhw_dir;
  const int frames = 6;
  io::Route hwn = straight_route(hwn_dir, projection, -20.25, frames);
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0F, 3.0F);
  std::ofstream(nhw_dir / "route.json") << R"({"format": "seqloc-route", "version": 1, "layout": "NHW"})";
  {
    std::ifstream in(hwn_dir / "frames.csv");
    std::ofstream out(nhw_dir / "frames.csv");
    std::string line;
    int row = 0;
    while (std::getline(in, line)) {
      if (row > 0) {
        const std::string name = "v" + std::to_string(row) + ".npy";
        line.replace(line.find("v.npy"), 5, name);
        std::vector<float> hwn_values(kSide * kSide * kBins), nhw_values(hwn_values.size());
        for (auto& value : hwn_values) value = noise(rng);
        for (int v = 0; v < kSide; ++v) {
          for (int u = 0; u < kSide; ++u) {
            for (int k = 0; k < kBins; ++k) {
              nhw_values[static_cast<std::size_t>((k * kSide + v) * kSide + u)] =
                  hwn_values[static_cast<std::size_t>((v * kSide + u) * kBins + k)];
            }
          }
        }
        test::write_npy_float32(hwn_dir / name, kSide, kSide, kBins, hwn_values);
        test::write_npy_float32(nhw_dir / name, kBins, kSide, kSide, nhw_values);
      }
      out << line << "\n";
      ++row;
    }
  }
  {  // the HWN route names the same per-frame files
    std::ifstream in(nhw_dir / "frames.csv");
    std::ofstream(hwn_dir / "frames.csv") << in.rdbuf();
  }
  hwn = io::read_route(hwn_dir.path());
  const io::Route nhw = io::read_route(nhw_dir.path());
  ASSERT_EQ(nhw.layout, io::VolumeLayout::nhw);
  for (const io::Mode mode : {io::Mode::single, io::Mode::seqloc}) {
    const auto a = localize_route(hwn, cache, small_options(), mode);
    const auto b = localize_route(nhw, cache, small_options(), mode);
    ASSERT_EQ(a.poses.size(), b.poses.size());
    for (std::size_t i = 0; i < a.poses.size(); ++i) {
      EXPECT_EQ(a.poses[i].x_m, b.poses[i].x_m) << io::mode_name(mode) << " frame " << i;
      EXPECT_EQ(a.poses[i].y_m, b.poses[i].y_m) << io::mode_name(mode) << " frame " << i;
      EXPECT_EQ(a.poses[i].compass_heading_deg, b.poses[i].compass_heading_deg)
          << io::mode_name(mode) << " frame " << i;
    }
  }
  // A transposition that swapped H and W would still put a centred peak at the centre: the
  // random volumes above have their argmax anywhere, and single mode is that argmax.
  std::set<std::pair<long, long>> cells;
  for (const auto& p : localize_route(hwn, cache, small_options(), io::Mode::single).poses) {
    cells.emplace(std::lround(p.x_m * 2), std::lround(p.y_m * 2));
  }
  EXPECT_GT(cells.size(), 3u);

  // Undeclared: the (64, 15, 15) volumes read as (H, W, N) would be 64 x 15 cells of 15 headings.
  std::ofstream(nhw_dir / "route.json") << R"({"format": "seqloc-route", "version": 1})";
  const io::Route undeclared = io::read_route(nhw_dir.path());
  try {
    (void)localize_route(undeclared, cache, small_options(), io::Mode::single);
    FAIL() << "an (N, H, W)-looking volume must be refused";
  } catch (const DataError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("v1.npy (frames.csv line 2)"), std::string::npos) << what;
    EXPECT_NE(what.find("shape (64, 15, 15) looks like (N, H, W)"), std::string::npos) << what;
    EXPECT_NE(what.find(R"("layout": "NHW")"), std::string::npos) << what;
  }
}

TEST(Crops, OutsideTheRegionOrJumpingAreRefusedNamingTheLine) {
  const auto region = make_region(47.5, 10.5, -200, 200, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  const auto projection = cache.metadata().projection();
  test::ScratchDir dir;
  io::Route route = straight_route(dir, projection, -20.25, 4);
  const auto options = small_options();
  EXPECT_NO_THROW(check_crops(route, cache.grid(), projection, options));
  auto expect_refused = [&](const io::Route& r, const std::vector<std::string>& fragments) {
    try {
      check_crops(r, cache.grid(), projection, options);
      FAIL() << "expected a refusal";
    } catch (const DataError& e) {
      for (const auto& fragment : fragments)
        EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
    EXPECT_THROW((void)localize_route(r, cache, options, io::Mode::single), DataError);
  };
  // Latitude and longitude exchanged on the third frame: thousands of km away, and called swapped.
  io::Route swapped = route;
  const auto geo = projection.reverse({swapped.frames[2].crop_grid->x_m, swapped.frames[2].crop_grid->y_m});
  swapped.frames[2].crop_grid.reset();
  swapped.frames[2].crop_geo = osm::GeoPoint{geo.lon_deg, geo.lat_deg};
  expect_refused(swapped, {"frames.csv:4: ", "km from the region's centre, outside the region", "look swapped"});
  // A grid crop just outside the region's east edge.
  io::Route outside = route;
  outside.frames[1].crop_grid->x_m = cache.grid().max_x() + 1;
  expect_refused(outside, {"frames.csv:3: ", "lies outside the region (x in ["});
  // A jump of 40 m between consecutive crops, beyond the 32 m window of these options.
  io::Route jump = route;
  jump.frames[3].crop_grid->x_m += 40;
  expect_refused(jump, {"frames.csv:5: crop centre lies 45.0 m from the previous frame's (line 4), more than the limit of 32.0 m"});
  auto wider = options;
  wider.max_crop_jump_m = 50;
  EXPECT_NO_THROW(check_crops(jump, cache.grid(), projection, wider));
}

// The window's conversions against the grid's own: a window cell is the region pixel moved by the
// origin, metres round-trip, centring puts the nearest pixel at (W/2, H/2), a shift moves the
// origin, and the road distance is the cache's own window in metres.
TEST(RegionWindow, ConvertsCentresShiftsAndReadsTheRoadOfItsCells) {
  const auto region = make_region(47.5, 10.5, -200, 200, 0.004, 0.002);
  raster::CacheReader cache(region->cache);
  const auto& grid = cache.grid();
  RegionWindow window(cache, 64, 48);
  window.centre_on(10.3, 0.2);
  const auto cu = std::lround(grid.region_u(10.3)), cv = std::lround(grid.region_v(0.2));
  EXPECT_EQ(window.origin_u(), cu - 32);
  EXPECT_EQ(window.origin_v(), cv - 24);
  EXPECT_DOUBLE_EQ(window.u_of(10.3), grid.region_u(10.3) - static_cast<double>(cu - 32));
  EXPECT_NEAR(window.x_of(window.u_of(10.3)), 10.3, 1e-9);
  EXPECT_NEAR(window.y_of(window.v_of(-7.7)), -7.7, 1e-9);
  EXPECT_NEAR(window.x_of(1.0) - window.x_of(0.0), raster::kCellM, 1e-12);
  EXPECT_NEAR(window.y_of(1.0) - window.y_of(0.0), -raster::kCellM, 1e-12) << "v runs south";
  const auto crop = window.crop_pose({10.3, 0.2, -1.5});
  EXPECT_NEAR(crop.centre_u, 32, 0.5);
  EXPECT_NEAR(crop.centre_v, 24, 0.5);
  EXPECT_EQ(crop.rotation_deg, -1.5);

  // Inside the margin of a quarter: no move; beyond it, the move that centres the position.
  EXPECT_FALSE(window.recentre_shift(20, 20, 0.25));
  EXPECT_FALSE(window.recentre_shift(16, 12, 0.25));
  const auto shift = window.recentre_shift(60.4, 5.6, 0.25);
  ASSERT_TRUE(shift);
  EXPECT_EQ((*shift)[0], 60 - 32);
  EXPECT_EQ((*shift)[1], 6 - 24);
  EXPECT_TRUE(window.recentre_shift(-3, 20, 0.25)) << "outside the window";

  std::vector<std::uint16_t> cm;
  auto expect_road_of_window = [&] {
    cache.read_road_distance(window.origin_u(), window.origin_v(), 64, 48, cm, true);
    const std::span<const float> road = window.road_distance_m();
    ASSERT_EQ(road.size(), cm.size()) << "the window's cells";
    for (std::size_t i = 0; i < cm.size(); ++i) ASSERT_EQ(road[i], static_cast<float>(cm[i] * 0.01)) << i;
  };
  expect_road_of_window();
  window.shift(7, -3);
  EXPECT_EQ(window.origin_u(), cu - 32 + 7);
  EXPECT_EQ(window.origin_v(), cv - 24 - 3);
  expect_road_of_window();  // read again after the move
}

// Frames come in order from the source, the next one prepared meanwhile (lookahead) or not; the
// source's error for a frame surfaces when that frame is asked for.
TEST(FramePrefetcher, GivesEachFrameOnceInOrderAndRethrowsItsError) {
  for (const bool lookahead : {false, true}) {
    std::mutex mutex;
    std::vector<std::size_t> asked;
    const FrameSource source = [&](std::size_t i) {
      {
        std::lock_guard lock(mutex);
        asked.push_back(i);
      }
      if (i == 3) throw DataError("frame 3 is bad");
      auto f = std::make_shared<filter::PreparedFrame>();
      f->entropy = static_cast<double>(i);
      return std::shared_ptr<const filter::PreparedFrame>(f);
    };
    FramePrefetcher frames(source, 5, lookahead);
    EXPECT_EQ(frames.get(0).entropy, 0);
    EXPECT_EQ(frames.get(1).entropy, 1);
    EXPECT_EQ(frames.get(1).entropy, 1) << "kept until released";
    frames.release(1);
    EXPECT_EQ(frames.get(2).entropy, 2);
    EXPECT_THROW((void)frames.get(3), DataError);
    {
      std::lock_guard lock(mutex);
      EXPECT_EQ(asked, (std::vector<std::size_t>{0, 1, 2, 3})) << "each frame asked for once, in order";
      asked.clear();
    }
    // With lookahead, taking frame 0 has frame 1 prepared in the background (the destructor
    // waits for it); without, nothing more is asked for.
    {
      FramePrefetcher ahead(source, 5, lookahead);
      EXPECT_EQ(ahead.get(0).entropy, 0);
    }
    EXPECT_EQ(asked, lookahead ? (std::vector<std::size_t>{0, 1}) : (std::vector<std::size_t>{0})) << lookahead;
  }
}

}  // namespace
}  // namespace seqloc::pipeline::localize_tests
