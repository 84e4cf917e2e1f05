#pragma once
// Region preprocessing: an OSM file becomes a region cache (conventions.md sections 1-3).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include "seqloc/core/error.hpp"
#include "seqloc/osm/features.hpp"

namespace seqloc::ingest {

/// Limits on a region, so that a mistyped bbox fails at once instead of after hours. The region
/// CRS (Transverse Mercator) stretches distances by |k - 1|, which grows with the distance from the
/// region's central meridian: 0.1 % at about 285 km. Wider areas are cut into several regions.
inline constexpr double kMaxScaleError = 0.001;
inline constexpr double kMaxClampM = 650.0;  ///< UInt16 centimetres hold up to 655.35 m

struct PreprocessOptions {
  std::filesystem::path input;
  std::filesystem::path output;
  std::optional<osm::GeoBox> bbox;  ///< default: the file header's bbox, else the data's
  double max_distance_m = 100.0;    ///< road-distance clamp
  /// Store classes only for tiles with a cell nearer than this to a road cell, in [0, clamp]; 0
  /// stores every tile's. Road distances are stored for every tile.
  double corridor_m = 0;
  int threads = 0;  ///< 0: all cores
  int shard_index = 0;
  int shard_count = 1;
  bool overwrite = false;
  /// Rendering holds the features of one square block of this many tiles a side at a time (the
  /// tiles do not depend on it; smaller blocks hold less but store long features more often).
  int block_tiles = 32;

  /// Throws UsageError naming the field, its value and the constraint it breaks.
  void validate() const;
};

struct PreprocessProgress {
  std::int64_t tiles_done = 0;
  std::int64_t tiles_total = 0;
};

struct PreprocessReport {
  std::int64_t tiles_total = 0;    ///< tiles of this shard
  std::int64_t tiles_written = 0;  ///< rendered by this run
  std::int64_t tiles_resumed = 0;  ///< already in an interrupted build's partial file
  std::int64_t tiles_skipped = 0;  ///< of those written, farther than the corridor from every road: no classes
  std::int64_t tiles_wide = 0, tiles_high = 0;
  std::size_t nodes = 0, lines = 0, areas = 0, roads = 0;
  std::uint64_t ways_missing_nodes = 0;
  std::size_t multipolygon_open_chains = 0;  ///< relation member chains left open (members cut)
  double read_seconds = 0;                   ///< reading and classifying the OSM input (wall)
  double render_seconds = 0;                 ///< rendering, encoding and writing the tiles (wall)
  double total_seconds = 0;
  /// CPU time per stage, summed over the worker threads (the writer is the calling thread).
  double classes_cpu_seconds = 0;
  double distance_cpu_seconds = 0;
  double encode_cpu_seconds = 0;
  double write_seconds = 0;
  int threads = 0;
  /// Peak resident memory (MB) while reading, classifying, projecting and cutting the features
  /// into blocks (holds the OSM node index), and while rendering and writing (one block at a time).
  double start_mb = 0;  ///< resident memory when the call began (the program and its libraries)
  double read_peak_mb = 0;
  double render_peak_mb = 0;
  double render_start_mb = 0;       ///< resident when rendering began (what reading left allocated)
  std::uint64_t spilled_bytes = 0;  ///< the features' temporary file (one copy per block they meet)
  double scale_error = 0;           ///< the region CRS's largest |k - 1| on the grid's edge
  osm::GeoBox bbox;
  double centre_lat = 0, centre_lon = 0;
};

/// Builds the cache. `on_progress` (optional) is called from the calling thread after each tile.
/// Throws UsageError, osm::OsmError or raster::CacheError with a message naming what is wrong.
PreprocessReport preprocess_region(const PreprocessOptions& options,
                                   const std::function<void(const PreprocessProgress&)>& on_progress = {});

}  // namespace seqloc::ingest
