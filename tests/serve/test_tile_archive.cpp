// PMTiles and MBTiles archives of a region's tiles: the tile ids against the Hilbert curve's
// defining properties, the directories read back by a decoder written here from the
// specification, every tile of a real extract's archives against what the server answers, and the
// MBTiles pixels as GDAL's own driver reads them.
#include <gtest/gtest.h>

#include <zlib.h>

#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <set>

#include <gdal.h>
#include <sqlite3.h>
#include <nlohmann/json.hpp>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/serve/service.hpp"
#include "seqloc/serve/tile_archive.hpp"
#include "seqloc/serve/web_mercator.hpp"
#include "serve/monaco_cache.hpp"
#include "support/test_support.hpp"

namespace seqloc::serve {
namespace {

// ---------------------------------------------------------------------------------------------
// Tile ids

// Every tile of zooms 0 .. 7 has an id of its own, the ids of zoom z fill [(4^z - 1) / 3, that +
// 4^z) exactly, and consecutive ids are side by side (a Hilbert curve is continuous).
TEST(PmtilesTileId, EachZoomIsAContinuousCurveOverItsRange) {
  EXPECT_EQ(pmtiles_tile_id(0, 0, 0), 0u);
  EXPECT_EQ(pmtiles_tile_id(1, 0, 0), 1u);
  EXPECT_EQ(pmtiles_tile_id(1, 0, 1), 2u);
  EXPECT_EQ(pmtiles_tile_id(1, 1, 1), 3u);
  EXPECT_EQ(pmtiles_tile_id(1, 1, 0), 4u);
  for (int z = 0; z <= 7; ++z) {
    const std::uint64_t n = std::uint64_t{1} << z, base = ((std::uint64_t{1} << (2 * z)) - 1) / 3;
    std::map<std::uint64_t, std::pair<std::uint64_t, std::uint64_t>> at;
    for (std::uint64_t x = 0; x < n; ++x)
      for (std::uint64_t y = 0; y < n; ++y) at[pmtiles_tile_id(z, x, y)] = {x, y};
    ASSERT_EQ(at.size(), n * n) << z;
    EXPECT_EQ(at.begin()->first, base) << z;
    EXPECT_EQ(at.rbegin()->first, base + n * n - 1) << z;
    for (auto it = std::next(at.begin()); it != at.end(); ++it) {
      const auto [x0, y0] = std::prev(it)->second;
      const auto [x1, y1] = it->second;
      const auto step = (x0 > x1 ? x0 - x1 : x1 - x0) + (y0 > y1 ? y0 - y1 : y1 - y0);
      ASSERT_EQ(step, 1u) << "zoom " << z << " id " << it->first;
    }
  }
  EXPECT_THROW((void)pmtiles_tile_id(27, 0, 0), UsageError);
  EXPECT_THROW((void)pmtiles_tile_id(3, 8, 0), UsageError);
}

// ---------------------------------------------------------------------------------------------
// A reader written from the specification

std::uint64_t varint(const std::string& s, std::size_t& at) {
  std::uint64_t v = 0;
  for (int shift = 0;; shift += 7) {
    const auto b = static_cast<unsigned char>(s.at(at++));
    v |= static_cast<std::uint64_t>(b & 0x7F) << shift;
    if (b < 0x80) return v;
  }
}

std::vector<PmtilesEntry> parse_directory(const std::string& s) {
  std::size_t at = 0;
  std::vector<PmtilesEntry> e(varint(s, at));
  std::uint64_t id = 0;
  for (auto& x : e) x.tile_id = id += varint(s, at);
  for (auto& x : e) x.run_length = static_cast<std::uint32_t>(varint(s, at));
  for (auto& x : e) x.length = static_cast<std::uint32_t>(varint(s, at));
  for (std::size_t i = 0; i < e.size(); ++i) {
    const std::uint64_t v = varint(s, at);
    e[i].offset = v == 0 && i > 0 ? e[i - 1].offset + e[i - 1].length : v - 1;
  }
  EXPECT_EQ(at, s.size());
  return e;
}

std::string gunzip(const std::string& in) {
  z_stream z{};
  EXPECT_EQ(inflateInit2(&z, 15 + 16), Z_OK);
  std::string out;
  char buffer[1 << 15];
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  z.avail_in = static_cast<uInt>(in.size());
  int r = Z_OK;
  while (r != Z_STREAM_END) {
    z.next_out = reinterpret_cast<Bytef*>(buffer);
    z.avail_out = sizeof buffer;
    r = inflate(&z, Z_NO_FLUSH);
    EXPECT_TRUE(r == Z_OK || r == Z_STREAM_END) << r;
    if (r != Z_OK && r != Z_STREAM_END) break;
    out.append(buffer, sizeof buffer - z.avail_out);
  }
  inflateEnd(&z);
  return out;
}

struct Archive {
  std::string bytes;
  std::uint64_t u64(std::size_t at) const {
    std::uint64_t v = 0;
    for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(bytes[at + static_cast<std::size_t>(i)]);
    return v;
  }
  std::int32_t i32(std::size_t at) const {
    std::uint32_t v = 0;
    for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(bytes[at + static_cast<std::size_t>(i)]);
    return static_cast<std::int32_t>(v);
  }
  std::string section(std::size_t header_at) const { return bytes.substr(u64(header_at), u64(header_at + 8)); }
  // Every addressed tile id with its contents, through the root and any leaves.
  std::map<std::uint64_t, std::string> tiles() const {
    std::map<std::uint64_t, std::string> out;
    const std::string leaves = section(40), data = section(56);
    std::vector<PmtilesEntry> pending = parse_directory(gunzip(section(8)));
    for (std::size_t i = 0; i < pending.size(); ++i) {
      const PmtilesEntry e = pending[i];
      if (e.run_length == 0) {
        const auto leaf = parse_directory(gunzip(leaves.substr(e.offset, e.length)));
        pending.insert(pending.end(), leaf.begin(), leaf.end());
        continue;
      }
      for (std::uint32_t r = 0; r < e.run_length; ++r) out[e.tile_id + r] = data.substr(e.offset, e.length);
    }
    return out;
  }
};

TEST(PmtilesDirectory, SerializedAsTheSpecificationSays) {
  const std::vector<PmtilesEntry> entries{{5, 0, 100, 1}, {6, 100, 50, 3}, {20, 0, 100, 1}, {21, 150, 7, 1}};
  const std::string s = serialize_pmtiles_directory(entries);
  // The count, ids 5 +1 +14 +1, runs, lengths, then offsets: 0 + 1, contiguous, 0 + 1 (back to the
  // first content), contiguous? no: 150 != 0 + 100, so 150 + 1.
  const std::string expected{4, 5, 1, 14, 1, 1, 3, 1, 1, 100, 50, 100, 7, 1, 0, 1, static_cast<char>(151), 1};
  EXPECT_EQ(s, expected);
  const auto back = parse_directory(s);
  ASSERT_EQ(back.size(), entries.size());
  for (std::size_t i = 0; i < back.size(); ++i) {
    EXPECT_EQ(back[i].tile_id, entries[i].tile_id);
    EXPECT_EQ(back[i].offset, entries[i].offset);
    EXPECT_EQ(back[i].length, entries[i].length);
    EXPECT_EQ(back[i].run_length, entries[i].run_length);
  }
}

// ---------------------------------------------------------------------------------------------
// Archives of a real extract

using test_data::monaco_cache;

// What the server answers for a tile (empty for 404).
std::string served(Service& service, MapLayer layer, int z, std::int64_t x, std::int64_t y, const std::string& style) {
  Request r;
  r.path = "/regions/monaco/xyz/" + std::string(layer_name(layer)) + "/" + std::to_string(z) + "/" + std::to_string(x) +
           "/" + std::to_string(y) + ".png";
  r.query.emplace("style", style);
  const Response response = service.handle(r);
  if (response.status == 404) return {};
  EXPECT_EQ(response.status, 200) << r.path;
  return *response.body;
}

// The (z, x, y) of each tile the server has at zoom z (those under the region's box that it
// answers), by asking it.
std::map<std::uint64_t, std::array<std::int64_t, 3>> served_tiles(Service& service, const osm::GeoBox& b, int z,
                                                                  MapLayer layer, const std::string& style,
                                                                  std::map<std::uint64_t, std::string>& bytes) {
  const double n = std::ldexp(1.0, z);
  const auto x0 = static_cast<std::int64_t>(std::floor((b.min_lon + 180) / 360 * n)),
             x1 = static_cast<std::int64_t>(std::floor((b.max_lon + 180) / 360 * n));
  auto row = [n](double lat) {
    return static_cast<std::int64_t>(std::floor((1 - std::asinh(std::tan(lat * M_PI / 180)) / M_PI) / 2 * n));
  };
  std::map<std::uint64_t, std::array<std::int64_t, 3>> out;
  // One tile of margin each way: the archive must hold every tile the server answers, and no other.
  for (std::int64_t y = row(b.max_lat) - 1; y <= row(b.min_lat) + 1; ++y)
    for (std::int64_t x = x0 - 1; x <= x1 + 1; ++x) {
      const std::string png = served(service, layer, z, x, y, style);
      if (png.empty()) continue;
      const auto id = pmtiles_tile_id(z, static_cast<std::uint64_t>(x), static_cast<std::uint64_t>(y));
      out[id] = {z, x, y};
      bytes[id] = png;
    }
  return out;
}

class TileArchiveTest : public ::testing::Test {
 protected:
  void SetUp() override {
    service_ = std::make_unique<Service>(std::vector<std::filesystem::path>{monaco_cache()}, ServiceOptions{});
    cache_ = std::make_unique<raster::CacheReader>(monaco_cache());
  }
  // The region's two lowest zooms (a few dozen tiles: each is warped twice, by the export and by
  // the server it is compared with).
  WebZooms two_zooms() const {
    WebZooms z = web_zooms(cache_->metadata());
    z.max_zoom = z.min_zoom + 1;
    return z;
  }
  std::unique_ptr<Service> service_;
  std::unique_ptr<raster::CacheReader> cache_;
  test::ScratchDir dir_;
};

TEST_F(TileArchiveTest, PmtilesHoldsEveryTileTheServerAnswersAndNothingElse) {
  const WebZooms zooms = two_zooms();
  for (const auto& [layer, style] :
       {std::pair{MapLayer::classes, std::string("color")}, std::pair{MapLayer::road_distance, std::string("data")}}) {
    ArchiveOptions o;
    o.layer = layer;
    o.styled = style == "color";
    o.threads = 3;
    o.min_zoom = zooms.min_zoom;
    o.max_zoom = zooms.max_zoom;
    const auto path = dir_ / (std::string(layer_name(layer)) + ".pmtiles");
    const ArchiveSummary s = export_tile_archive(*cache_, o, ArchiveFormat::pmtiles, path);
    EXPECT_FALSE(std::filesystem::exists(path.string() + ".partial"));
    Archive a{test::read_file(path)};
    ASSERT_EQ(a.bytes.substr(0, 7), "PMTiles");
    EXPECT_EQ(a.bytes[7], 3);
    EXPECT_LE(a.u64(8) + a.u64(16), 16384u);  // header and root in the first 16 KB
    EXPECT_EQ(a.bytes[99], 2);                // PNG
    EXPECT_EQ(a.bytes[100], zooms.min_zoom);
    EXPECT_EQ(a.bytes[101], zooms.max_zoom);
    const osm::GeoBox b = region_geo_bounds(cache_->metadata());
    EXPECT_NEAR(a.i32(102) / 1e7, b.min_lon, 1e-7);
    EXPECT_NEAR(a.i32(114) / 1e7, b.max_lat, 1e-7);
    const auto metadata = nlohmann::json::parse(gunzip(a.section(24)));
    EXPECT_EQ(metadata.at("attribution"), "Map data (c) OpenStreetMap contributors, ODbL 1.0");
    EXPECT_EQ(metadata.at("seqloc_layer"), layer_name(layer));
    std::map<std::uint64_t, std::string> expected;
    for (int z = zooms.min_zoom; z <= zooms.max_zoom; ++z) (void)served_tiles(*service_, b, z, layer, style, expected);
    const auto got = a.tiles();
    ASSERT_EQ(got.size(), expected.size()) << layer_name(layer);
    for (const auto& [id, png] : expected) {
      ASSERT_TRUE(got.count(id)) << "tile id " << id;
      EXPECT_EQ(got.at(id), png) << "tile id " << id;
    }
    EXPECT_EQ(a.u64(72), expected.size());  // addressed tiles
    EXPECT_EQ(s.tiles, static_cast<long long>(expected.size()));
    std::set<std::string> distinct;
    for (const auto& [id, png] : expected) distinct.insert(png);
    EXPECT_LE(s.unique_tiles, static_cast<long long>(expected.size()));
    EXPECT_GE(s.unique_tiles, static_cast<long long>(distinct.size()));
  }
}

TEST_F(TileArchiveTest, LeafDirectoriesWhenTheRootWouldPassItsBudget) {
  // A region this size fits in a root of 16 KB; with a budget of 300 bytes and leaves of 4
  // entries the writer must make leaves (and double them until their root fits), and every tile
  // is still found through them.
  ArchiveOptions o;
  o.layer = MapLayer::road_prior;
  o.styled = false;
  o.pmtiles_root_bytes = 300;
  o.pmtiles_leaf_entries = 4;
  const WebZooms zooms = two_zooms();
  o.min_zoom = zooms.min_zoom;
  o.max_zoom = zooms.max_zoom;
  const auto path = dir_ / "prior.pmtiles";
  const ArchiveSummary s = export_tile_archive(*cache_, o, ArchiveFormat::pmtiles, path);
  Archive a{test::read_file(path)};
  EXPECT_GT(s.leaf_directories, 1);
  EXPECT_GT(a.u64(48), 0u);          // the leaves' section
  EXPECT_LE(a.u64(16) + 127, 300u);  // the root within the budget
  std::map<std::uint64_t, std::string> expected;
  for (int z = zooms.min_zoom; z <= zooms.max_zoom; ++z) {
    (void)served_tiles(*service_, region_geo_bounds(cache_->metadata()), z, o.layer, "data", expected);
  }
  const auto got = a.tiles();
  ASSERT_EQ(got.size(), expected.size());
  for (const auto& [id, png] : expected) EXPECT_EQ(got.at(id), png) << id;
}

TEST_F(TileArchiveTest, MbtilesRowsAndGdalsPixelsAreTheServersTiles) {
  const WebZooms zooms = two_zooms();
  ArchiveOptions o;
  o.layer = MapLayer::classes;
  o.threads = 2;
  o.min_zoom = zooms.min_zoom;
  o.max_zoom = zooms.max_zoom;
  const auto path = dir_ / "classes.mbtiles";
  (void)export_tile_archive(*cache_, o, ArchiveFormat::mbtiles, path);
  const osm::GeoBox b = region_geo_bounds(cache_->metadata());
  std::map<std::uint64_t, std::string> expected;
  std::map<std::uint64_t, std::array<std::int64_t, 3>> where;
  for (int z = zooms.min_zoom; z <= zooms.max_zoom; ++z) {
    const auto at = served_tiles(*service_, b, z, o.layer, "color", expected);
    where.insert(at.begin(), at.end());
  }
  // The rows, TMS-numbered.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* q = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT zoom_level, tile_column, tile_row, tile_data FROM tiles", -1, &q, nullptr),
            SQLITE_OK);
  std::size_t rows = 0;
  while (sqlite3_step(q) == SQLITE_ROW) {
    const int z = sqlite3_column_int(q, 0);
    const std::int64_t x = sqlite3_column_int64(q, 1), y = (std::int64_t{1} << z) - 1 - sqlite3_column_int64(q, 2);
    const auto id = pmtiles_tile_id(z, static_cast<std::uint64_t>(x), static_cast<std::uint64_t>(y));
    const std::string data(static_cast<const char*>(sqlite3_column_blob(q, 3)),
                           static_cast<std::size_t>(sqlite3_column_bytes(q, 3)));
    ASSERT_TRUE(expected.count(id)) << z << "/" << x << "/" << y;
    EXPECT_EQ(data, expected.at(id)) << z << "/" << x << "/" << y;
    ++rows;
  }
  sqlite3_finalize(q);
  std::map<std::string, std::string> metadata;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT name, value FROM metadata", -1, &q, nullptr), SQLITE_OK);
  while (sqlite3_step(q) == SQLITE_ROW) {
    metadata[reinterpret_cast<const char*>(sqlite3_column_text(q, 0))] =
        reinterpret_cast<const char*>(sqlite3_column_text(q, 1));
  }
  sqlite3_finalize(q);
  sqlite3_close(db);
  EXPECT_EQ(rows, expected.size());
  for (const char* name : {"name", "format", "bounds", "center", "minzoom", "maxzoom", "attribution"}) {
    EXPECT_TRUE(metadata.count(name)) << name;
  }
  EXPECT_EQ(metadata["format"], "png");
  EXPECT_EQ(metadata["maxzoom"], std::to_string(zooms.max_zoom));

  // GDAL's MBTiles driver: the mosaic at the highest zoom, pixel for pixel against each served
  // tile of that zoom (decoded by GDAL's PNG driver).
  GDALAllRegister();
  GDALDatasetH ds = GDALOpen(path.c_str(), GA_ReadOnly);
  ASSERT_NE(ds, nullptr) << CPLGetLastErrorMsg();
  ASSERT_EQ(GDALGetRasterCount(ds), 4);
  double gt[6];
  ASSERT_EQ(GDALGetGeoTransform(ds, gt), CE_None);
  int compared = 0;
  for (const auto& [id, zxy] : where) {
    if (zxy[0] != zooms.max_zoom) continue;
    const WebBounds tile = web_tile_bounds(static_cast<int>(zxy[0]), zxy[1], zxy[2]);
    const int px = static_cast<int>(std::lround((tile.west - gt[0]) / gt[1]));
    const int py = static_cast<int>(std::lround((tile.north - gt[3]) / gt[5]));
    ASSERT_NEAR(gt[1] * 256, tile.east - tile.west, 1e-6);
    const std::string vsi = "/vsimem/tile_" + std::to_string(id) + ".png";
    const std::string& png = expected.at(id);
    VSIFCloseL(VSIFileFromMemBuffer(vsi.c_str(), reinterpret_cast<GByte*>(const_cast<char*>(png.data())),
                                    static_cast<vsi_l_offset>(png.size()), FALSE));
    GDALDatasetH tile_ds = GDALOpen(vsi.c_str(), GA_ReadOnly);
    ASSERT_NE(tile_ds, nullptr);
    ASSERT_EQ(GDALGetRasterCount(tile_ds), 4);
    // The mosaic spans the region's bounds (GDAL crops the edge tiles to them): the part of the
    // tile inside it.
    const int x0 = std::max(0, px), y0 = std::max(0, py);
    const int x1 = std::min(GDALGetRasterXSize(ds), px + 256), y1 = std::min(GDALGetRasterYSize(ds), py + 256);
    if (x1 <= x0 || y1 <= y0) {
      GDALClose(tile_ds);
      VSIUnlink(vsi.c_str());
      continue;
    }
    const int w = x1 - x0, h = y1 - y0;
    for (int band = 1; band <= 4; ++band) {
      std::vector<std::uint8_t> mosaic(static_cast<std::size_t>(w * h)), own(static_cast<std::size_t>(w * h));
      ASSERT_EQ(GDALRasterIO(GDALGetRasterBand(ds, band), GF_Read, x0, y0, w, h, mosaic.data(), w, h, GDT_Byte, 0, 0),
                CE_None);
      ASSERT_EQ(GDALRasterIO(GDALGetRasterBand(tile_ds, band), GF_Read, x0 - px, y0 - py, w, h, own.data(), w, h,
                             GDT_Byte, 0, 0),
                CE_None);
      ASSERT_EQ(mosaic, own) << "tile " << zxy[0] << "/" << zxy[1] << "/" << zxy[2] << " band " << band;
    }
    GDALClose(tile_ds);
    VSIUnlink(vsi.c_str());
    ++compared;
  }
  GDALClose(ds);
  EXPECT_GT(compared, 0);
}

TEST_F(TileArchiveTest, AZoomTheRegionDoesNotServeIsRefusedAndNothingIsWritten) {
  const WebZooms zooms = web_zooms(cache_->metadata());
  ArchiveOptions o;
  o.max_zoom = zooms.max_zoom + 1;
  const auto path = dir_ / "too_deep.pmtiles";
  EXPECT_THROW((void)export_tile_archive(*cache_, o, ArchiveFormat::pmtiles, path), UsageError);
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".partial"));
}

}  // namespace
}  // namespace seqloc::serve
