// Several regions used together: a route that crosses from one region's grid into the next is
// followed across, the belief handed over at the seam, and gets the poses it gets in one region
// built over both.

#include <cmath>
#include <fstream>
#include <random>

#include <GeographicLib/Geodesic.hpp>
#include <gtest/gtest.h>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/region_catalog.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"
#include "support/test_support.hpp"

namespace seqloc::pipeline::catalog_tests {
namespace {

constexpr double kLat0 = 47.5, kLon0 = 10.5;
constexpr int kBins = 64, kSide = 41, kCentre = 20, kFrames = 120, kRidgeFrom = 45;

std::filesystem::path build(const std::filesystem::path& osm, const std::filesystem::path& out, double lon0,
                            double lon1) {
  ingest::PreprocessOptions options;
  options.input = osm;
  options.output = out;
  options.bbox = osm::GeoBox{lon0, kLat0 - 0.0025, lon1, kLat0 + 0.0025};
  ingest::preprocess_region(options);
  return out;
}

// A route east along the road from x = -300 m to +295 m of the map's centre (lon 10.5, where the
// two regions meet; the route reaches it at frame 60), crops in lat/lon off the truth along the
// road. The first kRidgeFrom frames' volumes say where the vehicle is; from there on each is a
// flat ridge along the road (where along it: nobody knows), which only the belief carried from
// the frames before can place.
// With `reversed`, it is the other way round: the frames from kFrames - kRidgeFrom on say where the
// vehicle is, the ones before are the ridge, which only the frames after can place.
io::Route ridge_route(const std::filesystem::path& dir, bool reversed = false) {
  const osm::RegionProjection local(kLat0, kLon0);
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "route.json") << R"({"format": "seqloc-route", "version": 1, "name": "across"})";
  std::ofstream csv(dir / "frames.csv");
  csv.precision(17);
  csv << "frame,timestamp,volume,crop_lat,crop_lon,odo_forward_m,odo_left_m,odo_yaw_deg,gt_lat,gt_lon,"
         "gt_heading_deg\n";
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> offset(-10, 10);
  for (int t = 0; t < kFrames; ++t) {
    const double x = -300.25 + 5.0 * t, y = 0.25;
    const int shift = offset(rng);
    std::vector<float> v(static_cast<std::size_t>(kSide * kSide * kBins));
    for (int row = 0; row < kSide; ++row)
      for (int col = 0; col < kSide; ++col)
        for (int j = 0; j < kBins; ++j) {
          const double dj = std::min(std::abs(j - 16), kBins - std::abs(j - 16));
          auto value = static_cast<float>(-(row - kCentre) * (row - kCentre) / 2.0 - dj * dj / 2.0);
          if (reversed ? t >= kFrames - kRidgeFrom : t < kRidgeFrom) {
            const double along = col - (kCentre - shift);
            value -= static_cast<float>(along * along / (2 * 1.5 * 1.5));
          }
          v[static_cast<std::size_t>((row * kSide + col) * kBins + j)] = value;
        }
    test::write_npy_float32(dir / ("v" + std::to_string(t) + ".npy"), kSide, kSide, kBins, v);
    double gamma = 0;
    const auto gt = local.reverse({x, y}, gamma);
    const auto crop = local.reverse({x + shift * 0.5, y});
    csv << t << "," << t << ",v" << t << ".npy," << crop.lat_deg << "," << crop.lon_deg << "," << (t ? 5 : 0)
        << ",0,0," << gt.lat_deg << "," << gt.lon_deg << "," << 90 + gamma << "\n";
  }
  csv.close();
  return io::read_route(dir);
}

struct Seam {
  test::ScratchDir dir;
  std::filesystem::path whole, west, east;
  io::Route route, reversed;
  Seam() {
    osm::SyntheticMap map(kLat0, kLon0);
    map.way({{-1400, 0.25}, {1400, 0.25}}, {{"highway", "track"}});
    map.write(dir / "map.osm.pbf");
    whole = build(dir / "map.osm.pbf", dir / "whole.gpkg", kLon0 - 0.02, kLon0 + 0.02);
    std::filesystem::create_directories(dir / "regions");
    west = build(dir / "map.osm.pbf", dir / "regions" / "west.gpkg", kLon0 - 0.02, kLon0);
    east = build(dir / "map.osm.pbf", dir / "regions" / "east.gpkg", kLon0, kLon0 + 0.02);
    route = ridge_route(dir / "route");
    reversed = ridge_route(dir / "reversed", /*reversed=*/true);
  }
};

LocalizeOptions options() {
  LocalizeOptions o;
  o.filter.width = o.filter.height = 96;
  o.filter.headings = kBins;
  return o;
}

double apart_m(const io::FramePose& a, const io::FramePose& b) {
  double s = 0;
  GeographicLib::Geodesic::WGS84().Inverse(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg, s);
  return s;
}

TEST(RegionCatalog, ARouteAcrossTwoRegionsGetsThePosesOfOneRegionOverBoth) {
  Seam seam;
  raster::CacheReader whole(seam.whole);
  const RegionCatalog one(whole);
  const RegionCatalog two({seam.dir / "regions"});  // a folder: west.gpkg, east.gpkg
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(two.name(0), "east");
  const std::vector<io::Mode> modes{io::Mode::seqloc, io::Mode::online, io::Mode::single, io::Mode::offline,
                                    io::Mode::smooth};
  const auto a = localize_routes({seam.route}, one, options(), modes);
  const auto b = localize_routes({seam.route}, two, options(), modes);
  ASSERT_EQ(a.results.size(), modes.size());
  ASSERT_EQ(b.results.size(), modes.size());
  for (std::size_t m = 0; m < modes.size(); ++m) {
    const io::RouteResult& x = a.results[m];
    const io::RouteResult& y = b.results[m];
    ASSERT_EQ(y.poses.size(), static_cast<std::size_t>(kFrames));
    EXPECT_EQ(x.region_crossings, 0);
    EXPECT_EQ(y.region_crossings, 1) << io::mode_name(modes[m]);  // the route's, whatever the mode
    EXPECT_EQ(y.poses.front().region, "west");
    EXPECT_EQ(y.poses.back().region, "east");
    EXPECT_EQ(x.poses.back().region, "whole");
    // Offline's pose of a frame whose whole neighbourhood lies on the ridge is a tie along the road
    // (argmax over a flat ridge), decided by parts of a cell: compared are the frames whose
    // neighbourhood holds a frame that places the vehicle; some of them hold frames of both regions.
    const auto half = static_cast<std::size_t>(options().offline_half_window);
    const std::size_t compared =
        modes[m] == io::Mode::offline ? static_cast<std::size_t>(kRidgeFrom) + half : y.poses.size();
    std::size_t first_east = 0;
    while (y.poses[first_east].region == "west") ++first_east;
    EXPECT_LT(first_east, compared + half) << "no compared frame sums frames of both regions";
    double worst = 0, sum = 0;
    for (std::size_t i = 0; i < compared; ++i) {
      const double d = apart_m(x.poses[i], y.poses[i]);
      worst = std::max(worst, d);
      sum += d;
      // Each pose's error is measured in its own region's CRS, against the same truth.
      EXPECT_NEAR(*x.poses[i].position_error_m, *y.poses[i].position_error_m, 0.75)
          << io::mode_name(modes[m]) << " " << i;
    }
    const double mean = sum / static_cast<double>(compared);
    std::printf("%s: one region vs two, poses apart by %.3f m on average, %.3f m at most (%zu frames)\n",
                io::mode_name(modes[m]), mean, worst, compared);
    // The lattices of the three CRSs differ by parts of a cell (0.5 m).
    EXPECT_LT(mean, 0.25) << io::mode_name(modes[m]);
    EXPECT_LT(worst, 0.5) << io::mode_name(modes[m]);
  }
  // The belief crossed the seam: along the ridge only the frames before it say where the vehicle
  // is, and seqloc keeps it to the end of the route, well past the seam; single frames do not.
  auto mean_error = [](const io::RouteResult& r, int from, int to) {
    double sum = 0;
    for (int t = from; t < to; ++t) sum += *r.poses[static_cast<std::size_t>(t)].position_error_m;
    return sum / (to - from);
  };
  const int after_seam = kFrames - 40;
  EXPECT_LT(mean_error(b.results[0], after_seam, kFrames), 1.0) << "seqloc after the seam";
  EXPECT_GT(mean_error(b.results[2], after_seam, kFrames), 2.0) << "single frames along the ridge";
  EXPECT_LT(mean_error(b.results[4], after_seam, kFrames), 1.0) << "smooth after the seam";
}

// The backward filter's belief crosses the seam too: the frames before it are placed only by the
// frames after it, which smooth carries back across.
TEST(RegionCatalog, SmoothCarriesTheLaterFramesBackAcrossTheSeam) {
  Seam seam;
  raster::CacheReader whole(seam.whole);
  const RegionCatalog one(whole);
  const RegionCatalog two({seam.west, seam.east});
  const std::vector<io::Mode> modes{io::Mode::smooth, io::Mode::seqloc};
  const auto a = localize_routes({seam.reversed}, one, options(), modes);
  const auto b = localize_routes({seam.reversed}, two, options(), modes);
  const auto& x = a.results[0].poses;
  const auto& y = b.results[0].poses;
  ASSERT_EQ(y.size(), static_cast<std::size_t>(kFrames));
  EXPECT_EQ(b.results[0].region_crossings, 1);
  // Every frame that places the vehicle is in the east; the west's frames are all on the ridge.
  double worst = 0, smooth_error = 0, seqloc_error = 0;
  int west = 0;
  for (int t = 0; t < kFrames; ++t) {
    const auto i = static_cast<std::size_t>(t);
    worst = std::max(worst, apart_m(x[i], y[i]));
    if (y[i].region == "west") {
      ASSERT_LT(t, kFrames - kRidgeFrom);
      ++west;
      smooth_error += *y[i].position_error_m;
      seqloc_error += *b.results[1].poses[i].position_error_m;
    }
  }
  ASSERT_GT(west, 40);
  smooth_error /= west;
  seqloc_error /= west;
  std::printf(
      "smooth, reversed ridge: one region vs two %.3f m apart at most; mean error in the west "
      "(%d frames) %.2f m (seqloc %.2f m)\n",
      worst, west, smooth_error, seqloc_error);
  EXPECT_LT(worst, 0.5);
  EXPECT_LT(smooth_error, 1.0) << "the west's frames placed by the frames across the seam";
  EXPECT_GT(seqloc_error, 2.0) << "forward alone cannot place them";
}

// Fixed-lag smoothing crosses the seam as well: with a lag of L frames, the last L frames before
// the seam are placed by the frames after it, which the lag's backward filter carries back.
TEST(RegionCatalog, TheLagCarriesTheLaterFramesBackAcrossTheSeam) {
  Seam seam;
  raster::CacheReader whole(seam.whole);
  const RegionCatalog one(whole);
  const RegionCatalog two({seam.west, seam.east});
  // The reversed ridge from its frame 30 on (every lagged frame costs L backward steps).
  constexpr int kSkip = 30, kLag = 20, kPlacing = kFrames - kRidgeFrom - kSkip;  // the first frame that places
  io::Route route = seam.reversed;
  route.frames.erase(route.frames.begin(), route.frames.begin() + kSkip);
  LocalizeOptions lagged = options();
  lagged.lag = kLag;
  const auto a = localize_routes({route}, one, lagged, {io::Mode::seqloc});
  const auto b = localize_routes({route}, two, lagged, {io::Mode::seqloc});
  const auto& x = a.results[0].poses;
  const auto& y = b.results[0].poses;
  ASSERT_EQ(y.size(), route.frames.size());
  EXPECT_EQ(b.results[0].region_crossings, 1);
  int seam_frame = 0;
  while (y[static_cast<std::size_t>(seam_frame)].region == "west") ++seam_frame;
  // The frames whose lag reaches a frame that places the vehicle; the west holds some of them.
  // Before them, every frame the pose depends on is on the ridge: the pose is a tie along the road
  // (decided by parts of a cell, so not compared between the CRSs).
  const int reached_from = kPlacing - kLag;
  ASSERT_LT(reached_from + 3, seam_frame) << "the fixture must put such frames in the west";
  double worst = 0, reached = 0, unreached = 0;
  for (int t = 0; t < static_cast<int>(y.size()); ++t) {
    const auto i = static_cast<std::size_t>(t);
    if (t >= reached_from) worst = std::max(worst, apart_m(x[i], y[i]));
    if (t >= reached_from && t < seam_frame) reached += *y[i].position_error_m;
    if (t < reached_from) unreached += *y[i].position_error_m;
  }
  reached /= seam_frame - reached_from;
  unreached /= reached_from;
  std::printf(
      "seqloc lag %d, reversed ridge: one region vs two %.3f m apart at most (%zu frames); mean error of "
      "the %d west frames the lag reaches across the seam %.2f m (of the %d it does not reach %.2f m)\n",
      kLag, worst, y.size() - reached_from, seam_frame - reached_from, reached, reached_from, unreached);
  EXPECT_LT(worst, 0.5);
  EXPECT_LT(reached, 1.0) << "the lag's frames across the seam place the west's last frames";
  EXPECT_GT(unreached, 2.0) << "the frames beyond the lag's reach stay on the ridge";
}

// Where the belief's mass is: its centroid on the ellipsoid, and its circular mean compass heading.
struct Centroid {
  osm::GeoPoint where;
  double compass_deg = 0;
};
Centroid centroid(const SequentialLocalizer& localizer) {
  const auto& b = localizer.filter()->belief();
  const auto& window = localizer.window();
  const auto projection = window.cache().metadata().projection();
  double mass = 0, u = 0, v = 0, s = 0, c = 0;
  for (int k = 0; k < b.headings(); ++k)
    for (int y = 0; y < b.height(); ++y)
      for (int x = 0; x < b.width(); ++x) {
        const double p = b.prob(x, y, k), theta = b.bin_heading_deg(k) * M_PI / 180.0;
        mass += p;
        u += p * x;
        v += p * y;
        s += p * std::sin(theta);
        c += p * std::cos(theta);
      }
  double gamma = 0;
  const osm::GeoPoint where = projection.reverse({window.x_of(u / mass), window.y_of(v / mass)}, gamma);
  return {where, std::fmod(std::atan2(s, c) * 180.0 / M_PI + gamma + 360.0, 360.0)};
}

// The hand-over between two regions whose CRSs are 225 km apart, so that their grid norths differ
// by 1.1 degrees where the vehicle is: the belief moved into the next region's grid stays where it
// was on the ellipsoid, and its headings are turned so that its compass headings stay too; a crop
// carried across is the one made in the next grid.
TEST(RegionCatalog, HandOverKeepsTheBeliefsPlaceAndCompassHeadingAndCropsCarryAcross) {
  test::ScratchDir dir;
  constexpr double lon = 11.5;
  osm::SyntheticMap map(kLat0, lon);
  map.way({{-300, 0.25}, {300, 0.25}}, {{"highway", "track"}});
  map.write(dir / "map.osm.pbf");
  raster::CacheReader west(build(dir / "map.osm.pbf", dir / "west.gpkg", 10.0, lon + 0.01));
  raster::CacheReader east(build(dir / "map.osm.pbf", dir / "east.gpkg", lon - 0.01, 13.0));
  const auto pw = west.metadata().projection(), pe = east.metadata().projection();
  double gamma_west = 0, gamma_east = 0;
  const osm::GeoPoint crop{kLat0 + 0.0001, lon};
  const auto g = pw.forward(crop, gamma_west);
  (void)pe.forward(crop, gamma_east);
  ASSERT_GT(gamma_west - gamma_east, 1.0) << "the two grid norths differ there";
  {
    // A crop carried into the other grid is the crop made there (offline's neighbours): same
    // place, north at grid heading -gamma of the new CRS.
    const auto ge = pe.forward(crop);
    const GridCrop carried = carry_crop(GridCrop{g.x_m, g.y_m, -gamma_west}, pw, pe);
    EXPECT_NEAR(carried.x, ge.x_m, 1e-6);
    EXPECT_NEAR(carried.y, ge.y_m, 1e-6);
    EXPECT_NEAR(carried.rotation_deg, -gamma_east, 1e-9);
  }

  // One frame: a Gaussian blob (sigma 2 cells) heading 70 degrees true (spread over a few bins).
  constexpr int side = 31, bins = 256;
  std::vector<float> values(static_cast<std::size_t>(side * side * bins));
  for (int row = 0; row < side; ++row)
    for (int col = 0; col < side; ++col)
      for (int j = 0; j < bins; ++j) {
        const double dj = std::remainder(j * 360.0 / bins - 70.0, 360.0) / 3.0;
        values[static_cast<std::size_t>((row * side + col) * bins + j)] =
            static_cast<float>(-((row - 12) * (row - 12) + (col - 18) * (col - 18)) / 8.0 - dj * dj / 2.0);
      }
  LocalizeOptions o = options();
  o.filter.headings = bins;
  const auto frame = prepare_volume({values.data(), filter::VolumeType::float32, filter::VolumeValues::log_prob,
                                     side, side, bins, 0.5}, o);
  SequentialLocalizer localizer(west, o.filter, /*online=*/true, o.recentre_margin);
  (void)localizer.step(frame, GridCrop{g.x_m, g.y_m, -gamma_west}, {}, std::nullopt);
  const Centroid before = centroid(localizer);
  localizer.hand_over(east);
  EXPECT_EQ(&localizer.window().cache(), &east);
  const Centroid after = centroid(localizer);
  double apart = 0;
  GeographicLib::Geodesic::WGS84().Inverse(before.where.lat_deg, before.where.lon_deg, after.where.lat_deg,
                                           after.where.lon_deg, apart);
  EXPECT_LT(apart, 0.25) << "the nearest cell of the new grid: at most half a cell's diagonal off";
  EXPECT_NEAR(after.compass_deg, before.compass_deg, 0.1) << "turned by gamma: " << gamma_west - gamma_east;
  EXPECT_NEAR(before.compass_deg, 70.0, 0.5);
}

TEST(RegionCatalog, CropsOutsideEveryRegionAreNamed) {
  Seam seam;
  const RegionCatalog two({seam.west, seam.east});
  // A crop 11 km north of both regions.
  io::Route far = seam.route;
  far.frames[5].crop_geo = osm::GeoPoint{kLat0 + 0.1, kLon0};
  try {
    (void)route_regions(far, two, 48);
    ADD_FAILURE() << "a crop in no region was accepted";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("frames.csv:7: the crop at lat 47.6"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("(west, east)"), std::string::npos) << e.what();
  }
  const std::vector<std::filesystem::path> twice{seam.west, seam.west};
  EXPECT_THROW(RegionCatalog{twice}, UsageError) << "two regions of one name";
}

}  // namespace
}  // namespace seqloc::pipeline::catalog_tests
