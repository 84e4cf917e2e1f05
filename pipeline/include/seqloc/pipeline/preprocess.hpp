#pragma once
// Region preprocessing: an OSM file becomes a region cache (conventions.md sections 1-3).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include "seqloc/osm/features.hpp"
#include "seqloc/pipeline/errors.hpp"

namespace seqloc::pipeline {

/// Limits on a region, so that a mistyped bbox fails at once instead of after hours. Transverse
/// Mercator keeps the scale error under 0.31 % within 500 km of the centre, hence the extent limit;
/// larger areas are cut into several regions.
inline constexpr double kMaxRegionExtentM = 1'000'000.0;
inline constexpr double kMaxClampM = 650.0;  ///< UInt16 centimetres hold up to 655.35 m

struct PreprocessOptions {
  std::filesystem::path input;
  std::filesystem::path output;
  std::optional<osm::GeoBox> bbox;  ///< default: the file header's bbox, else the data's
  double max_distance_m = 100.0;    ///< road-distance clamp
  int threads = 0;                  ///< 0: all cores
  int shard_index = 0;
  int shard_count = 1;
  bool overwrite = false;

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
  std::int64_t tiles_wide = 0, tiles_high = 0;
  std::size_t nodes = 0, lines = 0, areas = 0, roads = 0;
  std::uint64_t ways_missing_nodes = 0;
  std::size_t multipolygon_open_chains = 0;  ///< relation member chains left open (members cut)
  double read_seconds = 0;    ///< reading and classifying the OSM input (wall)
  double render_seconds = 0;  ///< rendering, encoding and writing the tiles (wall)
  double total_seconds = 0;
  /// CPU time per stage, summed over the worker threads (the writer is the calling thread).
  double classes_cpu_seconds = 0;
  double distance_cpu_seconds = 0;
  double encode_cpu_seconds = 0;
  double write_seconds = 0;
  int threads = 0;
  osm::GeoBox bbox;
  double centre_lat = 0, centre_lon = 0;
};

/// Builds the cache. `on_progress` (optional) is called from the calling thread after each tile.
/// Throws UsageError, osm::OsmError or raster::CacheError with a message naming what is wrong.
PreprocessReport preprocess_region(const PreprocessOptions& options,
                                   const std::function<void(const PreprocessProgress&)>& on_progress = {});

}  // namespace seqloc::pipeline
