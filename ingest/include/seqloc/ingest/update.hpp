#pragma once
// Keeping a region cache current (docs/preprocess.md, "Keeping a cache current"): an OSM change
// file applied to the cache of its base, re-rendering only the tiles the change can alter
// (change_footprint.hpp). The result equals, tile for tile and in the roads table, the cache
// `seqloc preprocess` builds from the new data over the same box.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

#include "seqloc/ingest/change_footprint.hpp"
#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/osm/changes.hpp"

namespace seqloc::ingest {

struct UpdateOptions {
  std::filesystem::path cache;    ///< a complete, unsharded cache built from `base`
  std::filesystem::path base;     ///< the OSM file the cache was built from (its SHA-256 is checked)
  std::filesystem::path changes;  ///< an OSM change file (.osc, .osc.gz, .osc.bz2)
  /// The change's replication state (osm::read_replication_state): a server's state.txt, or a
  /// sequence file. Empty: the updated cache records no replication sequence or timestamp.
  std::filesystem::path state;
  std::filesystem::path output;   ///< the updated cache; empty: `cache`, replaced
  /// Where to keep the new state of the data (.osm.pbf), the base of the next update; empty: not kept.
  std::filesystem::path new_base;
  int threads = 0;  ///< 0: all cores
  /// Throws UsageError naming the field.
  void validate() const;
};

struct UpdateReport {
  osm::ChangeSummary changes;
  std::size_t features_changed = 0;
  std::int64_t tiles_total = 0, tiles_rendered = 0;
  double apply_seconds = 0, read_seconds = 0, render_seconds = 0, total_seconds = 0;
};

/// Applies the change file and writes the updated cache whole, or nothing: the cache is left as it
/// was on any error. Throws UsageError (options), DataError (a base that is not the cache's), osm::OsmError
/// (a change file that does not apply), raster::CacheError (a cache of another format or build).
UpdateReport update_region(const UpdateOptions& options,
                           const std::function<void(const PreprocessProgress&)>& on_progress = {});

}  // namespace seqloc::ingest
