#include "seqloc/raster/cache.hpp"

#include <algorithm>
#include <bit>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <set>
#include <utility>

#include "seqloc/osm/classes.hpp"
#include "seqloc/raster/png_codec.hpp"
#include "sqlite.hpp"

#ifndef SEQLOC_VERSION
#define SEQLOC_VERSION "unknown"
#endif

namespace seqloc::raster {
namespace {

// The region CRS is stored under this srs_id (GeoPackage reserves none above 32767 for users;
// GDAL numbers its own custom systems from 100000).
constexpr std::int64_t kSrsId = 100000;
constexpr int kTilesPerTransaction = 32;
constexpr const char* kGriddedCoverageSpec = "http://docs.opengeospatial.org/is/17-066r1/17-066r1.html";
constexpr std::uint16_t kDistanceNull = 65535;

std::int64_t tile_key(std::int64_t col, std::int64_t row) { return (col << 32) ^ row; }

std::string format_double(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.17g", value);
  return buffer;
}

std::string now_utc() {
  const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buffer;
}

std::string classes_json() {
  std::string json = "{";
  for (osm::Channel channel : {osm::Channel::areas, osm::Channel::ways, osm::Channel::nodes}) {
    if (json.size() > 1) json.append(",");
    json.append("\"").append(osm::channel_name(channel)).append("\":[");
    bool first = true;
    for (auto name : osm::group_names(channel)) {
      json.append(first ? "\"" : ",\"").append(name).append("\"");
      first = false;
    }
    json.append("]");
  }
  json.append("}");
  return json;
}

void remove_sqlite_files(const std::filesystem::path& path) {
  std::error_code ec;
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::filesystem::remove(path.string() + suffix, ec);
}

// GeoPackage geometry blob (GeoPackage 1.2, section 2.1.3) of a 2D LineString: header with the
// srs_id and an [minx, maxx, miny, maxy] envelope, then little-endian WKB.
std::vector<std::uint8_t> linestring_blob(const std::vector<osm::GridPoint>& points) {
  std::vector<std::uint8_t> blob;
  auto put = [&blob](const void* data, std::size_t n) {
    const auto* bytes = static_cast<const std::uint8_t*>(data);
    blob.insert(blob.end(), bytes, bytes + n);
  };
  static_assert(std::endian::native == std::endian::little, "GeoPackage blobs are written little-endian");
  blob.push_back('G');
  blob.push_back('P');
  blob.push_back(0);     // version 1
  blob.push_back(0x03);  // little-endian, envelope [minx, maxx, miny, maxy]
  const auto srs = static_cast<std::int32_t>(kSrsId);
  put(&srs, 4);
  double minx = points[0].x_m, maxx = minx, miny = points[0].y_m, maxy = miny;
  for (const auto& p : points) {
    minx = std::min(minx, p.x_m);
    maxx = std::max(maxx, p.x_m);
    miny = std::min(miny, p.y_m);
    maxy = std::max(maxy, p.y_m);
  }
  for (double v : {minx, maxx, miny, maxy}) put(&v, 8);
  blob.push_back(1);  // WKB little-endian
  const std::uint32_t type = 2, count = static_cast<std::uint32_t>(points.size());
  put(&type, 4);
  put(&count, 4);
  for (const auto& p : points) {
    put(&p.x_m, 8);
    put(&p.y_m, 8);
  }
  return blob;
}

std::vector<osm::GridPoint> parse_linestring_blob(std::span<const std::uint8_t> blob, const std::string& where) {
  auto fail = [&where]() -> std::vector<osm::GridPoint> { throw CacheFormatError(where + ": malformed road geometry"); };
  if (blob.size() < 8 || blob[0] != 'G' || blob[1] != 'P') return fail();
  const int envelope = (blob[3] >> 1) & 0x7;
  static constexpr std::size_t kEnvelopeBytes[] = {0, 32, 48, 48, 64};
  if (envelope > 4 || (blob[3] & 1) == 0) return fail();
  std::size_t offset = 8 + kEnvelopeBytes[envelope];
  if (blob.size() < offset + 9 || blob[offset] != 1) return fail();
  std::uint32_t type = 0, count = 0;
  std::memcpy(&type, blob.data() + offset + 1, 4);
  std::memcpy(&count, blob.data() + offset + 5, 4);
  offset += 9;
  if (type != 2 || blob.size() != offset + static_cast<std::size_t>(count) * 16) return fail();
  std::vector<osm::GridPoint> points(count);
  const auto* point = blob.data() + offset;
  for (auto& p : points) {
    std::memcpy(&p.x_m, point, 8);
    std::memcpy(&p.y_m, point + 8, 8);
    point += 16;
  }
  return points;
}

CacheMetadata metadata_from_db(const detail::Database& db) {
  if (!db.has_table("seqloc_metadata")) {
    throw CacheFormatError(db.path() + ": not a seqloc region cache (no seqloc_metadata table); build one with "
                           "`seqloc preprocess`");
  }
  std::map<std::string, std::string> rows;
  detail::Statement s(db, "SELECT key, value FROM seqloc_metadata");
  while (s.step()) rows[s.column_text(0)] = s.column_text(1);
  auto get = [&](const std::string& key) -> const std::string& {
    const auto it = rows.find(key);
    if (it == rows.end()) throw CacheFormatError(db.path() + ": metadata key '" + key + "' is missing");
    return it->second;
  };
  auto number = [&](const std::string& key) {
    const std::string& text = get(key);
    try {
      std::size_t used = 0;
      const double value = std::stod(text, &used);
      if (used != text.size()) throw std::invalid_argument(text);
      return value;
    } catch (const std::exception&) {
      throw CacheFormatError(db.path() + ": metadata key '" + key + "' is not a number: '" + text + "'");
    }
  };
  if (get("format") != "seqloc-region-cache") {
    throw CacheFormatError(db.path() + ": not a seqloc region cache (format '" + get("format") + "')");
  }
  CacheMetadata m;
  m.format_version = static_cast<int>(number("format_version"));
  if (m.format_version != kCacheFormatVersion) {
    throw CacheFormatError(db.path() + ": cache format version " + get("format_version") + ", but this seqloc reads " +
                           "version " + std::to_string(kCacheFormatVersion) +
                           "; rebuild the cache with `seqloc preprocess`");
  }
  m.software_version = get("software_version");
  m.source_file = get("source_file");
  m.source_sha256 = get("source_sha256");
  m.osm_replication_timestamp = get("osm_replication_timestamp");
  m.centre_lat = number("centre_lat");
  m.centre_lon = number("centre_lon");
  m.bbox = {number("bbox_min_lon"), number("bbox_min_lat"), number("bbox_max_lon"), number("bbox_max_lat")};
  m.max_distance_m = number("max_distance_m");
  m.grid = {static_cast<std::int64_t>(number("tile_x0")), static_cast<std::int64_t>(number("tile_y0")),
            static_cast<std::int64_t>(number("tile_x1")), static_cast<std::int64_t>(number("tile_y1"))};
  m.shard_index = static_cast<int>(number("shard_index"));
  m.shard_count = static_cast<int>(number("shard_count"));
  m.created_utc = get("created_utc");
  m.complete = get("state") == "complete";
  if (m.grid.tiles_wide() <= 0 || m.grid.tiles_high() <= 0 || m.shard_count < 1 || m.shard_index < 0 ||
      m.shard_index >= m.shard_count) {
    throw CacheFormatError(db.path() + ": inconsistent metadata (tile grid or shard)");
  }
  return m;
}

}  // namespace

const char* layer_table(Layer layer) { return layer == Layer::classes ? "classes" : "road_distance"; }

bool CacheMetadata::same_build(const CacheMetadata& o) const {
  return format_version == o.format_version && source_sha256 == o.source_sha256 && centre_lat == o.centre_lat &&
         centre_lon == o.centre_lon && bbox.min_lon == o.bbox.min_lon && bbox.min_lat == o.bbox.min_lat &&
         bbox.max_lon == o.bbox.max_lon && bbox.max_lat == o.bbox.max_lat && max_distance_m == o.max_distance_m &&
         grid == o.grid;
}

bool CacheMetadata::shard_owns(std::int64_t col, std::int64_t row) const {
  return (row * grid.tiles_wide() + col) % shard_count == shard_index;
}

std::vector<std::pair<std::string, std::string>> metadata_rows(const CacheMetadata& m) {
  const osm::RegionProjection projection = m.projection();
  return {
      {"format", "seqloc-region-cache"},
      {"format_version", std::to_string(m.format_version)},
      {"software_version", m.software_version},
      {"source_file", m.source_file},
      {"source_sha256", m.source_sha256},
      {"osm_replication_timestamp", m.osm_replication_timestamp},
      {"centre_lat", format_double(m.centre_lat)},
      {"centre_lon", format_double(m.centre_lon)},
      {"bbox_min_lon", format_double(m.bbox.min_lon)},
      {"bbox_min_lat", format_double(m.bbox.min_lat)},
      {"bbox_max_lon", format_double(m.bbox.max_lon)},
      {"bbox_max_lat", format_double(m.bbox.max_lat)},
      {"max_distance_m", format_double(m.max_distance_m)},
      {"cell_m", format_double(kCellM)},
      {"tile_px", std::to_string(kTilePx)},
      {"tile_x0", std::to_string(m.grid.tx0)},
      {"tile_y0", std::to_string(m.grid.ty0)},
      {"tile_x1", std::to_string(m.grid.tx1)},
      {"tile_y1", std::to_string(m.grid.ty1)},
      {"crs_proj", projection.proj_string()},
      {"crs_wkt", projection.wkt()},
      {"classes", classes_json()},
      {"shard_index", std::to_string(m.shard_index)},
      {"shard_count", std::to_string(m.shard_count)},
      {"created_utc", m.created_utc},
      {"state", m.complete ? "complete" : "building"},
      {"attribution", "Map data (c) OpenStreetMap contributors, ODbL 1.0 (https://www.openstreetmap.org/copyright)"},
  };
}

// ---------------------------------------------------------------------------------------------
// Writer

CacheWriter::CacheWriter(const std::filesystem::path& final_path, CacheMetadata metadata)
    : final_(final_path), partial_(final_path.string() + ".partial"), metadata_(std::move(metadata)) {
  const auto dir = final_.has_parent_path() ? final_.parent_path() : std::filesystem::path(".");
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    throw CacheIoError(final_.string() + ": output directory '" + dir.string() + "' does not exist");
  }
  metadata_.complete = false;
  if (metadata_.software_version.empty()) metadata_.software_version = SEQLOC_VERSION;
  if (metadata_.created_utc.empty()) metadata_.created_utc = now_utc();

  if (std::filesystem::exists(partial_, ec)) {
    try {
      auto db = std::make_unique<detail::Database>(partial_.string(), SQLITE_OPEN_READWRITE);
      const CacheMetadata previous = metadata_from_db(*db);
      if (previous.same_build(metadata_) && previous.shard_index == metadata_.shard_index &&
          previous.shard_count == metadata_.shard_count && !previous.complete) {
        db_ = std::move(db);
        resumed_ = true;
        metadata_.created_utc = previous.created_utc;
      }
    } catch (const CacheError&) {
      // An unreadable or foreign partial file is simply rebuilt.
    }
    if (!resumed_) remove_sqlite_files(partial_);
  }
  if (!db_) {
    db_ = std::make_unique<detail::Database>(partial_.string(), SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
  }
  db_->exec("PRAGMA journal_mode = WAL");
  db_->exec("PRAGMA synchronous = NORMAL");
  if (resumed_) {
    detail::Statement s(*db_, "SELECT tile_column, tile_row FROM classes");
    while (s.step()) done_[tile_key(s.column_int(0), s.column_int(1))] = true;
  } else {
    create_schema(metadata_.projection());
  }
}

CacheWriter::~CacheWriter() {
  if (db_ && in_transaction_) {
    try {
      db_->exec("COMMIT");
    } catch (const CacheError&) {
    }
  }
}

bool CacheWriter::has_tile(std::int64_t col, std::int64_t row) const { return done_.count(tile_key(col, row)) > 0; }

void CacheWriter::create_schema(const osm::RegionProjection& projection) {
  auto& db = *db_;
  db.exec("PRAGMA application_id = 1196444487");  // 'GPKG'
  db.exec("PRAGMA user_version = 10200");         // GeoPackage 1.2
  db.exec("BEGIN");
  db.exec(R"sql(
CREATE TABLE gpkg_spatial_ref_sys (
  srs_name TEXT NOT NULL, srs_id INTEGER NOT NULL PRIMARY KEY, organization TEXT NOT NULL,
  organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT);
CREATE TABLE gpkg_contents (
  table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL, identifier TEXT UNIQUE,
  description TEXT DEFAULT '', last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
  min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER,
  CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id));
CREATE TABLE gpkg_geometry_columns (
  table_name TEXT NOT NULL, column_name TEXT NOT NULL, geometry_type_name TEXT NOT NULL,
  srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT NULL,
  CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name),
  CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name),
  CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id));
CREATE TABLE gpkg_tile_matrix_set (
  table_name TEXT NOT NULL PRIMARY KEY, srs_id INTEGER NOT NULL,
  min_x DOUBLE NOT NULL, min_y DOUBLE NOT NULL, max_x DOUBLE NOT NULL, max_y DOUBLE NOT NULL,
  CONSTRAINT fk_gtms_table_name FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name),
  CONSTRAINT fk_gtms_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id));
CREATE TABLE gpkg_tile_matrix (
  table_name TEXT NOT NULL, zoom_level INTEGER NOT NULL, matrix_width INTEGER NOT NULL,
  matrix_height INTEGER NOT NULL, tile_width INTEGER NOT NULL, tile_height INTEGER NOT NULL,
  pixel_x_size DOUBLE NOT NULL, pixel_y_size DOUBLE NOT NULL,
  CONSTRAINT pk_ttm PRIMARY KEY (table_name, zoom_level),
  CONSTRAINT fk_tmm_table_name FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name));
CREATE TABLE gpkg_extensions (
  table_name TEXT, column_name TEXT, extension_name TEXT NOT NULL, definition TEXT NOT NULL,
  scope TEXT NOT NULL, CONSTRAINT ge_tce UNIQUE (table_name, column_name, extension_name));
CREATE TABLE gpkg_2d_gridded_coverage_ancillary (
  id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, tile_matrix_set_name TEXT NOT NULL UNIQUE,
  datatype TEXT NOT NULL DEFAULT 'integer', scale REAL NOT NULL DEFAULT 1.0, offset REAL NOT NULL DEFAULT 0.0,
  precision REAL DEFAULT 1.0, data_null REAL, grid_cell_encoding TEXT DEFAULT 'grid-value-is-center',
  uom TEXT, field_name TEXT DEFAULT 'Height', quantity_definition TEXT DEFAULT 'Height',
  CONSTRAINT fk_g2dgtct_name FOREIGN KEY(tile_matrix_set_name) REFERENCES gpkg_tile_matrix_set(table_name),
  CHECK (datatype in ('integer','float')));
CREATE TABLE gpkg_2d_gridded_tile_ancillary (
  id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, tpudt_name TEXT NOT NULL, tpudt_id INTEGER NOT NULL,
  scale REAL NOT NULL DEFAULT 1.0, offset REAL NOT NULL DEFAULT 0.0, min REAL DEFAULT NULL,
  max REAL DEFAULT NULL, mean REAL DEFAULT NULL, std_dev REAL DEFAULT NULL,
  CONSTRAINT fk_g2dgtat_name FOREIGN KEY (tpudt_name) REFERENCES gpkg_contents(table_name),
  UNIQUE (tpudt_name, tpudt_id));
CREATE TABLE classes (
  id INTEGER PRIMARY KEY AUTOINCREMENT, zoom_level INTEGER NOT NULL, tile_column INTEGER NOT NULL,
  tile_row INTEGER NOT NULL, tile_data BLOB NOT NULL, UNIQUE (zoom_level, tile_column, tile_row));
CREATE TABLE road_distance (
  id INTEGER PRIMARY KEY AUTOINCREMENT, zoom_level INTEGER NOT NULL, tile_column INTEGER NOT NULL,
  tile_row INTEGER NOT NULL, tile_data BLOB NOT NULL, UNIQUE (zoom_level, tile_column, tile_row));
CREATE TABLE roads (
  fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom LINESTRING, osm_id INTEGER, highway TEXT);
CREATE TABLE seqloc_metadata (key TEXT NOT NULL PRIMARY KEY, value TEXT NOT NULL);
INSERT INTO gpkg_spatial_ref_sys VALUES
  ('Undefined cartesian SRS', -1, 'NONE', -1, 'undefined', 'undefined cartesian coordinate reference system'),
  ('Undefined geographic SRS', 0, 'NONE', 0, 'undefined', 'undefined geographic coordinate reference system'),
  ('WGS 84 geodetic', 4326, 'EPSG', 4326, 'GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AXIS["Latitude",NORTH],AXIS["Longitude",EAST],AUTHORITY["EPSG","4326"]]', 'longitude/latitude coordinates in decimal degrees on the WGS 84 spheroid');
)sql");
  const RegionGrid& g = metadata_.grid;
  {
    detail::Statement s(db, "INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, 'NONE', ?, ?, ?)");
    s.bind(1, std::string_view("seqloc region TM"))
        .bind(2, kSrsId)
        .bind(3, kSrsId)
        .bind(4, projection.wkt())
        .bind(5, projection.proj_string());
    s.run();
  }
  {
    detail::Statement s(db, "INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, "
                            "max_x, max_y, srs_id) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)");
    auto add = [&](std::string_view table, std::string_view type, std::string_view description, bool spatial) {
      s.bind(1, table).bind(2, type).bind(3, table).bind(4, description);
      if (spatial) {
        s.bind(5, g.min_x()).bind(6, g.min_y()).bind(7, g.max_x()).bind(8, g.max_y()).bind(9, kSrsId);
      } else {
        s.bind_null(5).bind_null(6).bind_null(7).bind_null(8).bind_null(9);
      }
      s.run();
    };
    add("classes", "tiles", "OrienterNet semantic classes: R = areas, G = ways, B = nodes (0 = background)", true);
    add("road_distance", "2d-gridded-coverage", "distance to the nearest road cell, metres (UInt16 cm)", true);
    add("roads", "features", "road-group centerlines (OrienterNet 'road' ways)", true);
    add("seqloc_metadata", "attributes", "seqloc cache metadata", false);
  }
  {
    detail::Statement s(db, "INSERT INTO gpkg_tile_matrix_set VALUES (?, ?, ?, ?, ?, ?)");
    detail::Statement m(db, "INSERT INTO gpkg_tile_matrix VALUES (?, 0, ?, ?, ?, ?, ?, ?)");
    for (const char* table : {"classes", "road_distance"}) {
      s.bind(1, std::string_view(table)).bind(2, kSrsId).bind(3, g.min_x()).bind(4, g.min_y()).bind(5, g.max_x());
      s.bind(6, g.max_y());
      s.run();
      m.bind(1, std::string_view(table)).bind(2, g.tiles_wide()).bind(3, g.tiles_high());
      m.bind(4, std::int64_t{kTilePx}).bind(5, std::int64_t{kTilePx}).bind(6, kCellM).bind(7, kCellM);
      m.run();
    }
  }
  {
    detail::Statement s(db, "INSERT INTO gpkg_2d_gridded_coverage_ancillary (tile_matrix_set_name, datatype, scale, "
                            "offset, precision, data_null, grid_cell_encoding, uom, field_name, quantity_definition) "
                            "VALUES ('road_distance', 'integer', 0.01, 0.0, 0.01, ?, 'grid-value-is-area', 'm', "
                            "'road_distance', 'Distance to the nearest road cell')");
    s.bind(1, static_cast<double>(kDistanceNull));
    s.run();
  }
  {
    detail::Statement s(db, "INSERT INTO gpkg_extensions VALUES (?, ?, 'gpkg_2d_gridded_coverage', ?, 'read-write')");
    auto add = [&](std::string_view table, const char* column) {
      s.bind(1, table);
      if (column) {
        s.bind(2, std::string_view(column));
      } else {
        s.bind_null(2);
      }
      s.bind(3, std::string_view(kGriddedCoverageSpec));
      s.run();
    };
    add("gpkg_2d_gridded_coverage_ancillary", nullptr);
    add("gpkg_2d_gridded_tile_ancillary", nullptr);
    add("road_distance", "tile_data");
  }
  {
    detail::Statement s(db, "INSERT INTO gpkg_geometry_columns VALUES ('roads', 'geom', 'LINESTRING', ?, 0, 0)");
    s.bind(1, kSrsId);
    s.run();
  }
  write_metadata();
  db.exec("COMMIT");
}

void CacheWriter::write_metadata() {
  detail::Statement s(*db_, "INSERT OR REPLACE INTO seqloc_metadata (key, value) VALUES (?, ?)");
  for (const auto& [key, value] : metadata_rows(metadata_)) {
    s.bind(1, key).bind(2, value);
    s.run();
  }
}

void CacheWriter::begin() {
  if (!in_transaction_) {
    db_->exec("BEGIN");
    in_transaction_ = true;
  }
}

void CacheWriter::commit() {
  if (in_transaction_) {
    db_->exec("COMMIT");
    in_transaction_ = false;
    pending_ = 0;
  }
}

void CacheWriter::write_roads(const std::vector<RoadLine>& roads) {
  {
    detail::Statement count(*db_, "SELECT COUNT(*) FROM seqloc_metadata WHERE key = 'roads_written'");
    if (count.step() && count.column_int(0) > 0) return;
  }
  begin();
  detail::Statement s(*db_, "INSERT INTO roads (geom, osm_id, highway) VALUES (?, ?, ?)");
  for (const auto& road : roads) {
    if (road.points.size() < 2) continue;
    const auto blob = linestring_blob(road.points);
    s.bind_blob(1, blob).bind(2, road.osm_id).bind(3, road.highway);
    s.run();
  }
  db_->exec("INSERT OR REPLACE INTO seqloc_metadata (key, value) VALUES ('roads_written', 'yes')");
  commit();
}

void CacheWriter::write_tile(const EncodedTile& tile) {
  assert(metadata_.grid.contains_tile(tile.col, tile.row));
  begin();
  if (!insert_classes_) {
    insert_classes_ = std::make_unique<detail::Statement>(
        *db_, "INSERT OR REPLACE INTO classes (zoom_level, tile_column, tile_row, tile_data) VALUES (0, ?, ?, ?)");
    insert_distance_ = std::make_unique<detail::Statement>(
        *db_, "INSERT OR REPLACE INTO road_distance (zoom_level, tile_column, tile_row, tile_data) VALUES (0, ?, ?, ?)");
    insert_ancillary_ = std::make_unique<detail::Statement>(
        *db_, "INSERT OR REPLACE INTO gpkg_2d_gridded_tile_ancillary (tpudt_name, tpudt_id, scale, offset, min, max, "
              "mean) VALUES ('road_distance', ?, 1.0, 0.0, ?, ?, ?)");
  }
  insert_classes_->bind(1, tile.col).bind(2, tile.row).bind_blob(3, tile.classes_png);
  insert_classes_->run();
  insert_distance_->bind(1, tile.col).bind(2, tile.row).bind_blob(3, tile.distance_png);
  insert_distance_->run();
  const std::int64_t id = sqlite3_last_insert_rowid(db_->get());
  detail::Statement& ancillary = *insert_ancillary_;
  ancillary.bind(1, id)
      .bind(2, tile.distance_min_m)
      .bind(3, tile.distance_max_m)
      .bind(4, tile.distance_mean_m);
  ancillary.run();
  done_[tile_key(tile.col, tile.row)] = true;
  if (++pending_ >= kTilesPerTransaction) commit();
}

void CacheWriter::finish() {
  commit();
  const RegionGrid& g = metadata_.grid;
  for (std::int64_t row = 0; row < g.tiles_high(); ++row) {
    for (std::int64_t col = 0; col < g.tiles_wide(); ++col) {
      if (metadata_.shard_owns(col, row) && !has_tile(col, row)) {
        throw CacheError(partial_.string() + ": tile (" + std::to_string(col) + ", " + std::to_string(row) +
                         ") was never written; the cache is not complete");
      }
    }
  }
  insert_classes_.reset();
  insert_distance_.reset();
  insert_ancillary_.reset();
  metadata_.complete = true;
  db_->exec("BEGIN");
  write_metadata();
  db_->exec("COMMIT");
  db_->exec("PRAGMA journal_mode = DELETE");  // a finished cache is one self-contained file
  db_.reset();
  std::error_code ec;
  std::filesystem::rename(partial_, final_, ec);
  if (ec) throw CacheIoError(final_.string() + ": cannot move the finished cache into place: " + ec.message());
}

// ---------------------------------------------------------------------------------------------
// Encoder

EncodedTile TileEncoder::encode(std::int64_t col, std::int64_t row, const std::vector<std::uint8_t>& rgb,
                                bool classes_empty, const std::vector<std::uint16_t>& cm) {
  EncodedTile tile;
  tile.col = col;
  tile.row = row;
  if (classes_empty) {
    if (empty_classes_.empty()) empty_classes_ = encode_png_rgb8(rgb, kTilePx, kTilePx);
    tile.classes_png = empty_classes_;
  } else {
    tile.classes_png = encode_png_rgb8(rgb, kTilePx, kTilePx);
  }
  const auto [lo, hi] = std::minmax_element(cm.begin(), cm.end());
  tile.distance_min_m = *lo * 0.01;
  tile.distance_max_m = *hi * 0.01;
  if (*lo == *hi) {
    auto& blob = constant_distance_[*lo];
    if (blob.empty()) blob = encode_png_gray16(cm, kTilePx, kTilePx);
    tile.distance_png = blob;
    tile.distance_mean_m = tile.distance_min_m;
  } else {
    tile.distance_png = encode_png_gray16(cm, kTilePx, kTilePx);
    double sum = 0;
    for (auto v : cm) sum += v;
    tile.distance_mean_m = sum / static_cast<double>(cm.size()) * 0.01;
  }
  return tile;
}

// ---------------------------------------------------------------------------------------------
// Reader

CacheMetadata read_cache_metadata(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw CacheIoError(path.string() + ": no such cache file");
  detail::Database db(path.string(), SQLITE_OPEN_READONLY);
  try {
    return metadata_from_db(db);
  } catch (const CacheIoError& e) {
    throw CacheFormatError(path.string() + ": not a seqloc region cache (" + e.what() + ")");
  }
}

CacheReader::CacheReader(const std::filesystem::path& path, std::size_t lru_tiles)
    : path_(path), capacity_(std::max<std::size_t>(1, lru_tiles)) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw CacheIoError(path.string() + ": no such cache file");
  db_ = std::make_unique<detail::Database>(path.string(), SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX);
  try {
    metadata_ = metadata_from_db(*db_);
  } catch (const CacheIoError& e) {
    throw CacheFormatError(path.string() + ": not a seqloc region cache (" + e.what() + ")");
  }
  if (!metadata_.complete) {
    throw CacheFormatError(path.string() + ": the cache is unfinished (its build was interrupted); rerun "
                           "`seqloc preprocess` to complete it");
  }
  if (metadata_.shard_count > 1) {
    throw CacheFormatError(path.string() + ": this is shard " + std::to_string(metadata_.shard_index) + "/" +
                           std::to_string(metadata_.shard_count) + "; merge the shards with `seqloc cache merge`");
  }
}

CacheReader::~CacheReader() = default;

std::vector<std::uint8_t> CacheReader::tile_blob(Layer layer, std::int64_t col, std::int64_t row) {
  const char* table = layer_table(layer);
  if (!grid().contains_tile(col, row)) {
    throw CacheRangeError(path_.string() + ": tile (" + std::to_string(col) + ", " + std::to_string(row) + ") of '" +
                          table + "' is outside the region (columns 0.." + std::to_string(grid().tiles_wide() - 1) +
                          ", rows 0.." + std::to_string(grid().tiles_high() - 1) + ")");
  }
  std::lock_guard lock(mutex_);
  auto& statement = select_tile_[layer == Layer::classes ? 0 : 1];
  if (!statement) {
    statement = std::make_unique<detail::Statement>(
        *db_, std::string("SELECT tile_data FROM ") + table + " WHERE zoom_level = 0 AND tile_column = ? AND tile_row = ?");
  }
  detail::Statement& s = *statement;
  s.reset();
  s.bind(1, col).bind(2, row);
  if (!s.step()) {
    s.reset();
    throw CacheRangeError(path_.string() + ": tile (" + std::to_string(col) + ", " + std::to_string(row) + ") of '" +
                          table + "' is missing from the cache");
  }
  const auto blob = s.column_blob(0);
  std::vector<std::uint8_t> out(blob.begin(), blob.end());
  s.reset();
  return out;
}

bool CacheReader::has_tile(Layer layer, std::int64_t col, std::int64_t row) {
  if (!grid().contains_tile(col, row)) return false;
  std::lock_guard lock(mutex_);
  detail::Statement s(*db_, std::string("SELECT 1 FROM ") + layer_table(layer) +
                                " WHERE zoom_level = 0 AND tile_column = ? AND tile_row = ?");
  s.bind(1, col).bind(2, row);
  return s.step();
}

CacheReader::Decoded CacheReader::load(Layer layer, std::int64_t col, std::int64_t row) {
  const Key key{static_cast<int>(layer), col, row};
  {
    std::lock_guard lock(mutex_);
    if (auto it = index_.find(key); it != index_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second);
      ++stats_.hits;
      return it->second->second;
    }
    ++stats_.misses;
  }
  // Fetch under the lock (one SQLite connection), decode outside it so threads decode in parallel.
  const auto blob = tile_blob(layer, col, row);
  const std::string what = path_.string() + ": tile (" + std::to_string(col) + ", " + std::to_string(row) + ") of '" +
                           layer_table(layer) + "'";
  PngImage image;
  try {
    image = decode_png(blob, what, kTilePx);
  } catch (const PngError& e) {
    throw CacheFormatError(e.what());
  }
  if (image.width != kTilePx || image.height != kTilePx) throw CacheFormatError(what + ": not 512 x 512");
  Decoded decoded;
  if (layer == Layer::classes) {
    if (image.bit_depth != 8 || image.channels < 3) throw CacheFormatError(what + ": not an 8-bit RGB tile");
    if (image.channels == 3) {
      decoded.rgb = std::make_shared<const std::vector<std::uint8_t>>(std::move(image.pixels8));
    } else {
      std::vector<std::uint8_t> rgb(static_cast<std::size_t>(kTilePx) * kTilePx * 3);
      for (std::size_t i = 0; i < rgb.size() / 3; ++i) {
        for (int c = 0; c < 3; ++c) rgb[i * 3 + c] = image.pixels8[i * static_cast<std::size_t>(image.channels) + c];
      }
      decoded.rgb = std::make_shared<const std::vector<std::uint8_t>>(std::move(rgb));
    }
  } else {
    if (image.bit_depth != 16 || image.channels != 1) throw CacheFormatError(what + ": not a 16-bit grey tile");
    decoded.cm = std::make_shared<const std::vector<std::uint16_t>>(std::move(image.pixels16));
  }
  std::lock_guard lock(mutex_);
  if (auto it = index_.find(key); it != index_.end()) return it->second->second;  // another thread won
  lru_.emplace_front(key, decoded);
  index_[key] = lru_.begin();
  while (lru_.size() > capacity_) {
    index_.erase(lru_.back().first);
    lru_.pop_back();
  }
  return decoded;
}

std::shared_ptr<const std::vector<std::uint8_t>> CacheReader::classes_tile(std::int64_t col, std::int64_t row) {
  return load(Layer::classes, col, row).rgb;
}

std::shared_ptr<const std::vector<std::uint16_t>> CacheReader::distance_tile(std::int64_t col, std::int64_t row) {
  return load(Layer::road_distance, col, row).cm;
}

CacheReader::LruStats CacheReader::lru_stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

void CacheReader::check_window(std::int64_t u0, std::int64_t v0, int width, int height, bool fill_outside,
                               Layer layer) const {
  if (width <= 0 || height <= 0) throw CacheRangeError(path_.string() + ": empty window requested");
  if (fill_outside) return;
  const auto& g = grid();
  if (u0 < 0 || v0 < 0 || u0 + width > g.width_px() || v0 + height > g.height_px()) {
    auto floor_div = [](std::int64_t a) { return a >= 0 ? a / kTilePx : -((-a + kTilePx - 1) / kTilePx); };
    const std::int64_t col = u0 < 0 ? floor_div(u0) : floor_div(u0 + width - 1);
    const std::int64_t row = v0 < 0 ? floor_div(v0) : floor_div(v0 + height - 1);
    throw CacheRangeError(path_.string() + ": window at pixel (" + std::to_string(u0) + ", " + std::to_string(v0) +
                          ") size " + std::to_string(width) + " x " + std::to_string(height) + " of '" +
                          layer_table(layer) + "' reaches tile (" + std::to_string(col) + ", " + std::to_string(row) +
                          "), outside the region (" + std::to_string(g.tiles_wide()) + " x " +
                          std::to_string(g.tiles_high()) + " tiles)");
  }
}

namespace {

// Copies the part of each tile that a window covers; `fetch(col, row)` returns the tile's data,
// `fill` is written where the window leaves the region.
template <class T, class Fetch>
void stitch(const RegionGrid& grid, std::int64_t u0, std::int64_t v0, int width, int height, int channels, T fill,
            std::vector<T>& out, Fetch&& fetch) {
  out.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * static_cast<std::size_t>(channels),
             fill);
  auto floor_div = [](std::int64_t a) { return a >= 0 ? a / kTilePx : -((-a + kTilePx - 1) / kTilePx); };
  const std::int64_t c0 = std::max<std::int64_t>(0, floor_div(u0));
  const std::int64_t c1 = std::min<std::int64_t>(grid.tiles_wide() - 1, floor_div(u0 + width - 1));
  const std::int64_t r0 = std::max<std::int64_t>(0, floor_div(v0));
  const std::int64_t r1 = std::min<std::int64_t>(grid.tiles_high() - 1, floor_div(v0 + height - 1));
  for (std::int64_t row = r0; row <= r1; ++row) {
    for (std::int64_t col = c0; col <= c1; ++col) {
      const auto tile = fetch(col, row);
      const std::int64_t tu0 = col * kTilePx, tv0 = row * kTilePx;
      const std::int64_t a0 = std::max(u0, tu0), a1 = std::min(u0 + width, tu0 + kTilePx);
      const std::int64_t b0 = std::max(v0, tv0), b1 = std::min(v0 + height, tv0 + kTilePx);
      const auto n = static_cast<std::size_t>((a1 - a0) * channels);
      for (std::int64_t v = b0; v < b1; ++v) {
        const T* src = tile->data() + static_cast<std::size_t>(((v - tv0) * kTilePx + (a0 - tu0)) * channels);
        T* dst = out.data() + static_cast<std::size_t>(((v - v0) * width + (a0 - u0)) * channels);
        std::copy(src, src + n, dst);
      }
    }
  }
}

}  // namespace

void CacheReader::read_classes(std::int64_t u0, std::int64_t v0, int width, int height, std::vector<std::uint8_t>& rgb,
                               bool fill_outside) {
  check_window(u0, v0, width, height, fill_outside, Layer::classes);
  stitch<std::uint8_t>(grid(), u0, v0, width, height, 3, 0, rgb,
                       [this](std::int64_t c, std::int64_t r) { return classes_tile(c, r); });
}

void CacheReader::read_road_distance(std::int64_t u0, std::int64_t v0, int width, int height,
                                     std::vector<std::uint16_t>& cm, bool fill_outside) {
  check_window(u0, v0, width, height, fill_outside, Layer::road_distance);
  const auto clamp = static_cast<std::uint16_t>(std::lround(metadata_.max_distance_m * 100.0));
  stitch<std::uint16_t>(grid(), u0, v0, width, height, 1, clamp, cm,
                        [this](std::int64_t c, std::int64_t r) { return distance_tile(c, r); });
}

void CacheReader::read_road_distance_m(std::int64_t u0, std::int64_t v0, int width, int height,
                                       std::vector<float>& metres, bool fill_outside) {
  std::vector<std::uint16_t> cm;
  read_road_distance(u0, v0, width, height, cm, fill_outside);
  metres.resize(cm.size());
  std::transform(cm.begin(), cm.end(), metres.begin(), road_distance_metres);
}

std::vector<RoadLine> CacheReader::roads() {
  std::lock_guard lock(mutex_);
  std::vector<RoadLine> out;
  detail::Statement s(*db_, "SELECT fid, geom, osm_id, highway FROM roads ORDER BY fid");
  while (s.step()) {
    RoadLine road{s.column_int(2), s.column_text(3), {}};
    road.points = parse_linestring_blob(s.column_blob(1), path_.string() + ": roads fid " + std::to_string(s.column_int(0)));
    out.push_back(std::move(road));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Merge

void merge_shards(const std::vector<std::filesystem::path>& shards, const std::filesystem::path& out) {
  if (shards.empty()) throw CacheError("cache merge: no shards given");
  std::vector<CacheMetadata> metas;
  for (const auto& shard : shards) {
    metas.push_back(read_cache_metadata(shard));
    if (!metas.back().complete) throw CacheFormatError(shard.string() + ": shard is unfinished; rerun its build");
  }
  const CacheMetadata& first = metas.front();
  std::set<int> seen;
  for (std::size_t i = 0; i < metas.size(); ++i) {
    if (!metas[i].same_build(first) || metas[i].shard_count != first.shard_count) {
      throw CacheError(shards[i].string() + ": belongs to another build than " + shards[0].string() +
                       " (source, bbox, clamp or shard count differ)");
    }
    if (!seen.insert(metas[i].shard_index).second) {
      throw CacheError(shards[i].string() + ": shard " + std::to_string(metas[i].shard_index) + " given twice");
    }
  }
  if (static_cast<int>(seen.size()) != first.shard_count) {
    for (int i = 0; i < first.shard_count; ++i) {
      if (!seen.count(i)) {
        throw CacheError("cache merge: shard " + std::to_string(i) + "/" + std::to_string(first.shard_count) +
                         " is missing");
      }
    }
  }
  CacheMetadata merged = first;
  merged.shard_index = 0;
  merged.shard_count = 1;
  merged.created_utc.clear();
  CacheWriter writer(out, merged);
  for (std::size_t i = 0; i < shards.size(); ++i) {
    detail::Database db(shards[i].string(), SQLITE_OPEN_READONLY);
    if (i == 0) {
      std::vector<RoadLine> roads;
      detail::Statement s(db, "SELECT geom, osm_id, highway FROM roads ORDER BY fid");
      while (s.step()) {
        roads.push_back({s.column_int(1), s.column_text(2), parse_linestring_blob(s.column_blob(0), shards[i].string())});
      }
      writer.write_roads(roads);
    }
    detail::Statement s(db, "SELECT c.tile_column, c.tile_row, c.tile_data, d.tile_data, a.min, a.max, a.mean "
                            "FROM classes c JOIN road_distance d ON c.tile_column = d.tile_column AND "
                            "c.tile_row = d.tile_row LEFT JOIN gpkg_2d_gridded_tile_ancillary a ON "
                            "a.tpudt_name = 'road_distance' AND a.tpudt_id = d.id");
    while (s.step()) {
      EncodedTile tile;
      tile.col = s.column_int(0);
      tile.row = s.column_int(1);
      if (!metas[i].shard_owns(tile.col, tile.row)) {
        throw CacheError(shards[i].string() + ": holds tile (" + std::to_string(tile.col) + ", " +
                         std::to_string(tile.row) + ") of another shard");
      }
      const auto c = s.column_blob(2);
      const auto d = s.column_blob(3);
      tile.classes_png.assign(c.begin(), c.end());
      tile.distance_png.assign(d.begin(), d.end());
      tile.distance_min_m = s.column_double(4);
      tile.distance_max_m = s.column_double(5);
      tile.distance_mean_m = s.column_double(6);
      writer.write_tile(tile);
    }
  }
  writer.finish();
}

}  // namespace seqloc::raster
