#pragma once
// The preprocess report (docs/preprocess.md, "The report"): what `seqloc preprocess --report`
// writes about a run (the tiles, the features, the time and memory per stage). Its one writer and
// its one reader.

#include <cstdint>
#include <filesystem>
#include <string>

#include "seqloc/osm/features.hpp"

namespace seqloc::io {

/// A preprocessing run's figures: ingest::preprocess_region returns it, the report file holds it.
struct PreprocessReport {
  std::string output;              ///< the cache written
  double corridor_m = 0;           ///< PreprocessOptions::corridor_m
  std::int64_t tiles_total = 0;    ///< tiles of this shard
  std::int64_t tiles_written = 0;  ///< rendered by this run
  std::int64_t tiles_resumed = 0;  ///< already in an interrupted build's partial file
  std::int64_t tiles_skipped = 0;  ///< of those written, farther than the corridor from every road: no classes
  std::int64_t tiles_wide = 0, tiles_high = 0;
  std::uint64_t nodes = 0, lines = 0, areas = 0, roads = 0;
  std::uint64_t ways_missing_nodes = 0;
  std::uint64_t multipolygon_open_chains = 0;  ///< relation member chains left open (members cut)
  double read_seconds = 0;                     ///< reading and classifying the OSM input (wall)
  double render_seconds = 0;                   ///< rendering, encoding and writing the tiles (wall)
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

/// The report file's text (indented JSON, a newline at the end): {"format":
/// "seqloc-preprocess-report", "version": 1, "output", "tiles_wide", ..., "megapixels_per_layer"
/// (derived: tiles_total x 512 x 512 / 1e6), ..., "features": {"nodes", "lines", "areas",
/// "roads"}, ..., "bbox": [min_lon, min_lat, max_lon, max_lat], "centre": [lat, lon]}.
[[nodiscard]] std::string preprocess_report_json(const PreprocessReport& report);

/// Reads a report file. Throws DataError naming the file and the field that is missing or of the
/// wrong type, or the format or version that is not this one.
[[nodiscard]] PreprocessReport read_preprocess_report(const std::filesystem::path& path);

}  // namespace seqloc::io
