// The region cache's metadata and geometry codec, shared by its writer, reader and merge.
#include "seqloc/raster/cache.hpp"

#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <utility>

#include "seqloc/osm/classes.hpp"
#include "cache_format.hpp"
#include "sqlite.hpp"

namespace seqloc::raster {

namespace detail {
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
  blob.reserve(8 + 32 + 9 + 16 * points.size());
  auto put = [&blob](const void* data, std::size_t n) {
    const std::size_t at = blob.size();
    blob.resize(at + n);
    std::memcpy(blob.data() + at, data, n);
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
  // Caches written before `seqloc update` existed lack these two keys: nothing applied.
  if (const auto it = rows.find("osm_replication_sequence"); it != rows.end()) m.osm_replication_sequence = it->second;
  if (const auto it = rows.find("changes_applied"); it != rows.end()) m.changes_applied = it->second;
  m.centre_lat = number("centre_lat");
  m.centre_lon = number("centre_lon");
  m.bbox = {number("bbox_min_lon"), number("bbox_min_lat"), number("bbox_max_lon"), number("bbox_max_lat")};
  m.max_distance_m = number("max_distance_m");
  m.corridor_m = number("corridor_m");
  m.grid = {static_cast<std::int64_t>(number("tile_x0")), static_cast<std::int64_t>(number("tile_y0")),
            static_cast<std::int64_t>(number("tile_x1")), static_cast<std::int64_t>(number("tile_y1"))};
  m.shard_index = static_cast<int>(number("shard_index"));
  m.shard_count = static_cast<int>(number("shard_count"));
  m.created_utc = get("created_utc");
  m.complete = get("state") == "complete";
  if (m.grid.tiles_wide() <= 0 || m.grid.tiles_high() <= 0 || m.shard_count < 1 || m.shard_index < 0 ||
      m.shard_index >= m.shard_count || !(m.corridor_m >= 0 && m.corridor_m <= m.max_distance_m)) {
    throw CacheFormatError(db.path() + ": inconsistent metadata (tile grid or shard)");
  }
  return m;
}

}  // namespace detail

const char* layer_table(Layer layer) { return layer == Layer::classes ? "classes" : "road_distance"; }

bool CacheMetadata::same_build(const CacheMetadata& o) const {
  return format_version == o.format_version && source_sha256 == o.source_sha256 && centre_lat == o.centre_lat &&
         centre_lon == o.centre_lon && bbox.min_lon == o.bbox.min_lon && bbox.min_lat == o.bbox.min_lat &&
         bbox.max_lon == o.bbox.max_lon && bbox.max_lat == o.bbox.max_lat && max_distance_m == o.max_distance_m &&
         corridor_m == o.corridor_m && grid == o.grid;
}

bool CacheMetadata::shard_owns(std::int64_t col, std::int64_t row) const {
  return (row * grid.tiles_wide() + col) % shard_count == shard_index;
}

std::int64_t CacheMetadata::shard_tile_count() const {
  const std::int64_t n = grid.tile_count();
  return n / shard_count + (shard_index < n % shard_count ? 1 : 0);
}

std::vector<MetadataRow> metadata_rows(const CacheMetadata& m) {
  using K = MetadataRow::Kind;
  const osm::RegionProjection projection = m.projection();
  return {
      {"format", "seqloc-region-cache", K::text},
      {"format_version", std::to_string(m.format_version), K::number},
      {"software_version", m.software_version, K::text},
      {"source_file", m.source_file, K::text},
      {"source_sha256", m.source_sha256, K::text},
      {"osm_replication_timestamp", m.osm_replication_timestamp, K::text},
      {"osm_replication_sequence", m.osm_replication_sequence, K::text},
      {"changes_applied", m.changes_applied, K::text},
      {"centre_lat", detail::format_double(m.centre_lat), K::number},
      {"centre_lon", detail::format_double(m.centre_lon), K::number},
      {"bbox_min_lon", detail::format_double(m.bbox.min_lon), K::number},
      {"bbox_min_lat", detail::format_double(m.bbox.min_lat), K::number},
      {"bbox_max_lon", detail::format_double(m.bbox.max_lon), K::number},
      {"bbox_max_lat", detail::format_double(m.bbox.max_lat), K::number},
      {"max_distance_m", detail::format_double(m.max_distance_m), K::number},
      {"corridor_m", detail::format_double(m.corridor_m), K::number},
      {"cell_m", detail::format_double(kCellM), K::number},
      {"tile_px", std::to_string(kTilePx), K::number},
      {"tile_x0", std::to_string(m.grid.tx0), K::number},
      {"tile_y0", std::to_string(m.grid.ty0), K::number},
      {"tile_x1", std::to_string(m.grid.tx1), K::number},
      {"tile_y1", std::to_string(m.grid.ty1), K::number},
      {"crs_proj", projection.proj_string(), K::text},
      {"crs_wkt", projection.wkt(), K::text},
      {"classes", detail::classes_json(), K::json},
      {"shard_index", std::to_string(m.shard_index), K::number},
      {"shard_count", std::to_string(m.shard_count), K::number},
      {"created_utc", m.created_utc, K::text},
      {"state", m.complete ? "complete" : "building", K::text},
      {"attribution", "Map data (c) OpenStreetMap contributors, ODbL 1.0 (https://www.openstreetmap.org/copyright)",
       K::text},
  };
}

}  // namespace seqloc::raster
