// The tiles an OSM edit can change, against the tiles that do change: the data before and after
// (the change applied by osm::apply_changes) are each preprocessed whole over the same box, the
// two caches compared tile by tile in both layers, and every tile that differs must be in the
// footprint. The edits move a node shared by two roads (the roads themselves not in the change
// file), add a building, delete a track, move a vertex of a multipolygon's outer way (the relation
// not in the change file), and retag a node with a tag no class reads.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>

#include "seqloc/ingest/change_footprint.hpp"
#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/ingest/update.hpp"
#include "seqloc/osm/changes.hpp"
#include "seqloc/osm/reader.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc::ingest::change_footprint_tests {
namespace {

constexpr double kLat0 = 47.5, kLon0 = 10.5;
const osm::GeoBox kBox{kLon0 - 0.012, kLat0 - 0.009, kLon0 + 0.012, kLat0 + 0.009};

struct Fixture {
  osm::SyntheticMap map{kLat0, kLon0};
  std::int64_t crossing = 0, track = 0, forest_vertex = 0, bench = 0;
  std::int64_t track_node_a = 0, track_node_b = 0;
};

Fixture base_map() {
  Fixture f;
  auto& m = f.map;
  const auto west = m.node({-850, 0}), east = m.node({850, 0});
  f.crossing = m.node({40, 10});
  const auto south = m.node({40, -950}), north = m.node({40, 950});
  m.way_through({west, f.crossing, east}, {{"highway", "secondary"}});
  m.way_through({south, f.crossing, north}, {{"highway", "residential"}});
  f.track_node_a = m.node({-700, 700});
  f.track_node_b = m.node({-400, 820});
  f.track = m.way_through({f.track_node_a, f.track_node_b}, {{"highway", "track"}});
  // A forest as a multipolygon of one outer way whose vertices we know.
  const auto a = m.node({300, -700}), b = m.node({700, -700}), c = m.node({700, -400});
  f.forest_vertex = m.node({300, -400});
  const auto outer = m.way_through({a, b, c, f.forest_vertex, a}, {});
  m.relation({{'w', outer, "outer"}}, {{"type", "multipolygon"}, {"landuse", "forest"}});
  f.bench = m.node({-300, -300}, {{"amenity", "bench"}});
  return f;
}

std::string node_xml(const Fixture& f, std::int64_t id, int version, osm::LocalPoint p, const std::string& tags = "") {
  const osm::GeoPoint g = f.map.to_geo(p);
  std::ostringstream s;
  s.precision(10);
  s << "<node id=\"" << id << "\" version=\"" << version << "\" lat=\"" << g.lat_deg << "\" lon=\"" << g.lon_deg
    << "\">" << tags << "</node>\n";
  return s.str();
}

std::string changes(const Fixture& f) {
  std::string x = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<osmChange version=\"0.6\">\n<modify>\n";
  x += node_xml(f, f.crossing, 2, {40, 40});          // the crossing moves 30 m north
  x += node_xml(f, f.forest_vertex, 2, {340, -360});  // the forest's corner moves
  x += node_xml(f, f.bench, 2, {-300, -300}, R"(<tag k="amenity" v="bench"/><tag k="note" v="new paint"/>)");
  x += "</modify>\n<create>\n";
  x += node_xml(f, 900001, 1, {600, 600}) + node_xml(f, 900002, 1, {640, 600}) + node_xml(f, 900003, 1, {640, 630}) +
       node_xml(f, 900004, 1, {600, 630});
  x += R"(<way id="900010" version="1"><nd ref="900001"/><nd ref="900002"/><nd ref="900003"/><nd ref="900004"/>)"
       R"(<nd ref="900001"/><tag k="building" v="yes"/></way>)"
       "\n</create>\n<delete>\n";
  x += "<way id=\"" + std::to_string(f.track) + "\" version=\"2\"/>\n";
  x += "</delete>\n</osmChange>\n";
  return x;
}

using Tiles = std::set<std::pair<std::int64_t, std::int64_t>>;

Tiles differing_tiles(const std::filesystem::path& a, const std::filesystem::path& b) {
  raster::CacheReader ra(a), rb(b);
  Tiles differ;
  const auto& g = ra.grid();
  for (std::int64_t row = 0; row < g.tiles_high(); ++row)
    for (std::int64_t col = 0; col < g.tiles_wide(); ++col)
      for (const auto layer : {raster::Layer::classes, raster::Layer::road_distance}) {
        if (ra.tile_blob(layer, col, row) != rb.tile_blob(layer, col, row)) differ.emplace(col, row);
      }
  return differ;
}

PreprocessOptions options_for(const std::filesystem::path& input, const std::filesystem::path& output) {
  PreprocessOptions o;
  o.input = input;
  o.output = output;
  o.bbox = kBox;
  o.threads = 2;
  return o;
}

TEST(ChangeFootprint, HoldsEveryTileTheEditChanges) {
  test::ScratchDir dir;
  const Fixture f = base_map();
  f.map.write(dir / "old.osm.pbf", 100);
  std::ofstream(dir / "day.osc") << changes(f);
  const auto applied = osm::apply_changes(dir / "old.osm.pbf", dir / "day.osc", dir / "new.osm.pbf");
  EXPECT_EQ(applied.objects.size(), 9u);  // 3 nodes modified, 4 created, a way created, a way deleted
  (void)preprocess_region(options_for(dir / "old.osm.pbf", dir / "old.gpkg"));
  (void)preprocess_region(options_for(dir / "new.osm.pbf", dir / "new.gpkg"));
  const Tiles changed = differing_tiles(dir / "old.gpkg", dir / "new.gpkg");

  raster::CacheReader old_cache(dir / "old.gpkg");
  const ChangeFootprint fp =
      change_footprint(old_cache.metadata(), osm::read_osm(dir / "old.osm.pbf"), osm::read_osm(dir / "new.osm.pbf"));
  const Tiles predicted(fp.tiles.begin(), fp.tiles.end());
  for (const auto& t : changed) EXPECT_TRUE(predicted.contains(t)) << "tile " << t.first << "," << t.second;
  // Both roads through the crossing, the building, the track and the forest differ; the retagged
  // bench renders the same and is no change.
  EXPECT_EQ(fp.features_changed, 2u * 2 + 1 + 1 + 2);
  const auto& g = old_cache.grid();
  const auto total = static_cast<std::size_t>(g.tile_count());
  EXPECT_GE(changed.size(), 4u);
  EXPECT_LT(predicted.size(), total * 2 / 3) << predicted.size() << " of " << total;
  RecordProperty("tiles_changed", static_cast<int>(changed.size()));
  RecordProperty("tiles_predicted", static_cast<int>(predicted.size()));
}

TEST(ChangeFootprint, AnEditNoClassReadsTouchesNoTile) {
  test::ScratchDir dir;
  const Fixture f = base_map();
  f.map.write(dir / "old.osm.pbf", 100);
  std::ofstream(dir / "note.osc") << "<?xml version=\"1.0\"?>\n<osmChange version=\"0.6\"><modify>\n" +
                                         node_xml(f, f.bench, 2, {-300, -300},
                                                  R"(<tag k="amenity" v="bench"/><tag k="note" v="x"/>)") +
                                         "</modify></osmChange>\n";
  (void)osm::apply_changes(dir / "old.osm.pbf", dir / "note.osc", dir / "new.osm.pbf");
  (void)preprocess_region(options_for(dir / "old.osm.pbf", dir / "old.gpkg"));
  raster::CacheReader old_cache(dir / "old.gpkg");
  const ChangeFootprint fp =
      change_footprint(old_cache.metadata(), osm::read_osm(dir / "old.osm.pbf"), osm::read_osm(dir / "new.osm.pbf"));
  EXPECT_EQ(fp.features_changed, 0u);
  EXPECT_TRUE(fp.tiles.empty());
}


// seqloc update against a rebuild: the cache of the old data updated with the change file equals,
// tile for tile in both layers and road for road, the cache preprocessed from the new data.
class Update : public ::testing::TestWithParam<double> {};

TEST_P(Update, EqualsARebuildFromTheNewData) {
  test::ScratchDir dir;
  const Fixture f = base_map();
  f.map.write(dir / "old.osm.pbf", 100);
  std::ofstream(dir / "day.osc") << changes(f);
  PreprocessOptions old_options = options_for(dir / "old.osm.pbf", dir / "old.gpkg");
  old_options.corridor_m = GetParam();
  (void)preprocess_region(old_options);
  const std::string old_bytes = test::read_file(dir / "old.gpkg");

  UpdateOptions u;
  u.cache = dir / "old.gpkg";
  u.base = dir / "old.osm.pbf";
  u.changes = dir / "day.osc";
  u.output = dir / "updated.gpkg";
  u.new_base = dir / "new.osm.pbf";
  const UpdateReport report = update_region(u);
  EXPECT_EQ(test::read_file(dir / "old.gpkg"), old_bytes);  // -o leaves the cache as it was
  PreprocessOptions new_options = options_for(dir / "new.osm.pbf", dir / "rebuilt.gpkg");
  new_options.corridor_m = GetParam();
  (void)preprocess_region(new_options);

  raster::CacheReader updated(dir / "updated.gpkg"), rebuilt(dir / "rebuilt.gpkg");
  const auto& g = rebuilt.grid();
  ASSERT_TRUE(updated.grid() == g);
  for (std::int64_t row = 0; row < g.tiles_high(); ++row)
    for (std::int64_t col = 0; col < g.tiles_wide(); ++col) {
      for (const auto layer : {raster::Layer::classes, raster::Layer::road_distance}) {
        EXPECT_EQ(updated.has_tile(layer, col, row), rebuilt.has_tile(layer, col, row)) << col << "," << row;
        EXPECT_TRUE(updated.tile_blob(layer, col, row) == rebuilt.tile_blob(layer, col, row)) << col << "," << row;
      }
    }
  const auto a = updated.roads(), b = rebuilt.roads();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].osm_id, b[i].osm_id);
    EXPECT_EQ(a[i].highway, b[i].highway);
    ASSERT_EQ(a[i].points.size(), b[i].points.size());
    for (std::size_t k = 0; k < a[i].points.size(); ++k) {
      EXPECT_EQ(a[i].points[k].x_m, b[i].points[k].x_m);
      EXPECT_EQ(a[i].points[k].y_m, b[i].points[k].y_m);
    }
  }
  EXPECT_LT(report.tiles_rendered, report.tiles_total);
  EXPECT_GT(report.tiles_rendered, 0);
  EXPECT_EQ(updated.metadata().changes_applied, "day.osc");
  EXPECT_EQ(updated.metadata().source_sha256, rebuilt.metadata().source_sha256);  // the new base's
  RecordProperty("tiles_rendered", static_cast<int>(report.tiles_rendered));
}

INSTANTIATE_TEST_SUITE_P(Corridor, Update, ::testing::Values(0.0, 60.0));

TEST(UpdateRefusal, AWrongBaseOrABadChangeFileLeavesTheCacheAsItWas) {
  test::ScratchDir dir;
  const Fixture f = base_map();
  f.map.write(dir / "old.osm.pbf", 100);
  (void)preprocess_region(options_for(dir / "old.osm.pbf", dir / "old.gpkg"));
  const std::string before = test::read_file(dir / "old.gpkg");
  UpdateOptions u;
  u.cache = dir / "old.gpkg";  // replaced in place when the update succeeds
  u.base = dir / "old.osm.pbf";
  u.changes = dir / "bad.osc";
  std::ofstream(dir / "bad.osc") << changes(f).substr(0, 200);  // truncated
  EXPECT_THROW((void)update_region(u), osm::OsmInputError);
  std::ofstream(dir / "other.osm") << "<?xml version='1.0'?><osm version=\"0.6\"><node id=\"1\" version=\"1\" "
                                      "lat=\"47.5\" lon=\"10.5\"/></osm>\n";
  u.base = dir / "other.osm";
  std::ofstream(dir / "day.osc") << changes(f);
  u.changes = dir / "day.osc";
  try {
    (void)update_region(u);
    ADD_FAILURE() << "updated from a base the cache was not built from";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("not the OSM file"), std::string::npos) << e.what();
  }
  EXPECT_EQ(test::read_file(dir / "old.gpkg"), before);
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    const std::string name = entry.path().filename().string();
    EXPECT_TRUE(name.find(".partial") == std::string::npos && name.find(".new-") == std::string::npos) << name;
  }
  // In place, the cache is replaced by the updated one.
  u.base = dir / "old.osm.pbf";
  const UpdateReport r = update_region(u);
  EXPECT_GT(r.tiles_rendered, 0);
  EXPECT_NE(test::read_file(dir / "old.gpkg"), before);
  EXPECT_EQ(raster::CacheReader(dir / "old.gpkg").metadata().changes_applied, "day.osc");
}

}  // namespace
}  // namespace seqloc::ingest::change_footprint_tests
