// Preprocessing end to end on synthetic maps whose answer is known from their geometry, and the
// refusal of bad requests before any output is touched.

#include <algorithm>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/osm/reader.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc::ingest {
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
ingest::PreprocessOptions known_options(const test::ScratchDir& dir) {
  known_map().write(dir / "map.osm.pbf", 50);
  ingest::PreprocessOptions options;
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
  ingest::preprocess_region(options);
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
  EXPECT_EQ(metres(0, 80), 10.0);        // 20 cells north
  EXPECT_EQ(metres(0, 106), 3.0);        // 6 cells south
  EXPECT_EQ(metres(210, 100), 5.0);      // 10 cells past the east end
  EXPECT_EQ(metres(210, 94), 5.83);      // sqrt(10^2 + 6^2) / 2 = 5.8310 m
  EXPECT_EQ(metres(-100, -150), 100.0);  // 125 m from the road: the clamp

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

// Pixels a model trained on OrienterNet's tiles must read, each checked by hand from the geometry
// (conventions.md section 2 as corrected on 2026-12-01): node codes in Patterns.nodes order, exact
// ties of lines going toward the left endpoint, a multipolygon relation with members missing from
// the extract, and features beyond the bbox that fall into the grid's edge tiles. kBox spans
// +-301 m east-west and +-334 m north-south, so the grid is cells -1024..1023 both ways (+-512 m).
TEST(Preprocess, OrienterNetGoldenPixels) {
  test::ScratchDir dir;
  osm::SyntheticMap map(kLat0, kLon0);
  map.node(cell(10, -300), {{"amenity", "bicycle_parking"}});
  map.node(cell(12, -300), {{"amenity", "bench"}});
  map.node(cell(14, -300), {{"tourism", "artwork"}});
  map.node(cell(16, -300), {{"amenity", "clock"}});
  // Slope 1/4 drawn left to right and right to left: the line is half-way between two rows at
  // the middle column, and the tie goes to the left endpoint's row.
  map.way({cell(0, -250), cell(4, -249)}, {{"highway", "footway"}});
  map.way({cell(24, -249), cell(20, -250)}, {{"highway", "footway"}});
  // A steep road with ties at its first and third steps: road cells (100,-300), (100,-299),
  // (101,-298), (101,-297), (102,-296).
  map.way({cell(100, -300), cell(102, -296)}, {{"highway", "track"}});
  // A forest relation cut by the extract: its outer square (-400..-200 x -600..-400) is three open
  // ways, one reversed, with an inner square hole; a fourth outer member is missing; and a second
  // outer chain (-150..-50 x -600..-500) lost its closing way.
  const auto a = map.node(cell(-400, -600)), b = map.node(cell(-200, -600)), c = map.node(cell(-200, -400)),
             d = map.node(cell(-400, -400));
  const auto w1 = map.way_through({a, b, c}, {});
  const auto w2 = map.way_through({d, c}, {});  // reversed
  const auto w3 = map.way_through({d, a}, {});
  const auto hole = map.way({cell(-320, -520), cell(-280, -520), cell(-280, -480), cell(-320, -480)}, {}, true);
  const auto broken = map.way({cell(-150, -600), cell(-50, -600), cell(-50, -500), cell(-150, -500)}, {});
  map.relation({{'w', w1, "outer"},
                {'w', 99999, "outer"},
                {'w', w2, "outer"},
                {'w', broken, "outer"},
                {'w', w3, "outer"},
                {'w', hole, "inner"}},
               {{"type", "multipolygon"}, {"natural", "wood"}});
  // Beyond the bbox (east edge +301 m) but in the grid's edge tiles: a tree at x = 479.75 m, and a
  // road at x = 539.75 m, beyond the grid's edge (512 m) but within the 100 m clamp of it.
  map.node(cell(959, 10), {{"natural", "tree"}});
  map.way({cell(1079, -200), cell(1079, 200)}, {{"highway", "service"}});
  map.write(dir / "map.osm.pbf", 400);

  ingest::PreprocessOptions options;
  options.input = dir / "map.osm.pbf";
  options.output = dir / "r.gpkg";
  options.bbox = kBox;
  options.corridor_m = 0;  // the tree beyond the bbox is far from any road
  ingest::preprocess_region(options);
  raster::CacheReader reader(options.output);
  const auto& m = reader.metadata();
  ASSERT_EQ(m.grid.origin().u, -1024);
  ASSERT_EQ(m.grid.origin().v, -1024);
  ASSERT_EQ(m.grid.width_px(), 2048);
  ASSERT_EQ(m.grid.height_px(), 2048);
  std::vector<std::uint8_t> rgb;
  std::vector<std::uint16_t> cm;
  reader.read_classes(0, 0, 2048, 2048, rgb);
  reader.read_road_distance(0, 0, 2048, 2048, cm);
  auto at = [](std::int64_t u, std::int64_t v) { return static_cast<std::size_t>((v + 1024) * 2048 + (u + 1024)); };
  auto areas = [&](std::int64_t u, std::int64_t v) { return int{rgb[at(u, v) * 3]}; };
  auto ways = [&](std::int64_t u, std::int64_t v) { return int{rgb[at(u, v) * 3 + 1]}; };
  auto nodes = [&](std::int64_t u, std::int64_t v) { return int{rgb[at(u, v) * 3 + 2]}; };
  auto metres = [&](std::int64_t u, std::int64_t v) { return cm[at(u, v)] / 100.0; };

  // Node codes, written out: OrienterNet's Patterns.nodes order.
  EXPECT_EQ(nodes(10, -300), 17) << "bicycle_parking";
  EXPECT_EQ(nodes(12, -300), 25) << "bench";
  EXPECT_EQ(nodes(14, -300), 27) << "artwork";
  EXPECT_EQ(nodes(16, -300), 30) << "clock";

  // Ties of the footways (path = 7) in both drawing directions.
  for (std::int64_t u0 : {0, 20}) {
    EXPECT_EQ(ways(u0 + 1, -250), 7);
    EXPECT_EQ(ways(u0 + 2, -250), 7) << "tie at the middle column goes to the left endpoint's row";
    EXPECT_EQ(ways(u0 + 2, -249), 0);
    EXPECT_EQ(ways(u0 + 3, -249), 7);
  }
  // The steep road (road = 8) and its road distances.
  EXPECT_EQ(ways(100, -299), 8);
  EXPECT_EQ(ways(101, -299), 0);
  EXPECT_EQ(ways(101, -297), 8);
  EXPECT_EQ(ways(102, -297), 0);
  EXPECT_EQ(metres(100, -299), 0.0);
  EXPECT_EQ(metres(101, -299), 0.5);
  EXPECT_EQ(metres(102, -297), 0.5);

  // The incomplete forest relation (forest = 6).
  EXPECT_EQ(areas(-300, -450), 6) << "inside the glued outer ring";
  EXPECT_EQ(areas(-210, -590), 6);
  EXPECT_EQ(areas(-300, -500), 0) << "inside the hole";
  EXPECT_EQ(areas(-320, -500), 6) << "the hole's outline is drawn";
  EXPECT_EQ(areas(-401, -500), 0) << "outside";
  EXPECT_EQ(areas(-100, -550), 0) << "inside the chain that does not close";
  EXPECT_EQ(areas(-100, -600), 0) << "an open chain is not drawn at all";

  // Beyond the bbox, inside the grid.
  EXPECT_EQ(nodes(959, 10), 1) << "tree";
  EXPECT_EQ(metres(1023, 0), 28.0) << "56 cells west of the road outside the grid";
  EXPECT_EQ(metres(1023, 500), 100.0) << "152 m from the road's end: the clamp";
}

TEST(Preprocess, DefaultRegionIsTheHeaderBbox) {
  test::ScratchDir dir;
  known_map().write(dir / "map.osm.pbf", 50);
  const auto header = osm::read_osm_header(dir / "map.osm.pbf");
  ASSERT_TRUE(header.box.has_value());
  ingest::PreprocessOptions options;
  options.input = dir / "map.osm.pbf";
  options.output = dir / "r.gpkg";
  const auto report = ingest::preprocess_region(options);
  EXPECT_DOUBLE_EQ(report.bbox.min_lon, header.box->min_lon);
  EXPECT_DOUBLE_EQ(report.bbox.max_lat, header.box->max_lat);
  EXPECT_EQ(report.tiles_written, report.tiles_total);
}

void expect_usage_error(const ingest::PreprocessOptions& options, const std::string& fragment) {
  try {
    ingest::preprocess_region(options);
    FAIL() << "expected an error containing '" << fragment << "'";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(Preprocess, BadRequestsFailBeforeTouchingAnything) {
  test::ScratchDir dir;
  const auto options = known_options(dir);
  ingest::preprocess_region(options);
  const std::string before = test::read_file(options.output);

  expect_usage_error(options, "already exists; pass --overwrite");
  auto other = options;
  other.overwrite = true;
  other.bbox = osm::GeoBox{20.0, 10.0, 20.01, 10.01};
  expect_usage_error(other, "does not overlap the data");  // found after reading: the cache was open
  EXPECT_FALSE(std::filesystem::exists(options.output.string() + ".partial"));
  other.bbox = osm::GeoBox{0.0, 40.0, 30.0, 55.0};
  expect_usage_error(other, "beyond the 0.1 % that keeps the map metric");
  other.bbox = osm::GeoBox{11.0, 50.0, 10.0, 51.0};
  expect_usage_error(other, "lon0 < lon1");
  other.bbox = kBox;
  other.max_distance_m = 1000;
  expect_usage_error(other, "max_distance_m = 1000");
  other.max_distance_m = 100;
  other.corridor_m = 150;
  expect_usage_error(other, "corridor_m = 150: must be in [0, max_distance_m = 100]");
  other.corridor_m = 0;
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
  EXPECT_THROW(ingest::preprocess_region(corrupt), osm::OsmInputError);
  EXPECT_EQ(test::read_file(options.output), before);
  EXPECT_FALSE(std::filesystem::exists(dir / "no"));

  // Cut short after its header: the box is declared, so the cache opens before the data fails;
  // the error leaves no partial cache behind.
  const std::string whole = test::read_file(options.input);
  std::ofstream(dir / "cut.osm.pbf", std::ios::binary) << whole.substr(0, whole.size() * 2 / 3);
  corrupt.input = dir / "cut.osm.pbf";
  EXPECT_THROW(ingest::preprocess_region(corrupt), osm::OsmInputError);
  EXPECT_EQ(test::read_file(options.output), before);
  EXPECT_FALSE(std::filesystem::exists(options.output.string() + ".partial"));
  // A partial file another build left (here one nothing can read) outlives the failed run: a
  // successful one would have replaced it, a failed one must not have cost it.
  const std::string partial = options.output.string() + ".partial";
  std::ofstream(partial, std::ios::binary) << "an interrupted build of another input";
  EXPECT_THROW(ingest::preprocess_region(corrupt), osm::OsmInputError);
  EXPECT_EQ(test::read_file(partial), "an interrupted build of another input");
}

TEST(Preprocess, ReadersKeepReadingWhileACacheIsRebuilt) {
  test::ScratchDir dir;
  auto options = known_options(dir);
  options.max_distance_m = 50;
  ingest::preprocess_region(options);

  raster::CacheReader reader(options.output, /*lru_tiles=*/1);
  const auto first = *reader.distance_tile(0, 0);
  options.overwrite = true;
  options.max_distance_m = 100;
  std::atomic<bool> done{false};
  std::jthread rebuild([&] {
    ingest::preprocess_region(options);
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

// Every tile's stored PNGs, both layers, in (col, row) order; nothing for a tile not stored.
std::vector<std::vector<std::uint8_t>> stored_tiles(const std::filesystem::path& cache) {
  raster::CacheReader reader(cache);
  std::vector<std::vector<std::uint8_t>> tiles;
  for (std::int64_t row = 0; row < reader.grid().tiles_high(); ++row) {
    for (std::int64_t col = 0; col < reader.grid().tiles_wide(); ++col) {
      for (auto layer : {raster::Layer::classes, raster::Layer::road_distance}) {
        tiles.push_back(reader.has_tile(layer, col, row) ? reader.tile_blob(layer, col, row)
                                                         : std::vector<std::uint8_t>{});
      }
    }
  }
  return tiles;
}

// Rendering block by block must not change a pixel: the road, the fence and the forest cross
// tile and block seams (the grid is 4 x 4 tiles; blocks of 1 and 3 tiles cut it everywhere and
// unevenly), and a single block is the whole region's features at once.
TEST(Preprocess, BlocksOfAnySizeGiveTheSameTiles) {
  test::ScratchDir dir;
  auto options = known_options(dir);
  ingest::preprocess_region(options);
  const auto whole = stored_tiles(options.output);
  ASSERT_EQ(whole.size(), 32u);
  options.overwrite = true;
  for (int side : {1, 3}) {
    options.block_tiles = side;
    const auto report = ingest::preprocess_region(options);
    EXPECT_GT(report.spilled_bytes, 0u);
    EXPECT_TRUE(stored_tiles(options.output) == whole) << "blocks of " << side << " tiles";
  }
}

// A corridor cache stores classes for exactly the tiles that have a cell nearer than the corridor
// to a road (judged on the full cache's distances) and reads back everywhere as the full cache
// does, but for the left-out classes: background. Road distances are all stored. The known map's
// one road runs at y = -50.25 m from x = -100.25 to 100.25 m, so at 40 m only the two tiles south
// of y = 0 that it crosses keep their classes.
TEST(Preprocess, CorridorLeavesOutClassesFarFromRoadsAndReadersFillThem) {
  test::ScratchDir dir;
  auto options = known_options(dir);
  options.corridor_m = 0;  // every tile
  ingest::preprocess_region(options);
  raster::CacheReader full(options.output);
  const auto grid = full.grid();

  auto corridor = options;
  corridor.output = dir / "corridor.gpkg";
  corridor.corridor_m = 40;
  const auto report = ingest::preprocess_region(corridor);
  raster::CacheReader reader(corridor.output);
  EXPECT_EQ(reader.metadata().corridor_m, 40);

  int kept = 0;
  std::size_t lost = 0;  // classes the full cache has in the left-out tiles (the forest)
  const std::vector<std::uint8_t> background(512 * 512 * 3, 0);
  for (std::int64_t row = 0; row < grid.tiles_high(); ++row) {
    for (std::int64_t col = 0; col < grid.tiles_wide(); ++col) {
      const auto& cm = *full.distance_tile(col, row);
      const bool near = *std::min_element(cm.begin(), cm.end()) < 4000;
      kept += near ? 1 : 0;
      EXPECT_EQ(reader.has_tile(raster::Layer::classes, col, row), near) << col << "," << row;
      EXPECT_TRUE(reader.has_tile(raster::Layer::road_distance, col, row)) << col << "," << row;
      EXPECT_EQ(*reader.distance_tile(col, row), cm);
      const auto& rgb = *full.classes_tile(col, row);
      EXPECT_EQ(*reader.classes_tile(col, row), near ? rgb : background);
      if (!near) lost += static_cast<std::size_t>(std::count_if(rgb.begin(), rgb.end(), [](auto c) { return c != 0; }));
      // The PNG handed to other tools (serve, exports) is there either way.
      EXPECT_FALSE(reader.tile_blob(raster::Layer::classes, col, row).empty());
    }
  }
  EXPECT_EQ(kept, 2) << "the two tiles the road crosses";
  EXPECT_EQ(report.tiles_written, grid.tile_count());
  EXPECT_EQ(report.tiles_skipped, grid.tile_count() - kept);
  EXPECT_GT(lost, 10000u) << "the forest, 60 m and more from the road";

  // A window across kept and left-out tiles, and one beyond the grid, still refused.
  std::vector<std::uint8_t> window;
  reader.read_classes(200, 900, 1200, 300, window);
  EXPECT_EQ(window.size(), 3u * 360000u);
  EXPECT_THROW(reader.read_classes(-10, 0, 20, 20, window), raster::CacheRangeError);

  // Sharded, it merges into the same cache.
  std::vector<std::filesystem::path> shards;
  for (int i = 0; i < 3; ++i) {
    auto shard = corridor;
    shard.output = dir / ("shard" + std::to_string(i) + ".gpkg");
    shard.shard_index = i;
    shard.shard_count = 3;
    ingest::preprocess_region(shard);
    shards.push_back(shard.output);
  }
  raster::merge_shards(shards, dir / "merged.gpkg");
  EXPECT_TRUE(stored_tiles(dir / "merged.gpkg") == stored_tiles(corridor.output));
}

}  // namespace
}  // namespace seqloc::ingest
