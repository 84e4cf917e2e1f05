#include "seqloc/ingest/update.hpp"

#include <unistd.h>

#include "region_tiles.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/core/stopwatch.hpp"
#include "seqloc/osm/reader.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/tile_renderer.hpp"

namespace seqloc::ingest {
namespace {

using core::Clock;
using core::seconds_since;

// The new state of the data, in a scratch file beside the output that goes when the update ends
// (kept as `new_base` when asked for).
class ScratchFile {
 public:
  explicit ScratchFile(std::filesystem::path p) : path_(std::move(p)) {}
  ~ScratchFile() {
    std::error_code ignored;
    std::filesystem::remove(path_, ignored);
  }
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

raster::CacheMetadata updated_metadata(raster::CacheMetadata m, const UpdateOptions& o, const osm::ChangeSummary& s,
                                       const std::filesystem::path& new_data) {
  m.source_file = (o.new_base.empty() ? o.base : o.new_base).filename().string();
  m.source_sha256 = osm::file_sha256(new_data);
  // The old state's are not the new data's: without a state they are left empty, not kept.
  m.osm_replication_timestamp = s.replication.timestamp;
  m.osm_replication_sequence = s.replication.sequence;
  m.changes_applied += (m.changes_applied.empty() ? "" : "\n") + o.changes.filename().string();
  m.created_utc.clear();
  return m;
}

}  // namespace

void UpdateOptions::validate() const {
  if (cache.empty()) throw UsageError("cache: the region cache to update is required");
  if (base.empty()) throw UsageError("base: the OSM file the cache was built from is required (--base)");
  if (changes.empty()) throw UsageError("changes: an OSM change file is required (--changes)");
  if (threads < 0) throw UsageError("threads = " + std::to_string(threads) + ": must be >= 0 (0 = all cores)");
}

UpdateReport update_region(const UpdateOptions& options,
                           const std::function<void(const PreprocessProgress&)>& on_progress) {
  const auto start = Clock::now();
  options.validate();
  const std::filesystem::path output = options.output.empty() ? options.cache : options.output;
  raster::CacheMetadata metadata;
  {
    raster::CacheReader reader(options.cache);  // refuses another format version, an incomplete cache
    metadata = reader.metadata();
  }
  if (metadata.shard_count != 1) {
    throw UsageError(options.cache.string() + ": a shard of a cache; merge the shards (seqloc cache merge) first");
  }
  if (osm::file_sha256(options.base) != metadata.source_sha256) {
    throw DataError(options.base.string() + ": not the OSM file " + options.cache.string() +
                    " was built from (its SHA-256 differs from the cache's source_sha256)");
  }
  // Read before anything is written: a bad state file costs nothing.
  const osm::ReplicationState state =
      options.state.empty() ? osm::ReplicationState{} : osm::read_replication_state(options.state);
  UpdateReport report;
  const ScratchFile new_data(output.string() + ".new-" + std::to_string(::getpid()) + ".osm.pbf");
  auto t0 = Clock::now();
  report.changes = osm::apply_changes(options.base, options.changes, new_data.path(), state);
  report.apply_seconds = seconds_since(t0);

  t0 = Clock::now();
  const osm::RegionProjection projection = metadata.projection();
  osm::ReadOptions read;
  read.keep_box = detail::region_keep_box(metadata.grid, projection, metadata.max_distance_m);
  const osm::FeatureSet after = osm::read_osm(new_data.path(), read);
  const ChangeFootprint footprint = change_footprint(metadata, osm::read_osm(options.base, read), after);
  report.read_seconds = seconds_since(t0);
  report.features_changed = footprint.features_changed;
  report.tiles_total = metadata.grid.tile_count();
  report.tiles_rendered = static_cast<std::int64_t>(footprint.tiles.size());

  t0 = Clock::now();
  raster::CacheWriter writer = raster::CacheWriter::updating(
      options.cache, output, updated_metadata(metadata, options, report.changes, new_data.path()));
  raster::RegionFeatures pixels = raster::project_features(after, projection);
  writer.write_roads(pixels.roads);
  const raster::TileRenderer renderer(pixels, metadata.grid, metadata.max_distance_m);
  PreprocessOptions render_options;
  render_options.max_distance_m = metadata.max_distance_m;
  render_options.corridor_m = metadata.corridor_m;
  render_options.threads = options.threads;
  PreprocessReport render_report;
  render_report.tiles_total = report.tiles_rendered;
  try {
    detail::render_region_tiles(renderer, footprint.tiles, writer, render_options, on_progress, render_report);
    writer.finish();
  } catch (...) {
    writer.discard();
    throw;
  }
  report.render_seconds = seconds_since(t0);
  if (!options.new_base.empty()) core::commit_file(new_data.path(), options.new_base);
  report.total_seconds = seconds_since(start);
  return report;
}

}  // namespace seqloc::ingest
