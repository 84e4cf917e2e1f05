// Preprocessing end to end on synthetic maps whose answer is known from their geometry, and the
// refusal of bad requests before any output is touched.

#include <fstream>
#include <thread>

#include <gtest/gtest.h>

#include "seqloc/osm/reader.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/preprocess.hpp"
#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc::pipeline {
namespace {

constexpr double kLat0 = 47.5, kLon0 = 10.5;
// Symmetric around (kLat0, kLon0), so the region CRS is the synthetic map's local frame.
const osm::GeoBox kBox{kLon0 - 0.004, kLat0 - 0.003, kLon0 + 0.004, kLat0 + 0.003};

// Coordinates in metres of the centre of global cell (u, v) (grid.hpp).
osm::LocalPoint cell(std::int64_t u, std::int64_t v) { return {raster::centre_x(u), raster::centre_y(v)}; }

osm::SyntheticMap known_map() {
  osm::SyntheticMap map(kLat0, kLon0);
  map.node(cell(20, -41), {{"natural", "tree"}});
  // An east-west road along global row 100, cells -201 .. 200.
  map.way({cell(-201, 100), cell(200, 100)}, {{"highway", "secondary"}});
  // A fence crossing it at column 150.
  map.way({cell(150, 95), cell(150, 105)}, {{"barrier", "fence"}});
  // A building, cells 60..80 x -70..-60, inside a forest with a hole.
  map.way({cell(60, -70), cell(80, -70), cell(80, -60), cell(60, -60)}, {{"building", "yes"}}, true);
  map.multipolygon({{cell(-100, -200), cell(200, -200), cell(200, -20), cell(-100, -20)}},
                   {{cell(-60, -160), cell(-20, -160), cell(-20, -120), cell(-60, -120)}}, {{"landuse", "forest"}});
  return map;
}

// The known map written to `dir`, with options to preprocess it over kBox into dir/r.gpkg.
PreprocessOptions known_options(const test::ScratchDir& dir) {
  known_map().write(dir / "map.osm.pbf", 50);
  PreprocessOptions options;
  options.input = dir / "map.osm.pbf";
  options.output = dir / "r.gpkg";
  options.bbox = kBox;
  return options;
}

struct Built {
  test::ScratchDir dir;
  std::filesystem::path cache;
};

std::unique_ptr<Built> build_known() {
  auto b = std::make_unique<Built>();
  const auto options = known_options(b->dir);
  preprocess_region(options);
  b->cache = options.output;
  return b;
}

TEST(Preprocess, KnownGeometryGivesKnownPixels) {
  const auto built = build_known();
  raster::CacheReader reader(built->cache);
  const auto& m = reader.metadata();
  EXPECT_DOUBLE_EQ(m.centre_lat, kLat0);
  EXPECT_DOUBLE_EQ(m.centre_lon, kLon0);
  const raster::Pixel o = m.grid.origin();
  std::vector<std::uint8_t> rgb;
  std::vector<std::uint16_t> cm;
  const int w = static_cast<int>(m.grid.width_px()), h = static_cast<int>(m.grid.height_px());
  reader.read_classes(0, 0, w, h, rgb);
  reader.read_road_distance(0, 0, w, h, cm);
  auto at = [&](std::int64_t u, std::int64_t v) { return static_cast<std::size_t>((v - o.v) * w + (u - o.u)); };
  auto areas = [&](std::int64_t u, std::int64_t v) { return rgb[at(u, v) * 3]; };
  auto ways = [&](std::int64_t u, std::int64_t v) { return rgb[at(u, v) * 3 + 1]; };
  auto nodes = [&](std::int64_t u, std::int64_t v) { return rgb[at(u, v) * 3 + 2]; };
  auto metres = [&](std::int64_t u, std::int64_t v) { return cm[at(u, v)] / 100.0; };
  const auto code = [](const char* g) { return osm::find_group(g)->code(); };

  // The tree: exactly one cell, at its own cell (pixel centres, north-up rows).
  EXPECT_EQ(nodes(20, -41), code("tree"));
  EXPECT_EQ(nodes(20, -40), 0);
  EXPECT_EQ(nodes(20, -42), 0);
  EXPECT_EQ(nodes(21, -41), 0);

  // The road: one cell wide; distance 0 on it, exact metres off it.
  EXPECT_EQ(ways(0, 100), code("road"));
  EXPECT_EQ(ways(0, 99), 0);
  EXPECT_EQ(ways(0, 101), 0);
  EXPECT_EQ(metres(0, 100), 0.0);
  EXPECT_EQ(metres(0, 80), 10.0);          // 20 cells north
  EXPECT_EQ(metres(0, 106), 3.0);          // 6 cells south
  EXPECT_EQ(metres(210, 100), 5.0);        // 10 cells past the east end
  EXPECT_EQ(metres(210, 94), 5.83);        // sqrt(10^2 + 6^2) / 2 = 5.8310 m
  EXPECT_EQ(metres(-100, -150), 100.0);    // 125 m from the road: the clamp

  // The fence wins the ways channel where it crosses the road (fence precedes road), but the
  // road distance still sees the road there.
  EXPECT_EQ(ways(150, 100), code("fence"));
  EXPECT_EQ(ways(150, 97), code("fence"));
  EXPECT_EQ(metres(150, 100), 0.0);

  // The building: filled in the areas channel (over the forest: building precedes forest),
  // outlined in the ways channel.
  EXPECT_EQ(areas(70, -65), code("building"));
  EXPECT_EQ(areas(60, -70), code("building"));
  EXPECT_EQ(ways(60, -65), code("building_outline"));
  EXPECT_EQ(ways(70, -65), 0);
  EXPECT_EQ(areas(81, -65), code("forest"));

  // The forest and its hole.
  EXPECT_EQ(areas(0, -100), code("forest"));
  EXPECT_EQ(areas(-40, -140), 0) << "inside the inner ring";
  EXPECT_EQ(areas(-60, -140), code("forest")) << "the inner ring's outline is drawn";
  EXPECT_EQ(areas(0, -10), 0) << "north of the forest";

  const auto roads = reader.roads();
  ASSERT_EQ(roads.size(), 1u);
  EXPECT_EQ(roads[0].highway, "secondary");
  EXPECT_NEAR(roads[0].points[0].x_m, raster::centre_x(-201), 0.02);  // OSM stores 1e-7 degrees
}

TEST(Preprocess, DefaultRegionIsTheHeaderBbox) {
  test::ScratchDir dir;
  known_map().write(dir / "map.osm.pbf", 50);
  const auto header = osm::read_osm_header(dir / "map.osm.pbf");
  ASSERT_TRUE(header.box.has_value());
  PreprocessOptions options;
  options.input = dir / "map.osm.pbf";
  options.output = dir / "r.gpkg";
  const auto report = preprocess_region(options);
  EXPECT_DOUBLE_EQ(report.bbox.min_lon, header.box->min_lon);
  EXPECT_DOUBLE_EQ(report.bbox.max_lat, header.box->max_lat);
  EXPECT_EQ(report.tiles_written, report.tiles_total);
}

void expect_usage_error(const PreprocessOptions& options, const std::string& fragment) {
  try {
    preprocess_region(options);
    FAIL() << "expected an error containing '" << fragment << "'";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(Preprocess, BadRequestsFailBeforeTouchingAnything) {
  test::ScratchDir dir;
  const auto options = known_options(dir);
  preprocess_region(options);
  const std::string before = test::read_file(options.output);

  expect_usage_error(options, "already exists; pass --overwrite");
  auto other = options;
  other.overwrite = true;
  other.bbox = osm::GeoBox{20.0, 10.0, 20.01, 10.01};
  expect_usage_error(other, "does not overlap the data");
  other.bbox = osm::GeoBox{0.0, 40.0, 30.0, 55.0};
  expect_usage_error(other, "at most 1000 km");
  other.bbox = osm::GeoBox{11.0, 50.0, 10.0, 51.0};
  expect_usage_error(other, "lon0 < lon1");
  other.bbox = kBox;
  other.max_distance_m = 1000;
  expect_usage_error(other, "max_distance_m = 1000");
  other.max_distance_m = 100;
  other.shard_index = 3;
  other.shard_count = 2;
  expect_usage_error(other, "shard = 3/2");
  other.shard_index = 0;
  other.shard_count = 1;
  other.output = dir / "no" / "such" / "dir" / "r.gpkg";
  expect_usage_error(other, "does not exist");

  // A corrupt input with --overwrite: an error, and the previous cache is untouched.
  std::ofstream(dir / "bad.osm.pbf", std::ios::binary) << std::string(300, '\x07');
  auto corrupt = options;
  corrupt.overwrite = true;
  corrupt.input = dir / "bad.osm.pbf";
  EXPECT_THROW(preprocess_region(corrupt), osm::OsmInputError);
  EXPECT_EQ(test::read_file(options.output), before);
  EXPECT_FALSE(std::filesystem::exists(dir / "no"));
}

TEST(Preprocess, ReadersKeepReadingWhileACacheIsRebuilt) {
  test::ScratchDir dir;
  auto options = known_options(dir);
  options.max_distance_m = 50;
  preprocess_region(options);

  raster::CacheReader reader(options.output, /*lru_tiles=*/1);
  const auto first = *reader.distance_tile(0, 0);
  options.overwrite = true;
  options.max_distance_m = 100;
  std::atomic<bool> done{false};
  std::jthread rebuild([&] {
    preprocess_region(options);
    done = true;
  });
  int reads = 0;
  while (!done || reads < 10) {
    // Alternate tiles so every read goes to the file, not the LRU.
    EXPECT_EQ(*reader.distance_tile(0, 0), first);
    (void)reader.distance_tile(1, 0);
    ++reads;
  }
  rebuild.join();
  EXPECT_EQ(reader.metadata().max_distance_m, 50) << "the open reader keeps the cache it opened";
  raster::CacheReader fresh(options.output);
  EXPECT_EQ(fresh.metadata().max_distance_m, 100);
}

}  // namespace
}  // namespace seqloc::pipeline
