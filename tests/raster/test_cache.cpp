// The region cache: what is written reads back, windows stitch seamlessly across tiles, and
// interrupted builds, shards and foreign files behave as documented.

#include <fstream>
#include <random>

#include <sqlite3.h>
#include <gtest/gtest.h>

#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/crop_window.hpp"
#include "seqloc/raster/png_codec.hpp"
#include "seqloc/raster/tile_renderer.hpp"
#include "support/test_support.hpp"

namespace seqloc::raster {
namespace {

// A 3 x 3 tile region around the origin: x in [-256, 512), y in [-256, 512).
const RegionGrid kGrid{-1, -1, 2, 2};

RegionFeatures random_features(unsigned seed) {
  std::mt19937 rng(seed);
  const Pixel o = kGrid.origin();
  // Coordinates reach 300 px beyond the region so that the halo matters.
  std::uniform_int_distribution<std::int64_t> u(o.u - 300, o.u + kGrid.width_px() + 300);
  std::uniform_int_distribution<std::int64_t> v(o.v - 300, o.v + kGrid.height_px() + 300);
  std::uniform_int_distribution<int> step(-60, 60);
  RegionFeatures f;
  auto group = [](const char* name) { return *osm::find_group(name); };
  for (int i = 0; i < 25; ++i) {
    PixelLine line{i % 3 == 0 ? group("path") : osm::kRoad, {}, {}};
    Pixel p{u(rng), v(rng)};
    for (int k = 0; k < 8; ++k) {
      line.points.push_back(p);
      line.box.extend(p);
      p = {p.u + step(rng) * 4, p.v + step(rng) * 4};
    }
    if (line.group == osm::kRoad) {
      RoadLine road{1000 + i, "track", {}};
      for (const auto& q : line.points) road.points.push_back({centre_x(q.u), centre_y(q.v)});
      f.roads.push_back(std::move(road));
    }
    f.lines.push_back(std::move(line));
  }
  for (int i = 0; i < 12; ++i) {
    PixelArea area{i % 2 ? osm::kBuildingArea : group("forest"), {}, {}};
    const Pixel c{u(rng), v(rng)};
    std::vector<Pixel> ring;
    for (int k = 0; k < 6; ++k) {
      const double a = k * M_PI / 3;
      ring.push_back({c.u + static_cast<std::int64_t>(80 * std::cos(a)) + step(rng),
                      c.v + static_cast<std::int64_t>(80 * std::sin(a)) + step(rng)});
      area.box.extend(ring.back());
    }
    area.rings.push_back(ring);
    f.areas.push_back(std::move(area));
  }
  for (int i = 0; i < 200; ++i) f.nodes.push_back({group(i % 2 ? "tree" : "bench"), {u(rng), v(rng)}});
  return f;
}

CacheMetadata test_metadata(int shard_index = 0, int shard_count = 1) {
  CacheMetadata m;
  m.source_file = "synthetic";
  m.source_sha256 = "0123";
  m.centre_lat = 47.5;
  m.centre_lon = 10.5;
  m.bbox = {10.49, 47.49, 10.51, 47.51};
  m.max_distance_m = 100;
  m.grid = kGrid;
  m.shard_index = shard_index;
  m.shard_count = shard_count;
  return m;
}

// Renders and stores the tiles of one shard; stops after `max_tiles` without finishing when set.
void build(const std::filesystem::path& path, const TileRenderer& renderer, const RegionFeatures& features,
           const CacheMetadata& metadata, int max_tiles = -1) {
  CacheWriter writer(path, metadata);
  writer.write_roads(features.roads);
  RenderScratch scratch;
  TileEncoder encoder;
  std::vector<std::uint8_t> rgb;
  std::vector<std::uint16_t> cm;
  int written = 0;
  for (std::int64_t row = 0; row < kGrid.tiles_high(); ++row) {
    for (std::int64_t col = 0; col < kGrid.tiles_wide(); ++col) {
      if (!metadata.shard_owns(col, row) || writer.has_tile(col, row)) continue;
      if (max_tiles >= 0 && written == max_tiles) return;  // simulated interruption
      const bool any = renderer.render_classes(col, row, scratch, rgb);
      renderer.render_road_distance(col, row, scratch, cm);
      writer.write_tile(encoder.encode(col, row, rgb, !any, cm));
      ++written;
    }
  }
  writer.finish();
}

// Tiles one class covers are encoded once per colour: each still decodes to its own pixels, a tile
// that differs in one pixel is not taken for a uniform one, and the empty tile keeps its own blob.
TEST(TileEncoder, UniformTilesEncodedOncePerColourDecodeToTheirOwnPixels) {
  const std::size_t n = static_cast<std::size_t>(kTilePx) * kTilePx;
  const std::vector<std::uint16_t> cm(n, 1234);
  auto uniform = [&](std::uint8_t r, std::uint8_t g, std::uint8_t b) {
    std::vector<std::uint8_t> rgb(3 * n);
    for (std::size_t i = 0; i < n; ++i) {
      rgb[3 * i] = r;
      rgb[3 * i + 1] = g;
      rgb[3 * i + 2] = b;
    }
    return rgb;
  };
  const auto forest = uniform(0, 128, 0), water = uniform(0, 0, 200), empty = uniform(0, 0, 0);
  auto almost = forest;
  almost[3 * (n - 1) + 2] = 1;  // the last pixel's blue
  TileEncoder encoder;
  const std::vector<std::pair<const std::vector<std::uint8_t>*, bool>> tiles{
      {&forest, false}, {&water, false}, {&forest, false}, {&almost, false}, {&empty, true}, {&empty, false}};
  for (const auto& [rgb, is_empty] : tiles) {
    const EncodedTile tile = encoder.encode(0, 0, *rgb, is_empty, cm);
    EXPECT_EQ(tile.classes_png, encode_png_rgb8(*rgb, kTilePx, kTilePx));
    EXPECT_EQ(decode_png(tile.classes_png, "tile").pixels8, *rgb);
  }
}

class CacheTest : public ::testing::Test {
 protected:
  RegionFeatures features = random_features(42);
  TileRenderer renderer{features, kGrid, 100.0};
  test::ScratchDir dir;
};

TEST_F(CacheTest, TilesReadBackAsRendered) {
  build(dir / "r.gpkg", renderer, features, test_metadata());
  CacheReader reader(dir / "r.gpkg");
  EXPECT_EQ(reader.grid(), kGrid);
  RenderScratch scratch;
  std::vector<std::uint8_t> rgb;
  std::vector<std::uint16_t> cm;
  int nonzero_tiles = 0;
  for (std::int64_t row = 0; row < 3; ++row) {
    for (std::int64_t col = 0; col < 3; ++col) {
      renderer.render_classes(col, row, scratch, rgb);
      renderer.render_road_distance(col, row, scratch, cm);
      EXPECT_EQ(*reader.classes_tile(col, row), rgb);
      EXPECT_EQ(*reader.distance_tile(col, row), cm);
      nonzero_tiles += std::any_of(rgb.begin(), rgb.end(), [](std::uint8_t b) { return b != 0; });
    }
  }
  EXPECT_GT(nonzero_tiles, 5) << "the fixture must actually draw something";
  const auto roads = reader.roads();
  ASSERT_EQ(roads.size(), features.roads.size());
  EXPECT_EQ(roads[3].osm_id, features.roads[3].osm_id);
  EXPECT_EQ(roads[3].points.size(), features.roads[3].points.size());
  EXPECT_DOUBLE_EQ(roads[3].points[2].x_m, features.roads[3].points[2].x_m);
}

TEST_F(CacheTest, WindowAcrossFourTilesEqualsOneRaster) {
  build(dir / "r.gpkg", renderer, features, test_metadata());
  CacheReader reader(dir / "r.gpkg", 4);
  // Region pixels [400, 1100) x [300, 900): spans the corner where four tiles meet.
  const std::int64_t u0 = 400, v0 = 300;
  const int w = 700, h = 600;
  const Pixel o = kGrid.origin();
  std::vector<std::uint8_t> stitched_rgb, direct_rgb;
  reader.read_classes(u0, v0, w, h, stitched_rgb);
  RenderScratch scratch;
  renderer.render_classes_window(Window{o.u + u0, o.v + v0, w, h}, scratch, direct_rgb);
  EXPECT_EQ(stitched_rgb, direct_rgb);

  // One distance transform over the window grown by the clamp, computed in one piece.
  const int halo = renderer.halo_px();
  std::vector<std::uint8_t> mask;
  renderer.render_road_mask(Window{o.u + u0 - halo, o.v + v0 - halo, w + 2 * halo, h + 2 * halo}, mask);
  std::vector<std::uint32_t> squared;
  DistanceScratch ds;
  squared_distance(mask, w + 2 * halo, h + 2 * halo, halo, halo, w, h, ds, squared);
  std::vector<std::uint16_t> direct_cm(squared.size()), stitched_cm;
  for (std::size_t i = 0; i < squared.size(); ++i) direct_cm[i] = quantize_distance_cm(squared[i], kCellM, 10000);
  reader.read_road_distance(u0, v0, w, h, stitched_cm);
  EXPECT_EQ(stitched_cm, direct_cm);
  EXPECT_NE(std::count(direct_cm.begin(), direct_cm.end(), 10000), static_cast<long>(direct_cm.size()));
  EXPECT_GT(reader.lru_stats().misses, 0u);
}

TEST_F(CacheTest, LruServesRepeatedReads) {
  build(dir / "r.gpkg", renderer, features, test_metadata());
  CacheReader reader(dir / "r.gpkg", 2);
  const auto a = reader.classes_tile(1, 1);
  const auto b = reader.classes_tile(1, 1);
  EXPECT_EQ(a.get(), b.get());
  EXPECT_EQ(reader.lru_stats().hits, 1u);
  (void)reader.classes_tile(0, 0);
  (void)reader.classes_tile(0, 1);  // evicts (1, 1)
  (void)reader.classes_tile(1, 1);
  EXPECT_EQ(reader.lru_stats().misses, 4u);
}

TEST_F(CacheTest, OutsideTheRegionIsAnErrorNamingTheTile) {
  build(dir / "r.gpkg", renderer, features, test_metadata());
  CacheReader reader(dir / "r.gpkg");
  try {
    (void)reader.classes_tile(5, 0);
    FAIL();
  } catch (const CacheRangeError& e) {
    EXPECT_NE(std::string(e.what()).find("tile (5, 0)"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("r.gpkg"), std::string::npos) << e.what();
  }
  std::vector<std::uint8_t> rgb;
  try {
    reader.read_classes(-10, 100, 20, 20, rgb);
    FAIL();
  } catch (const CacheRangeError& e) {
    EXPECT_NE(std::string(e.what()).find("tile (-1, 0)"), std::string::npos) << e.what();
  }
  std::vector<std::uint16_t> cm;
  reader.read_road_distance(-10, -10, 20, 20, cm, /*fill_outside=*/true);
  EXPECT_EQ(cm[0], 10000) << "outside the region: the clamp";
  reader.read_classes(1530, 1530, 20, 20, rgb, true);
  EXPECT_EQ(rgb.back(), 0) << "outside the region: background";
}

// A crop of an odd side is centred on the cell holding the point, of an even side on the nearest
// cell corner: counted here from the grid's edges, independently of the region-pixel arithmetic.
TEST_F(CacheTest, CropWindowsCentreOnTheCellOrCornerOfThePoint) {
  build(dir / "r.gpkg", renderer, features, test_metadata());
  const CacheReader reader(dir / "r.gpkg");
  const auto& grid = reader.grid();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> x(grid.min_x(), grid.max_x()), y(grid.min_y(), grid.max_y());
  for (int k = 0; k < 200; ++k) {
    const double px = x(rng), py = y(rng);
    for (const double size_m : {0.5, 10.0, 10.5, 64.0, 333.5}) {
      const CropWindow w = locate_crop_xy(reader, px, py, size_m);
      const int n = static_cast<int>(std::lround(size_m / kCellM));
      ASSERT_EQ(w.size, n);
      const double west = grid.min_x() + static_cast<double>(w.u0) * kCellM;
      const double north = grid.max_y() - static_cast<double>(w.v0) * kCellM;
      const double cx = west + n * kCellM / 2, cy = north - n * kCellM / 2;
      if (n % 2) {
        EXPECT_DOUBLE_EQ(cx, grid.min_x() + (std::floor((px - grid.min_x()) / kCellM) + 0.5) * kCellM) << px;
        EXPECT_DOUBLE_EQ(cy, grid.max_y() - (std::floor((grid.max_y() - py) / kCellM) + 0.5) * kCellM) << py;
      } else {
        EXPECT_DOUBLE_EQ(cx, grid.min_x() + std::round((px - grid.min_x()) / kCellM) * kCellM) << px;
        EXPECT_DOUBLE_EQ(cy, grid.max_y() - std::round((grid.max_y() - py) / kCellM) * kCellM) << py;
      }
    }
  }
  // By lat/lon: the same window as by the point's region coordinates.
  const auto& projection = reader.metadata().projection();
  const osm::GridPoint p = projection.forward({47.5005, 10.5003});
  const CropWindow by_geo = locate_crop(reader, 47.5005, 10.5003, 64.0);
  const CropWindow by_xy = locate_crop_xy(reader, p.x_m, p.y_m, 64.0);
  EXPECT_EQ(by_geo.u0, by_xy.u0);
  EXPECT_EQ(by_geo.v0, by_xy.v0);
  // What cannot be placed, and why.
  const auto kind_of = [](auto&& locate) {
    try {
      (void)locate();
    } catch (const CropError& e) {
      return e.kind();
    }
    ADD_FAILURE() << "no CropError";
    return CropError::Kind::bad_argument;
  };
  using Kind = CropError::Kind;
  EXPECT_EQ(kind_of([&] { return locate_crop_xy(reader, grid.max_x() + 1, 0, 64); }), Kind::outside);
  EXPECT_EQ(kind_of([&] { return locate_crop_xy(reader, 0, grid.min_y() - 0.01, 64); }), Kind::outside);
  EXPECT_EQ(kind_of([&] { return locate_crop(reader, 0.0, 0.0, 64); }), Kind::outside);
  EXPECT_EQ(kind_of([&] { return locate_crop_xy(reader, 0, 0, 0.2); }), Kind::bad_argument);
  EXPECT_EQ(kind_of([&] { return locate_crop_xy(reader, 0, 0, 2000); }), Kind::bad_argument);  // above 1,024 m
  EXPECT_EQ(kind_of([&] { return locate_crop_xy(reader, 0, 0, 200, 100); }), Kind::bad_argument);
  EXPECT_EQ(kind_of([&] { return locate_crop_xy(reader, std::nan(""), 0, 64); }), Kind::bad_argument);
  EXPECT_EQ(kind_of([&] { return locate_crop(reader, 91.0, 10.5, 64); }), Kind::bad_argument);
}

TEST_F(CacheTest, ForeignAndOtherVersionFilesAreRefused) {
  build(dir / "r.gpkg", renderer, features, test_metadata());
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir / "r.gpkg").c_str(), &db), SQLITE_OK);
  // Version 1 caches hold other node codes and line cells: they must be rebuilt, not read.
  for (const char* version : {"1", "99"}) {
    const std::string sql = std::string("UPDATE seqloc_metadata SET value = '") + version + "' WHERE key = 'format_version'";
    sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr);
    try {
      CacheReader reader(dir / "r.gpkg");
      FAIL();
    } catch (const CacheFormatError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("format version ") + version + ","), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("reads version 3"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("rebuild the cache with `seqloc preprocess`"), std::string::npos) << e.what();
    }
  }
  sqlite3_close(db);
  std::ofstream(dir / "text.gpkg") << "not a database, but long enough to look like one to nobody";
  EXPECT_THROW(CacheReader(dir / "text.gpkg"), CacheError);
  EXPECT_THROW(CacheReader(dir / "missing.gpkg"), CacheIoError);
}

TEST_F(CacheTest, InterruptedBuildResumesAndMatchesAFullBuild) {
  build(dir / "full.gpkg", renderer, features, test_metadata());
  build(dir / "r.gpkg", renderer, features, test_metadata(), /*max_tiles=*/4);
  EXPECT_FALSE(std::filesystem::exists(dir / "r.gpkg")) << "nothing appears under the final name";
  ASSERT_TRUE(std::filesystem::exists(dir / "r.gpkg.partial"));
  EXPECT_THROW(CacheReader(dir / "r.gpkg.partial"), CacheFormatError) << "an unfinished cache is not read";
  {
    CacheWriter writer(dir / "r.gpkg", test_metadata());
    EXPECT_TRUE(writer.resumed());
    EXPECT_EQ(writer.tiles_stored(), 4);
  }
  build(dir / "r.gpkg", renderer, features, test_metadata());
  CacheReader full(dir / "full.gpkg"), resumed(dir / "r.gpkg");
  for (std::int64_t row = 0; row < 3; ++row) {
    for (std::int64_t col = 0; col < 3; ++col) {
      EXPECT_EQ(full.tile_blob(Layer::classes, col, row), resumed.tile_blob(Layer::classes, col, row));
      EXPECT_EQ(full.tile_blob(Layer::road_distance, col, row), resumed.tile_blob(Layer::road_distance, col, row));
    }
  }
  EXPECT_EQ(resumed.roads().size(), features.roads.size()) << "roads are not written twice";
  // A partial file of another build is not resumed.
  build(dir / "s.gpkg", renderer, features, test_metadata(), 2);
  auto other = test_metadata();
  other.max_distance_m = 50;
  CacheWriter writer(dir / "s.gpkg", other);
  EXPECT_FALSE(writer.resumed());
  EXPECT_EQ(writer.tiles_stored(), 0);
}

TEST_F(CacheTest, MergedShardsEqualASingleRunTileForTile) {
  build(dir / "full.gpkg", renderer, features, test_metadata());
  std::vector<std::filesystem::path> shards;
  for (int i = 0; i < 4; ++i) {
    shards.push_back(dir / ("shard" + std::to_string(i) + ".gpkg"));
    build(shards.back(), renderer, features, test_metadata(i, 4));
    EXPECT_THROW(CacheReader{shards.back()}, CacheFormatError) << "a shard alone is not a cache";
  }
  EXPECT_THROW(merge_shards({shards[0], shards[1], shards[2]}, dir / "m.gpkg"), CacheError);
  EXPECT_THROW(merge_shards({shards[0], shards[0], shards[2], shards[3]}, dir / "m.gpkg"), CacheError);
  merge_shards(shards, dir / "merged.gpkg");
  CacheReader full(dir / "full.gpkg"), merged(dir / "merged.gpkg");
  for (std::int64_t row = 0; row < 3; ++row) {
    for (std::int64_t col = 0; col < 3; ++col) {
      EXPECT_EQ(full.tile_blob(Layer::classes, col, row), merged.tile_blob(Layer::classes, col, row));
      EXPECT_EQ(full.tile_blob(Layer::road_distance, col, row), merged.tile_blob(Layer::road_distance, col, row));
    }
  }
  EXPECT_EQ(merged.roads().size(), features.roads.size());
  // Shards of another build do not mix.
  auto other = test_metadata(1, 4);
  other.source_sha256 = "4567";
  build(dir / "foreign.gpkg", renderer, features, other);
  EXPECT_THROW(merge_shards({shards[0], dir / "foreign.gpkg", shards[2], shards[3]}, dir / "x.gpkg"), CacheError);
}

}  // namespace
}  // namespace seqloc::raster
