#pragma once
// Reads an OpenStreetMap file (.osm.pbf, .osm, .osm.gz, .osm.bz2) with libosmium and classifies
// its elements with OrienterNet's rules.

#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "seqloc/osm/errors.hpp"
#include "seqloc/osm/features.hpp"

namespace seqloc::osm {

struct ReadOptions {
  /// Drop features whose bbox lies wholly outside this box (keeps memory bounded when a small
  /// region is cut from a large file). Unset: keep everything.
  std::optional<GeoBox> keep_box;
};

/// Throws OsmInputError naming the file when it is missing, empty, truncated or corrupt.
[[nodiscard]] FeatureSet read_osm(const std::filesystem::path& input, const ReadOptions& options = {});

/// The same from bytes in memory: `format` is "pbf", "xml" or "opl"; `name` names the buffer in
/// errors. Throws OsmInputError for empty, truncated or corrupt data.
[[nodiscard]] FeatureSet read_osm_buffer(std::span<const char> data, std::string_view format, const std::string& name,
                                         const ReadOptions& options = {});

/// The header of the file only (cheap): its declared bbox, if any, and replication state.
struct OsmHeaderInfo {
  std::optional<GeoBox> box;
  std::string replication_timestamp;  ///< `osmosis_replication_timestamp`, else `timestamp`; may be empty
  std::string replication_sequence;   ///< `osmosis_replication_sequence_number`; may be empty
};
[[nodiscard]] OsmHeaderInfo read_osm_header(const std::filesystem::path& input);

/// Lower-case hex SHA-256 of a file's bytes (recorded in the cache's metadata).
[[nodiscard]] std::string file_sha256(const std::filesystem::path& path);

}  // namespace seqloc::osm
