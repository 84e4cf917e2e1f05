#pragma once
// What the parts of the region cache share (cache_format.cpp: the GeoPackage's metadata and
// geometry codec; cache_writer.cpp, cache_reader.cpp, cache_merge.cpp). Private to raster.

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "seqloc/osm/projection.hpp"
#include "seqloc/raster/cache.hpp"
#include "sqlite.hpp"

namespace seqloc::raster::detail {

// The region CRS is stored under this srs_id (GeoPackage reserves none above 32767 for users;
// GDAL numbers its own custom systems from 100000).
constexpr std::int64_t kSrsId = 100000;
constexpr int kTilesPerTransaction = 32;
constexpr const char* kGriddedCoverageSpec = "http://docs.opengeospatial.org/is/17-066r1/17-066r1.html";
constexpr std::uint16_t kDistanceNull = 65535;

/// A double as text that reads back exactly (%.17g).
std::string format_double(double value);
/// The time now as an ISO 8601 UTC timestamp.
std::string now_utc();
/// The class groups of each channel as JSON (the cache's `classes` metadata).
std::string classes_json();
/// Removes a SQLite database and its -wal, -shm and -journal files, ignoring errors.
void remove_sqlite_files(const std::filesystem::path& path);
/// GeoPackage geometry blob (GeoPackage 1.2, section 2.1.3) of a 2D LineString in the region CRS.
std::vector<std::uint8_t> linestring_blob(const std::vector<osm::GridPoint>& points);
/// The reverse; throws CacheFormatError naming `where` for a blob it cannot read.
std::vector<osm::GridPoint> parse_linestring_blob(std::span<const std::uint8_t> blob, const std::string& where);
/// The seqloc_metadata table of an open cache; throws CacheFormatError when it is not one.
CacheMetadata metadata_from_db(const Database& db);

}  // namespace seqloc::raster::detail
