#pragma once
// The region cache (conventions.md section 3): one GeoPackage per region that GDAL and QGIS open
// as it is. Raster tables `classes` (RGB PNG tiles) and `road_distance` (2D gridded coverage,
// UInt16 PNG tiles, scale 0.01 m), vector table `roads`, and the key/value table
// `seqloc_metadata`. See docs/cache-format.md.
//
// Writing is crash-safe: a build writes `NAME.gpkg.partial` (WAL, committed in batches) and
// renames it over `NAME.gpkg` only when complete. An interrupted build resumes from the partial
// file when rerun with the same input and parameters; the previous cache is never touched.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "seqloc/core/error.hpp"
#include "seqloc/osm/features.hpp"
#include "seqloc/osm/projection.hpp"
#include "seqloc/raster/grid.hpp"
#include "seqloc/raster/lru_cache.hpp"
#include "seqloc/raster/tile_renderer.hpp"

namespace seqloc::raster {

namespace detail {
class Database;
class Statement;
}

/// Base of the cache's data and I/O errors. Messages name the file (and tile) concerned.
class CacheError : public Error {
 public:
  explicit CacheError(const std::string& message, ErrorCategory category = ErrorCategory::data)
      : Error(category, message) {}
};
/// The file cannot be opened, read or written.
class CacheIoError : public CacheError {
 public:
  explicit CacheIoError(const std::string& message) : CacheError(message, ErrorCategory::io) {}
};
/// The file is not a seqloc cache, or one of another format version.
class CacheFormatError : public CacheError {
 public:
  explicit CacheFormatError(const std::string& message) : CacheError(message) {}
};
/// A tile or window outside the cached region, or a tile missing from a cache (not_found).
class CacheRangeError : public CacheError {
 public:
  explicit CacheRangeError(const std::string& message) : CacheError(message, ErrorCategory::not_found) {}
};

/// Version of the cache layout this build reads and writes.
inline constexpr int kCacheFormatVersion = 3;

enum class Layer { classes, road_distance };
[[nodiscard]] const char* layer_table(Layer layer);

struct CacheMetadata {
  int format_version = kCacheFormatVersion;
  std::string software_version;
  std::string source_file;  ///< file name of the OSM input
  std::string source_sha256;
  std::string osm_replication_timestamp;
  /// The replication sequence number of the data (empty: not known), and the OSM change files
  /// `seqloc update` applied since the build, oldest first, one per line (empty: none).
  std::string osm_replication_sequence, changes_applied;
  double centre_lat = 0;  ///< origin of the region CRS
  double centre_lon = 0;
  osm::GeoBox bbox;  ///< the requested bbox (lon/lat)
  double max_distance_m = 100;
  /// The classes of tiles farther than this from every road cell are not stored (0: every tile's
  /// are); readers take them as background. At most max_distance_m. Road distances are complete.
  double corridor_m = 0;
  RegionGrid grid;
  int shard_index = 0;
  int shard_count = 1;
  std::string created_utc;
  bool complete = false;

  /// True when both describe the same build (source, region, parameters, format), so that tiles
  /// of one may stand for tiles of the other (resume, merge).
  [[nodiscard]] bool same_build(const CacheMetadata& other) const;
  [[nodiscard]] osm::RegionProjection projection() const { return {centre_lat, centre_lon}; }
  /// Tiles (col, row) of shard `index` of `count`: every count-th tile in row-major order.
  [[nodiscard]] bool shard_owns(std::int64_t col, std::int64_t row) const;
  /// How many tiles the shard owns.
  [[nodiscard]] std::int64_t shard_tile_count() const;
};

/// One tile of both raster layers, encoded for storage.
struct EncodedTile {
  std::int64_t col = 0;
  std::int64_t row = 0;
  std::vector<std::uint8_t> classes_png;  ///< empty: left out, outside a corridor cache's corridor
  std::vector<std::uint8_t> distance_png;
  /// Statistics of the road-distance tile in metres (the coverage's unit, after its scale).
  double distance_min_m = 0;
  double distance_max_m = 0;
  double distance_mean_m = 0;
};

class CacheWriter {
 public:
  /// Opens `final_path`.partial, resuming it when it holds the same build, else starting anew
  /// (removing a partial file of another build). Throws CacheIoError when the output directory is
  /// missing or not writable.
  CacheWriter(const std::filesystem::path& final_path, CacheMetadata metadata);
  /// A writer that changes some tiles of the complete cache `existing`: a copy of it at
  /// `final_path`.partial, whose tiles write_tile() replaces (a tile whose classes are left out
  /// loses its stored ones), whose roads write_roads() replaces, and which finish() puts in place
  /// of `final_path` (which may be `existing`) with `metadata`. The grid must be the existing one.
  [[nodiscard]] static CacheWriter updating(const std::filesystem::path& existing,
                                            const std::filesystem::path& final_path, CacheMetadata metadata);
  /// Whether a writer of `metadata` would remove the partial file there: one of another build, or
  /// one nothing can read (false when there is none, or it holds this build, which is resumed).
  [[nodiscard]] static bool would_remove_partial(const std::filesystem::path& final_path,
                                                 const CacheMetadata& metadata);
  ~CacheWriter();
  CacheWriter(const CacheWriter&) = delete;
  CacheWriter& operator=(const CacheWriter&) = delete;

  [[nodiscard]] bool resumed() const { return resumed_; }
  /// What the cache records (the grid, the shard), as given; `complete` is false until finish().
  [[nodiscard]] const CacheMetadata& metadata() const { return metadata_; }
  /// Whether the interrupted build being resumed stored this tile (false for a new build).
  [[nodiscard]] bool has_tile(std::int64_t col, std::int64_t row);
  /// Tiles stored so far, the resumed ones included.
  [[nodiscard]] std::int64_t tiles_stored() const { return stored_; }
  /// Tiles this cache's shard covers (all the grid's for an unsharded build).
  [[nodiscard]] std::int64_t tiles_owned() const;

  /// Stores the road centerlines (once; a resumed build keeps the ones it has).
  void write_roads(const std::vector<RoadLine>& roads);
  /// Stores one tile of both layers; committed in batches.
  void write_tile(const EncodedTile& tile);
  /// Checks that every tile of the shard was stored (CacheError if not), commits,
  /// marks the cache complete and renames it to its final path (replacing an older one).
  void finish();
  /// Gives the build up (the input failed before any tile was written): closes the cache and
  /// removes the partial file, unless it is an interrupted build being resumed, which stays as it
  /// was. The writer must not be used afterwards.
  void discard();

  [[nodiscard]] const std::filesystem::path& partial_path() const { return partial_; }

 private:
  struct Updating {};
  CacheWriter(const std::filesystem::path& existing, const std::filesystem::path& final_path, CacheMetadata metadata,
              Updating);
  void create_schema(const osm::RegionProjection& projection);
  void forget_tile(std::int64_t col, std::int64_t row, bool classes_too);
  void write_metadata();
  void begin();
  void commit();

  std::filesystem::path final_;
  std::filesystem::path partial_;
  CacheMetadata metadata_;
  std::unique_ptr<detail::Database> db_;
  // Prepared once, used for every tile (declared after db_: finalized before it closes).
  std::unique_ptr<detail::Statement> insert_classes_, insert_distance_, insert_ancillary_, find_tile_;
  std::int64_t stored_ = 0;
  bool resumed_ = false;
  bool updating_ = false;
  bool in_transaction_ = false;
  int pending_ = 0;
};

/// Encodes rendered tile buffers for the cache (PNG), reusing one blob for constant tiles.
class TileEncoder {
 public:
  [[nodiscard]] EncodedTile encode(std::int64_t col, std::int64_t row, const std::vector<std::uint8_t>& rgb,
                                   bool classes_empty, const std::vector<std::uint16_t>& cm);
  /// The road distance alone, for a tile whose classes a corridor cache leaves out.
  [[nodiscard]] EncodedTile encode_distance(std::int64_t col, std::int64_t row, const std::vector<std::uint16_t>& cm);

 private:
  std::unordered_map<std::uint32_t, std::vector<std::uint8_t>> uniform_classes_;  ///< by colour (0xRRGGBB), and the empty tile
  std::unordered_map<std::uint16_t, std::vector<std::uint8_t>> constant_distance_;
};

/// A road distance as the cache stores it (centimetres, UInt16) in metres: the float nearest to
/// cm / 100. Every reader of the layer converts with this.
[[nodiscard]] inline float road_distance_metres(std::uint16_t cm) { return static_cast<float>(cm * 0.01); }

class CacheReader {
 public:
  /// Opens a complete cache read-only. Throws CacheFormatError for a file that is not a seqloc
  /// cache, an unfinished one, or one of another format version.
  explicit CacheReader(const std::filesystem::path& path, std::size_t lru_tiles = 64);
  ~CacheReader();
  CacheReader(const CacheReader&) = delete;
  CacheReader& operator=(const CacheReader&) = delete;

  [[nodiscard]] const CacheMetadata& metadata() const { return metadata_; }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  [[nodiscard]] const RegionGrid& grid() const { return metadata_.grid; }

  /// Decoded tiles, shared with the LRU: RGB interleaved (512 x 512 x 3), or centimetres (512 x 512).
  [[nodiscard]] std::shared_ptr<const std::vector<std::uint8_t>> classes_tile(std::int64_t col, std::int64_t row);
  [[nodiscard]] std::shared_ptr<const std::vector<std::uint16_t>> distance_tile(std::int64_t col, std::int64_t row);
  /// The PNG of a tile: the stored one, or for classes a corridor cache left out (far from every
  /// road), the tile readers take them for: background.
  [[nodiscard]] std::vector<std::uint8_t> tile_blob(Layer layer, std::int64_t col, std::int64_t row);
  /// Whether the tile is stored (a corridor cache leaves out the classes of tiles far from roads).
  [[nodiscard]] bool has_tile(Layer layer, std::int64_t col, std::int64_t row);

  /// A window of the region raster (region pixels, north-west origin), stitched across tiles.
  /// Cells outside the region raise CacheRangeError unless `fill_outside` is set, in which case
  /// they get background (classes) or the clamp (road distance).
  void read_classes(std::int64_t u0, std::int64_t v0, int width, int height, std::vector<std::uint8_t>& rgb,
                    bool fill_outside = false);
  void read_road_distance(std::int64_t u0, std::int64_t v0, int width, int height, std::vector<std::uint16_t>& cm,
                          bool fill_outside = false);
  /// The same window in metres (road_distance_metres of each cell).
  void read_road_distance_m(std::int64_t u0, std::int64_t v0, int width, int height, std::vector<float>& metres,
                            bool fill_outside = false);

  /// The road centerlines of the cache.
  [[nodiscard]] std::vector<RoadLine> roads();

  struct LruStats {
    std::size_t hits = 0;
    std::size_t misses = 0;
  };
  [[nodiscard]] LruStats lru_stats() const;

 private:
  struct Decoded {
    std::shared_ptr<const std::vector<std::uint8_t>> rgb;
    std::shared_ptr<const std::vector<std::uint16_t>> cm;
  };
  Decoded load(Layer layer, std::int64_t col, std::int64_t row);
  /// The stored PNG, or nothing when the tile is not stored; CacheRangeError outside the grid.
  std::optional<std::vector<std::uint8_t>> stored_blob(Layer layer, std::int64_t col, std::int64_t row);
  [[noreturn]] void throw_missing_tile(Layer layer, std::int64_t col, std::int64_t row) const;
  void check_window(std::int64_t u0, std::int64_t v0, int width, int height, bool fill_outside, Layer layer) const;

  std::filesystem::path path_;
  std::unique_ptr<detail::Database> db_;
  std::unique_ptr<detail::Statement> select_tile_[2];  ///< per layer, prepared on first use
  CacheMetadata metadata_;
  mutable std::mutex mutex_;
  using Key = std::tuple<int, std::int64_t, std::int64_t>;
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      return std::hash<std::int64_t>()((std::get<1>(k) * 1000003 + std::get<2>(k)) * 4 + std::get<0>(k));
    }
  };
  LruCache<Key, Decoded, KeyHash> lru_;  ///< guarded by mutex_
  std::shared_ptr<const std::vector<std::uint8_t>> far_;  ///< classes outside the corridor: background
  std::vector<std::uint8_t> far_png_;                     ///< the same encoded, made on first use
  LruStats stats_;
};

/// Reads the metadata of any seqloc cache (complete, partial or shard) without checks beyond
/// the format; for `seqloc cache info`.
[[nodiscard]] CacheMetadata read_cache_metadata(const std::filesystem::path& path);

/// One row of `seqloc_metadata`: its key, its text as stored, and what the text holds (a number
/// is written as a decimal that reads back to the same double; the class table is JSON).
struct MetadataRow {
  enum class Kind { text, number, json };
  std::string key, value;
  Kind kind = Kind::text;
};

/// The metadata as the rows stored in `seqloc_metadata`, with the kind of each (the one list of
/// them: the writer stores them, `seqloc cache info --json` types its values by them).
[[nodiscard]] std::vector<MetadataRow> metadata_rows(const CacheMetadata& metadata);

/// Merges shards of one build into a complete cache at `out` (atomically). Throws CacheError when
/// the shards belong to different builds, overlap, or do not cover the region.
void merge_shards(const std::vector<std::filesystem::path>& shards, const std::filesystem::path& out);

}  // namespace seqloc::raster
