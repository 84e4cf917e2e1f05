// Writing a region cache: the GeoPackage schema, tiles, roads and metadata; and the tile encoder.
#include "seqloc/raster/cache.hpp"

#include <algorithm>
#include <cassert>
#include <cstring>
#include <optional>
#include <utility>

#include "cache_format.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/raster/png_codec.hpp"
#include "sqlite.hpp"

#ifndef SEQLOC_VERSION
#define SEQLOC_VERSION "unknown"
#endif

namespace seqloc::raster {

namespace {

// The metadata of the partial cache at `partial` when it is an interrupted build of `metadata`
// (the same build and shard, not complete); nothing when it is missing, unreadable or foreign.
std::optional<CacheMetadata> interrupted_build(const std::filesystem::path& partial, const CacheMetadata& metadata) {
  std::error_code ec;
  if (!std::filesystem::exists(partial, ec)) return std::nullopt;
  try {
    const detail::Database db(partial.string(), SQLITE_OPEN_READWRITE);
    CacheMetadata previous = detail::metadata_from_db(db);
    if (previous.same_build(metadata) && previous.shard_index == metadata.shard_index &&
        previous.shard_count == metadata.shard_count && !previous.complete) {
      return previous;
    }
  } catch (const CacheError&) {
  }
  return std::nullopt;
}

}  // namespace

bool CacheWriter::would_remove_partial(const std::filesystem::path& final_path, const CacheMetadata& metadata) {
  const std::filesystem::path partial = final_path.string() + ".partial";
  std::error_code ec;
  return std::filesystem::exists(partial, ec) && !interrupted_build(partial, metadata);
}

CacheWriter::CacheWriter(const std::filesystem::path& final_path, CacheMetadata metadata)
    : final_(final_path), partial_(final_path.string() + ".partial"), metadata_(std::move(metadata)) {
  const auto dir = final_.has_parent_path() ? final_.parent_path() : std::filesystem::path(".");
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    throw CacheIoError(final_.string() + ": output directory '" + dir.string() + "' does not exist");
  }
  metadata_.complete = false;
  if (metadata_.software_version.empty()) metadata_.software_version = SEQLOC_VERSION;
  if (metadata_.created_utc.empty()) metadata_.created_utc = detail::now_utc();

  if (const auto previous = interrupted_build(partial_, metadata_)) {
    db_ = std::make_unique<detail::Database>(partial_.string(), SQLITE_OPEN_READWRITE);
    resumed_ = true;
    metadata_.created_utc = previous->created_utc;
  } else if (std::filesystem::exists(partial_, ec)) {
    detail::remove_sqlite_files(partial_);  // an unreadable or foreign partial file is simply rebuilt
  }
  if (!db_) {
    db_ = std::make_unique<detail::Database>(partial_.string(), SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
  }
  db_->exec("PRAGMA journal_mode = WAL");
  db_->exec("PRAGMA synchronous = NORMAL");
  if (resumed_) {
    detail::Statement s(*db_, "SELECT COUNT(*) FROM road_distance");
    if (s.step()) stored_ = s.column_int(0);
  } else {
    create_schema(metadata_.projection());
  }
}

CacheWriter CacheWriter::updating(const std::filesystem::path& existing, const std::filesystem::path& final_path,
                                  CacheMetadata metadata) {
  return CacheWriter(existing, final_path, std::move(metadata), Updating{});
}

CacheWriter::CacheWriter(const std::filesystem::path& existing, const std::filesystem::path& final_path,
                         CacheMetadata metadata, Updating)
    : final_(final_path), partial_(final_path.string() + ".partial"), metadata_(std::move(metadata)) {
  metadata_.complete = false;
  metadata_.software_version = SEQLOC_VERSION;
  detail::remove_sqlite_files(partial_);
  std::error_code ec;
  std::filesystem::copy_file(existing, partial_, std::filesystem::copy_options::overwrite_existing, ec);
  if (ec) throw CacheIoError(partial_.string() + ": cannot copy " + existing.string() + ": " + ec.message());
  db_ = std::make_unique<detail::Database>(partial_.string(), SQLITE_OPEN_READWRITE);
  const CacheMetadata previous = detail::metadata_from_db(*db_);
  if (!(previous.grid == metadata_.grid) || previous.shard_count != 1 || !previous.complete) {
    db_.reset();
    detail::remove_sqlite_files(partial_);
    throw CacheError(existing.string() + ": only a complete, unsharded cache of the same grid can be updated");
  }
  db_->exec("PRAGMA journal_mode = WAL");
  db_->exec("PRAGMA synchronous = NORMAL");
  resumed_ = updating_ = true;
  stored_ = metadata_.grid.tile_count();
  db_->exec("BEGIN");
  write_metadata();  // "building" until finish(): a copy left by a killed update is no cache
  db_->exec("COMMIT");
}

// Before a tile is replaced: its distance statistics row (keyed by the tile row's id, which the
// replacement changes), and its classes when the new tile leaves them out.
void CacheWriter::forget_tile(std::int64_t col, std::int64_t row, bool classes_too) {
  detail::Statement a(*db_,
                      "DELETE FROM gpkg_2d_gridded_tile_ancillary WHERE tpudt_name = 'road_distance' AND tpudt_id IN "
                      "(SELECT id FROM road_distance WHERE zoom_level = 0 AND tile_column = ? AND tile_row = ?)");
  a.bind(1, col).bind(2, row);
  a.run();
  if (classes_too) {
    detail::Statement c(*db_, "DELETE FROM classes WHERE zoom_level = 0 AND tile_column = ? AND tile_row = ?");
    c.bind(1, col).bind(2, row);
    c.run();
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

bool CacheWriter::has_tile(std::int64_t col, std::int64_t row) {
  if (!resumed_) return false;  // a new build has stored only what it rendered, once
  // One look-up in the tile index, not a list of the stored tiles: a resumed country would hold
  // one entry per tile for the whole region.
  if (!find_tile_) {
    find_tile_ = std::make_unique<detail::Statement>(
        *db_, "SELECT 1 FROM road_distance WHERE zoom_level = 0 AND tile_column = ? AND tile_row = ?");
  }
  find_tile_->bind(1, col).bind(2, row);
  const bool found = find_tile_->step();
  find_tile_->reset();
  return found;
}

void CacheWriter::discard() {
  find_tile_.reset();
  insert_classes_.reset();
  insert_distance_.reset();
  insert_ancillary_.reset();
  in_transaction_ = false;
  db_.reset();                                                        // closing rolls back what was not committed
  if (!resumed_ || updating_) detail::remove_sqlite_files(partial_);  // an update's copy is ours alone
}

std::int64_t CacheWriter::tiles_owned() const { return metadata_.shard_tile_count(); }

namespace {

// The GeoPackage 1.2 tables (with the gridded coverage extension) and seqloc's own, and the two
// spatial reference systems every GeoPackage has, plus WGS 84.
constexpr const char* kSchemaSql = R"sql(
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
)sql";

// The region's transverse Mercator CRS, under detail::kSrsId.
void insert_region_srs(detail::Database& db, const osm::RegionProjection& projection) {
  detail::Statement s(db, "INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, 'NONE', ?, ?, ?)");
  s.bind(1, std::string_view("seqloc region TM"))
      .bind(2, detail::kSrsId)
      .bind(3, detail::kSrsId)
      .bind(4, projection.wkt())
      .bind(5, projection.proj_string());
  s.run();
}

// Each table's entry in gpkg_contents: the rasters and roads with the region's extent.
void insert_contents(detail::Database& db, const RegionGrid& g) {
  detail::Statement s(db,
                      "INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, "
                      "max_x, max_y, srs_id) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)");
  auto add = [&](std::string_view table, std::string_view type, std::string_view description, bool spatial) {
    s.bind(1, table).bind(2, type).bind(3, table).bind(4, description);
    if (spatial) {
      s.bind(5, g.min_x()).bind(6, g.min_y()).bind(7, g.max_x()).bind(8, g.max_y()).bind(9, detail::kSrsId);
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

// One zoom level of kTilePx tiles at kCellM per pixel for both rasters.
void insert_tile_matrices(detail::Database& db, const RegionGrid& g) {
  detail::Statement s(db, "INSERT INTO gpkg_tile_matrix_set VALUES (?, ?, ?, ?, ?, ?)");
  detail::Statement m(db, "INSERT INTO gpkg_tile_matrix VALUES (?, 0, ?, ?, ?, ?, ?, ?)");
  for (const char* table : {"classes", "road_distance"}) {
    s.bind(1, std::string_view(table)).bind(2, detail::kSrsId).bind(3, g.min_x()).bind(4, g.min_y()).bind(5, g.max_x());
    s.bind(6, g.max_y());
    s.run();
    m.bind(1, std::string_view(table)).bind(2, g.tiles_wide()).bind(3, g.tiles_high());
    m.bind(4, std::int64_t{kTilePx}).bind(5, std::int64_t{kTilePx}).bind(6, kCellM).bind(7, kCellM);
    m.run();
  }
}

// road_distance as a gridded coverage (UInt16 centimetres), and the roads' geometry column.
void insert_coverage_and_geometry(detail::Database& db) {
  detail::Statement coverage(
      db,
      "INSERT INTO gpkg_2d_gridded_coverage_ancillary (tile_matrix_set_name, datatype, scale, offset, precision, "
      "data_null, grid_cell_encoding, uom, field_name, quantity_definition) VALUES ('road_distance', 'integer', "
      "0.01, 0.0, 0.01, ?, 'grid-value-is-area', 'm', 'road_distance', 'Distance to the nearest road cell')");
  coverage.bind(1, static_cast<double>(detail::kDistanceNull));
  coverage.run();
  detail::Statement s(db, "INSERT INTO gpkg_extensions VALUES (?, ?, 'gpkg_2d_gridded_coverage', ?, 'read-write')");
  auto add = [&](std::string_view table, const char* column) {
    s.bind(1, table);
    if (column) {
      s.bind(2, std::string_view(column));
    } else {
      s.bind_null(2);
    }
    s.bind(3, std::string_view(detail::kGriddedCoverageSpec));
    s.run();
  };
  add("gpkg_2d_gridded_coverage_ancillary", nullptr);
  add("gpkg_2d_gridded_tile_ancillary", nullptr);
  add("road_distance", "tile_data");
  detail::Statement geometry(db, "INSERT INTO gpkg_geometry_columns VALUES ('roads', 'geom', 'LINESTRING', ?, 0, 0)");
  geometry.bind(1, detail::kSrsId);
  geometry.run();
}

}  // namespace

void CacheWriter::create_schema(const osm::RegionProjection& projection) {
  auto& db = *db_;
  db.exec("PRAGMA application_id = 1196444487");  // 'GPKG'
  db.exec("PRAGMA user_version = 10200");         // GeoPackage 1.2
  db.exec("BEGIN");
  db.exec(kSchemaSql);
  insert_region_srs(db, projection);
  insert_contents(db, metadata_.grid);
  insert_tile_matrices(db, metadata_.grid);
  insert_coverage_and_geometry(db);
  write_metadata();
  db.exec("COMMIT");
}

void CacheWriter::write_metadata() {
  detail::Statement s(*db_, "INSERT OR REPLACE INTO seqloc_metadata (key, value) VALUES (?, ?)");
  for (const MetadataRow& row : metadata_rows(metadata_)) {
    s.bind(1, row.key).bind(2, row.value);
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
  if (updating_) {
    // Replaced whole, numbered from 1 again as a new cache's are.
    begin();
    db_->exec("DELETE FROM roads");
    db_->exec("DELETE FROM sqlite_sequence WHERE name = 'roads'");
  } else {
    detail::Statement count(*db_, "SELECT COUNT(*) FROM seqloc_metadata WHERE key = 'roads_written'");
    if (count.step() && count.column_int(0) > 0) return;
  }
  begin();
  detail::Statement s(*db_, "INSERT INTO roads (geom, osm_id, highway) VALUES (?, ?, ?)");
  for (const auto& road : roads) {
    if (road.points.size() < 2) continue;
    const auto blob = detail::linestring_blob(road.points);
    s.bind_blob(1, blob).bind(2, road.osm_id).bind(3, road.highway);
    s.run();
  }
  db_->exec("INSERT OR REPLACE INTO seqloc_metadata (key, value) VALUES ('roads_written', 'yes')");
  commit();
  // Tiles never read the roads back: the page cache they filled is handed back now rather than
  // staying allocated while every tile is written (allocated on top of what reading left, it would
  // keep glibc from shortening the heap beneath it).
  sqlite3_db_release_memory(db_->get());
}

void CacheWriter::write_tile(const EncodedTile& tile) {
  assert(metadata_.grid.contains_tile(tile.col, tile.row));
  begin();
  if (!insert_classes_) {
    insert_classes_ = std::make_unique<detail::Statement>(
        *db_, "INSERT OR REPLACE INTO classes (zoom_level, tile_column, tile_row, tile_data) VALUES (0, ?, ?, ?)");
    insert_distance_ = std::make_unique<detail::Statement>(
        *db_,
        "INSERT OR REPLACE INTO road_distance (zoom_level, tile_column, tile_row, tile_data) VALUES (0, ?, ?, ?)");
    insert_ancillary_ = std::make_unique<detail::Statement>(
        *db_,
        "INSERT OR REPLACE INTO gpkg_2d_gridded_tile_ancillary (tpudt_name, tpudt_id, scale, offset, min, max, "
        "mean) VALUES ('road_distance', ?, 1.0, 0.0, ?, ?, ?)");
  }
  if (updating_) forget_tile(tile.col, tile.row, tile.classes_png.empty());
  if (!tile.classes_png.empty()) {
    insert_classes_->bind(1, tile.col).bind(2, tile.row).bind_blob(3, tile.classes_png);
    insert_classes_->run();
  } else if (metadata_.corridor_m <= 0) {
    throw CacheError(partial_.string() + ": tile (" + std::to_string(tile.col) + ", " + std::to_string(tile.row) +
                     ") has no classes, but the cache is not a corridor cache");
  }
  insert_distance_->bind(1, tile.col).bind(2, tile.row).bind_blob(3, tile.distance_png);
  insert_distance_->run();
  const std::int64_t id = sqlite3_last_insert_rowid(db_->get());
  detail::Statement& ancillary = *insert_ancillary_;
  ancillary.bind(1, id).bind(2, tile.distance_min_m).bind(3, tile.distance_max_m).bind(4, tile.distance_mean_m);
  ancillary.run();
  if (!updating_) ++stored_;
  if (++pending_ >= detail::kTilesPerTransaction) commit();
}

void CacheWriter::finish() {
  commit();
  // Every tile of the shard has its road distance (classes may be left out of a corridor cache).
  // A tile is stored once (the primary key), so counting is enough; nothing is held per tile.
  std::int64_t rows = 0;
  {
    detail::Statement count(*db_, "SELECT COUNT(*) FROM road_distance");
    if (count.step()) rows = count.column_int(0);
  }
  if (rows != tiles_owned()) {
    throw CacheError(partial_.string() + ": " + std::to_string(rows) + " tiles stored, but the shard has " +
                     std::to_string(tiles_owned()) + "; the cache is not complete");
  }
  find_tile_.reset();
  insert_classes_.reset();
  insert_distance_.reset();
  insert_ancillary_.reset();
  metadata_.complete = true;
  db_->exec("BEGIN");
  write_metadata();
  db_->exec("COMMIT");
  db_->exec("PRAGMA journal_mode = DELETE");  // a finished cache is one self-contained file
  db_.reset();
  core::commit_file(partial_, final_);
}

// ---------------------------------------------------------------------------------------------
// Encoder

namespace {

// The one colour of a tile whose pixels are all the same (packed 0xRRGGBB), if they are: the
// bytes then repeat with the period of a pixel.
std::optional<std::uint32_t> uniform_colour(const std::vector<std::uint8_t>& rgb) {
  if (rgb.size() < 3 || std::memcmp(rgb.data(), rgb.data() + 3, rgb.size() - 3) != 0) return std::nullopt;
  return (std::uint32_t{rgb[0]} << 16) | (std::uint32_t{rgb[1]} << 8) | rgb[2];
}

// The key of the empty tile among the colours: outside 0xRRGGBB.
constexpr std::uint32_t kEmptyClasses = 0x1000000;

}  // namespace

EncodedTile TileEncoder::encode(std::int64_t col, std::int64_t row, const std::vector<std::uint8_t>& rgb,
                                bool classes_empty, const std::vector<std::uint16_t>& cm) {
  EncodedTile tile;
  tile.col = col;
  tile.row = row;
  // An empty tile, or one a single class covers (forest, water), is encoded once per colour.
  const std::optional<std::uint32_t> colour =
      classes_empty ? std::optional<std::uint32_t>(kEmptyClasses) : uniform_colour(rgb);
  if (colour) {
    auto& blob = uniform_classes_[*colour];
    if (blob.empty()) blob = encode_png_rgb8(rgb, kTilePx, kTilePx);
    tile.classes_png = blob;
  } else {
    tile.classes_png = encode_png_rgb8(rgb, kTilePx, kTilePx);
  }
  EncodedTile distance = encode_distance(col, row, cm);
  tile.distance_png = std::move(distance.distance_png);
  tile.distance_min_m = distance.distance_min_m;
  tile.distance_max_m = distance.distance_max_m;
  tile.distance_mean_m = distance.distance_mean_m;
  return tile;
}

EncodedTile TileEncoder::encode_distance(std::int64_t col, std::int64_t row, const std::vector<std::uint16_t>& cm) {
  EncodedTile tile;
  tile.col = col;
  tile.row = row;
  // One pass for the three statistics (integer min, max and sum vectorize).
  std::uint16_t lo = 0xffff, hi = 0;
  std::uint64_t sum = 0;
  for (const std::uint16_t v : cm) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
    sum += v;
  }
  tile.distance_min_m = lo * 0.01;
  tile.distance_max_m = hi * 0.01;
  if (lo == hi) {
    auto& blob = constant_distance_[lo];
    if (blob.empty()) blob = encode_png_gray16(cm, kTilePx, kTilePx);
    tile.distance_png = blob;
    tile.distance_mean_m = tile.distance_min_m;
  } else {
    tile.distance_png = encode_png_gray16(cm, kTilePx, kTilePx);
    tile.distance_mean_m = static_cast<double>(sum) / static_cast<double>(cm.size()) * 0.01;
  }
  return tile;
}

}  // namespace seqloc::raster
