#pragma once
// Region preprocessing: an OSM file becomes a region cache (conventions.md sections 1-3).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include "seqloc/core/error.hpp"
#include "seqloc/io/preprocess_report.hpp"
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

/// The run's figures (seqloc/io/preprocess_report.hpp: its fields and its file).
using PreprocessReport = io::PreprocessReport;

/// Builds the cache. `on_progress` (optional) is called from the calling thread after each tile.
/// Throws UsageError, osm::OsmError or raster::CacheError with a message naming what is wrong.
PreprocessReport preprocess_region(const PreprocessOptions& options,
                                   const std::function<void(const PreprocessProgress&)>& on_progress = {});

}  // namespace seqloc::ingest
