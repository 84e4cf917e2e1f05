#include "seqloc/ingest/preprocess.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <exception>
#include <iomanip>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include "feature_blocks.hpp"
#include "peak_memory.hpp"
#include "region_tiles.hpp"
#include "seqloc/core/stopwatch.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/osm/reader.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/tile_renderer.hpp"

namespace seqloc::ingest {
namespace {

using core::Clock;
using core::seconds_since;

std::string describe(const osm::GeoBox& b) {
  std::ostringstream s;
  s.precision(9);
  s << b.min_lon << "," << b.min_lat << "," << b.max_lon << "," << b.max_lat;
  return s.str();
}

// The region's extent in grid metres: the projected bbox boundary, sampled densely because
// straight lon/lat edges are curves in Transverse Mercator.
raster::RegionGrid grid_for(const osm::GeoBox& bbox, const osm::RegionProjection& projection) {
  double min_x = 1e300, min_y = 1e300, max_x = -1e300, max_y = -1e300;
  constexpr int kSamples = 64;
  for (int i = 0; i <= kSamples; ++i) {
    const double t = static_cast<double>(i) / kSamples;
    const double lon = bbox.min_lon + t * (bbox.max_lon - bbox.min_lon);
    const double lat = bbox.min_lat + t * (bbox.max_lat - bbox.min_lat);
    for (osm::GeoPoint p : {osm::GeoPoint{bbox.min_lat, lon}, osm::GeoPoint{bbox.max_lat, lon},
                            osm::GeoPoint{lat, bbox.min_lon}, osm::GeoPoint{lat, bbox.max_lon}}) {
      const auto g = projection.forward(p);
      min_x = std::min(min_x, g.x_m);
      max_x = std::max(max_x, g.x_m);
      min_y = std::min(min_y, g.y_m);
      max_y = std::max(max_y, g.y_m);
    }
  }
  return raster::RegionGrid::covering(min_x, min_y, max_x, max_y);
}

// The geographic box to keep features from: every tile of `grid` (which reaches up to a tile
// beyond the bbox) plus the clamp (roads that far outside still set distances inside), plus a
// margin for snapping. The grown grid's boundary is sampled densely, as in grid_for.
osm::GeoBox keep_box_for(const raster::RegionGrid& grid, const osm::RegionProjection& projection, double clamp_m) {
  const double reach = clamp_m + 2.0;
  const double x0 = grid.min_x() - reach, x1 = grid.max_x() + reach;
  const double y0 = grid.min_y() - reach, y1 = grid.max_y() + reach;
  osm::GeoBox box = osm::GeoBox::empty();
  constexpr int kSamples = 64;
  for (int i = 0; i <= kSamples; ++i) {
    const double t = static_cast<double>(i) / kSamples;
    const double x = x0 + t * (x1 - x0), y = y0 + t * (y1 - y0);
    for (osm::GridPoint p :
         {osm::GridPoint{x, y0}, osm::GridPoint{x, y1}, osm::GridPoint{x0, y}, osm::GridPoint{x1, y}}) {
      box.extend(projection.reverse(p));
    }
  }
  return box;
}

// A bounded queue between the rendering workers and the single SQLite writer.
class TileQueue {
 public:
  explicit TileQueue(std::size_t capacity) : capacity_(capacity) {}

  bool push(raster::EncodedTile tile) {
    std::unique_lock lock(mutex_);
    not_full_.wait(lock, [&] { return queue_.size() < capacity_ || closed_; });
    if (closed_) return false;
    queue_.push_back(std::move(tile));
    not_empty_.notify_one();
    return true;
  }
  std::optional<raster::EncodedTile> pop() {
    std::unique_lock lock(mutex_);
    not_empty_.wait(lock, [&] { return !queue_.empty() || producers_ == 0 || closed_; });
    if (queue_.empty()) return std::nullopt;
    auto tile = std::move(queue_.front());
    queue_.pop_front();
    not_full_.notify_one();
    return tile;
  }
  void set_producers(int n) {
    std::lock_guard lock(mutex_);
    producers_ = n;
  }
  void producer_done() {
    std::lock_guard lock(mutex_);
    --producers_;
    not_empty_.notify_all();
  }
  void close() {
    std::lock_guard lock(mutex_);
    closed_ = true;
    not_full_.notify_all();
    not_empty_.notify_all();
  }

 private:
  std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable not_full_, not_empty_;
  std::deque<raster::EncodedTile> queue_;
  int producers_ = 0;
  bool closed_ = false;
};

}  // namespace

void PreprocessOptions::validate() const {
  auto fail = [](const std::string& message) { throw UsageError(message); };
  if (input.empty()) fail("input: an OSM file is required");
  if (output.empty()) fail("output: a cache path is required (-o REGION.gpkg)");
  if (!(max_distance_m > 0 && max_distance_m <= kMaxClampM)) {
    std::ostringstream s;
    s << "max_distance_m = " << max_distance_m << ": must be in (0, " << kMaxClampM
      << "] (the road distance is stored as UInt16 centimetres)";
    fail(s.str());
  }
  if (!(corridor_m >= 0 && corridor_m <= max_distance_m)) {
    std::ostringstream s;
    s << "corridor_m = " << corridor_m << ": must be in [0, max_distance_m = " << max_distance_m
      << "] (0 stores every tile; beyond the clamp the distance to the nearest road is not known)";
    fail(s.str());
  }
  if (block_tiles < 1) fail("block_tiles = " + std::to_string(block_tiles) + ": must be >= 1");
  if (threads < 0) fail("threads = " + std::to_string(threads) + ": must be >= 0 (0 = all cores)");
  if (shard_count < 1 || shard_index < 0 || shard_index >= shard_count) {
    fail("shard = " + std::to_string(shard_index) + "/" + std::to_string(shard_count) +
         ": needs 0 <= I < N (e.g. --shard 0/4)");
  }
  if (bbox) {
    const auto& b = *bbox;
    if (!(b.min_lon >= -180 && b.max_lon <= 180 && b.min_lat >= -85 && b.max_lat <= 85)) {
      fail("bbox = " + describe(b) + ": longitudes must lie in [-180, 180] and latitudes in [-85, 85]");
    }
    if (!(b.min_lon < b.max_lon && b.min_lat < b.max_lat)) {
      fail("bbox = " + describe(b) + ": must be lon0,lat0,lon1,lat1 with lon0 < lon1 and lat0 < lat1");
    }
  }
}

namespace {

double checked_scale_error(const osm::GeoBox& bbox);

// The region's box as declared before reading: --bbox, else the .osm.pbf header's; none when only
// the data can tell.
std::optional<osm::GeoBox> declared_box(const PreprocessOptions& options, const osm::OsmHeaderInfo& header) {
  if (options.bbox) return options.bbox;
  if (header.box && header.box->valid() && header.box->min_lon < header.box->max_lon) return header.box;
  return std::nullopt;
}

// The region's box (the declared one, else the data's) and its features, read once.
std::pair<osm::GeoBox, osm::FeatureSet> read_region(const PreprocessOptions& options, std::optional<osm::GeoBox> bbox) {
  osm::ReadOptions read_options;
  if (bbox) {
    const osm::GeoPoint centre = bbox->centre();
    const osm::RegionProjection projection(centre.lat_deg, centre.lon_deg);
    read_options.keep_box = keep_box_for(grid_for(*bbox, projection), projection, options.max_distance_m);
  }
  auto features = osm::read_osm(options.input, read_options);
  if (!bbox) {
    if (!features.data_box.valid()) throw UsageError(options.input.string() + ": holds no nodes, so no region");
    bbox = features.data_box;
  }
  if (!features.data_box.valid() || !features.data_box.intersects(*bbox)) {
    throw UsageError("bbox " + describe(*bbox) + " does not overlap the data of " + options.input.string() +
                     (features.data_box.valid() ? " (data bbox " + describe(features.data_box) + ")" : " (no nodes)"));
  }
  return {*bbox, std::move(features)};
}

// What the cache records of the build: its source, box, grid, options and shard.
raster::CacheMetadata metadata_for(const PreprocessOptions& options, const osm::GeoBox& bbox,
                                   const osm::OsmHeaderInfo& header) {
  const osm::GeoPoint centre = bbox.centre();
  raster::CacheMetadata metadata;
  metadata.source_file = options.input.filename().string();
  metadata.source_sha256 = osm::file_sha256(options.input);
  metadata.osm_replication_timestamp = header.replication_timestamp;
  metadata.osm_replication_sequence = header.replication_sequence;
  metadata.centre_lat = centre.lat_deg;
  metadata.centre_lon = centre.lon_deg;
  metadata.bbox = bbox;
  metadata.max_distance_m = options.max_distance_m;
  metadata.corridor_m = options.corridor_m;
  metadata.grid = grid_for(bbox, osm::RegionProjection(centre.lat_deg, centre.lon_deg));
  metadata.shard_index = options.shard_index;
  metadata.shard_count = options.shard_count;
  return metadata;
}

// A block's tiles to render: their GeoPackage (col, row) in the region, the renderer of the block
// (whose tile (0, 0) is the region's (col0, row0)).
struct BlockJob {
  const raster::TileRenderer& renderer;
  std::int64_t col0 = 0, row0 = 0;
  std::vector<std::pair<std::int64_t, std::int64_t>> tiles;
};

// Renders the tiles of `job` on the options' threads while the calling thread writes them to the
// cache in the order they come; adds the stage times to the report. Tiles farther than the
// corridor from every road keep their road distance; their classes are neither drawn nor stored.
void render_tiles(const BlockJob& job, raster::CacheWriter& writer, const PreprocessOptions& options,
                  const std::function<void(const PreprocessProgress&)>& on_progress, PreprocessReport& report) {
  const int threads = options.threads > 0 ? options.threads : core::default_threads();
  const auto corridor_cm = static_cast<std::uint16_t>(std::lround(options.corridor_m * 100.0));
  TileQueue queue(static_cast<std::size_t>(threads) * 8);
  queue.set_producers(threads);
  std::atomic<std::size_t> next{0};
  std::exception_ptr worker_error;
  std::mutex error_mutex;
  report.threads = threads;
  struct StageTimes {
    double classes = 0, distance = 0, encode = 0;
  };
  std::vector<StageTimes> stage_times(static_cast<std::size_t>(threads));
  std::vector<std::jthread> workers;
  workers.reserve(static_cast<std::size_t>(threads));
  for (int t = 0; t < threads; ++t) {
    workers.emplace_back([&, t] {
      StageTimes& times = stage_times[static_cast<std::size_t>(t)];
      try {
        raster::RenderScratch scratch;
        raster::TileEncoder encoder;
        std::vector<std::uint8_t> rgb;
        std::vector<std::uint16_t> cm;
        for (std::size_t i = next++; i < job.tiles.size(); i = next++) {
          const auto [col, row] = job.tiles[i];
          auto t0 = Clock::now();
          const bool near_road = job.renderer.render_road_distance(col - job.col0, row - job.row0, scratch, cm);
          times.distance += seconds_since(t0);
          const bool in_corridor =
              corridor_cm == 0 || (near_road && *std::min_element(cm.begin(), cm.end()) < corridor_cm);
          bool any_class = false;
          if (in_corridor) {
            t0 = Clock::now();
            any_class = job.renderer.render_classes(col - job.col0, row - job.row0, scratch, rgb);
            times.classes += seconds_since(t0);
          }
          t0 = Clock::now();
          auto tile =
              in_corridor ? encoder.encode(col, row, rgb, !any_class, cm) : encoder.encode_distance(col, row, cm);
          times.encode += seconds_since(t0);
          if (!queue.push(std::move(tile))) break;
        }
      } catch (...) {
        std::lock_guard lock(error_mutex);
        if (!worker_error) worker_error = std::current_exception();
        queue.close();
      }
      queue.producer_done();
    });
  }
  try {
    while (auto tile = queue.pop()) {
      const auto t0 = Clock::now();
      writer.write_tile(*tile);
      report.write_seconds += seconds_since(t0);
      ++report.tiles_written;
      if (tile->classes_png.empty()) ++report.tiles_skipped;
      if (on_progress) on_progress({report.tiles_resumed + report.tiles_written, report.tiles_total});
    }
  } catch (...) {
    queue.close();
    throw;  // the workers stop at their next push; jthread joins them
  }
  workers.clear();
  if (worker_error) std::rethrow_exception(worker_error);
  for (const auto& times : stage_times) {
    report.classes_cpu_seconds += times.classes;
    report.distance_cpu_seconds += times.distance;
    report.encode_cpu_seconds += times.encode;
  }
}

// The largest scale error |k - 1| of the region CRS on the grid's boundary (where it is largest:
// it grows with the distance from the central meridian).
double edge_scale_error(const raster::RegionGrid& grid, const osm::RegionProjection& projection) {
  double worst = 0;
  constexpr int kSamples = 16;
  for (int i = 0; i <= kSamples; ++i) {
    const double t = static_cast<double>(i) / kSamples;
    const double x = grid.min_x() + t * (grid.max_x() - grid.min_x());
    const double y = grid.min_y() + t * (grid.max_y() - grid.min_y());
    for (osm::GridPoint p : {osm::GridPoint{x, grid.min_y()}, osm::GridPoint{x, grid.max_y()},
                             osm::GridPoint{grid.min_x(), y}, osm::GridPoint{grid.max_x(), y}}) {
      worst = std::max(worst, std::abs(projection.scale(p) - 1.0));
    }
  }
  return worst;
}

// Refuses a region whose CRS would stretch distances by more than kMaxScaleError at the grid's
// edge; returns the scale error there.
double checked_scale_error(const osm::GeoBox& bbox) {
  const osm::GeoPoint centre = bbox.centre();
  const osm::RegionProjection projection(centre.lat_deg, centre.lon_deg);
  const raster::RegionGrid grid = grid_for(bbox, projection);
  const double scale_error = edge_scale_error(grid, projection);
  if (scale_error <= kMaxScaleError) return scale_error;
  // Transverse Mercator's error grows as x^2 / (2 R^2) with the distance x from the centre line.
  const double width_m = grid.max_x() - grid.min_x();
  const double max_width_m = 2.0 * 6'371'000.0 * std::sqrt(2.0 * kMaxScaleError);
  std::ostringstream s;
  s << std::fixed << std::setprecision(0) << "bbox " << describe(bbox) << " spans " << width_m / 1000
    << " km east-west; at the grid's edge the region CRS would stretch distances by " << std::setprecision(2)
    << scale_error * 100 << " %, beyond the " << std::setprecision(1) << kMaxScaleError * 100
    << " % that keeps the map metric. Cut it into at least " << std::setprecision(0) << std::ceil(width_m / max_width_m)
    << " regions side by side (each under about " << max_width_m / 1000 << " km east-west, any height)";
  throw UsageError(s.str());
}

// The features projected to the lattice, written to the roads table and cut into blocks (the
// geographic features and the projected ones are freed here).
std::unique_ptr<detail::FeatureBlocks> spill_features(osm::FeatureSet features, const osm::RegionProjection& projection,
                                                      const raster::RegionGrid& grid, const PreprocessOptions& options,
                                                      raster::CacheWriter& writer, PreprocessReport& report) {
  raster::RegionFeatures pixels = raster::project_features(features, projection);
  features = {};
  report.roads = pixels.roads.size();
  writer.write_roads(pixels.roads);
  pixels.roads = {};
  const auto spill_dir = options.output.has_parent_path() ? options.output.parent_path() : std::filesystem::path(".");
  auto blocks = std::make_unique<detail::FeatureBlocks>(
      pixels, grid, raster::TileRenderer::halo_for(options.max_distance_m), options.block_tiles, spill_dir);
  report.spilled_bytes = blocks->spilled_bytes();
  return blocks;
}

// Block by block (32 x 32 tiles, 8.2 km, by default), so that only one block's features and bins
// are held while rendering, whatever the region's size; the tiles the shard owns and the cache
// does not hold yet.
void render_blocks(const detail::FeatureBlocks& blocks, const raster::RegionGrid& grid,
                   const raster::CacheMetadata& metadata, raster::CacheWriter& writer, const PreprocessOptions& options,
                   const std::function<void(const PreprocessProgress&)>& on_progress, PreprocessReport& report) {
  for (std::int64_t by = 0; by < blocks.blocks_high(); ++by) {
    for (std::int64_t bx = 0; bx < blocks.blocks_wide(); ++bx) {
      const std::int64_t side = options.block_tiles, col0 = bx * side, row0 = by * side;
      std::vector<std::pair<std::int64_t, std::int64_t>> tiles;
      for (std::int64_t row = row0; row < std::min(row0 + side, grid.tiles_high()); ++row) {
        for (std::int64_t col = col0; col < std::min(col0 + side, grid.tiles_wide()); ++col) {
          if (metadata.shard_owns(col, row) && !writer.has_tile(col, row)) tiles.emplace_back(col, row);
        }
      }
      if (tiles.empty()) continue;
      const raster::RegionFeatures block_features = blocks.load(bx, by);
      const raster::TileRenderer renderer(block_features, blocks.block_grid(bx, by), options.max_distance_m);
      render_tiles(BlockJob{renderer, col0, row0, std::move(tiles)}, writer, options, on_progress, report);
      detail::release_free_memory();  // the block's features and bins
    }
  }
}

// The output may be written: it does not exist (or --overwrite), its folder does.
void check_output(const PreprocessOptions& options) {
  std::error_code ec;
  if (std::filesystem::exists(options.output, ec) && !options.overwrite) {
    throw UsageError(options.output.string() + ": already exists; pass --overwrite to replace it");
  }
  const auto out_dir = options.output.has_parent_path() ? options.output.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(out_dir, ec)) {
    throw UsageError(options.output.string() + ": output directory '" + out_dir.string() + "' does not exist");
  }
}

// The report's account of the region read: its box, grid and features.
PreprocessReport region_report(const osm::GeoBox& bbox, const raster::RegionGrid& grid,
                               const osm::FeatureSet& features) {
  PreprocessReport report;
  const osm::GeoPoint centre = bbox.centre();
  report.scale_error = checked_scale_error(bbox);
  report.bbox = bbox;
  report.centre_lat = centre.lat_deg;
  report.centre_lon = centre.lon_deg;
  report.tiles_wide = grid.tiles_wide();
  report.tiles_high = grid.tiles_high();
  report.nodes = features.points.size();
  report.lines = features.lines.size();
  report.areas = features.areas.size();
  report.ways_missing_nodes = features.ways_missing_nodes;
  report.multipolygon_open_chains = features.multipolygon_open_chains;
  return report;
}

}  // namespace

PreprocessReport preprocess_region(const PreprocessOptions& options,
                                   const std::function<void(const PreprocessProgress&)>& on_progress) {
  const auto start = Clock::now();
  const double start_mb = detail::rss_mb().value_or(0);
  options.validate();
  check_output(options);

  // The cache opens before the features are read whenever the box is declared: SQLite's
  // connection and caches are then allocated beneath reading's many small blocks instead of on top
  // of them, where they would pin the heap reading leaves (hundreds of MB long for a large region,
  // nearly all of it free): glibc cannot shorten a heap below a live block, and rendering's
  // allocations would spread over it (at 10x andorra rendering's peak was 72 MB this way against
  // 58 MB at 1x; 59 MB with the cache opened first). Not over the partial file of another build:
  // opening removes it, and it must outlive an input that then fails to read.
  const osm::OsmHeaderInfo header = osm::read_osm_header(options.input);
  const std::optional<osm::GeoBox> declared = declared_box(options, header);
  if (declared) (void)checked_scale_error(*declared);  // before reading anything
  std::optional<raster::CacheMetadata> declared_metadata;
  std::optional<raster::CacheWriter> writer;
  if (declared) {
    declared_metadata = metadata_for(options, *declared, header);
    if (!raster::CacheWriter::would_remove_partial(options.output, *declared_metadata)) {
      writer.emplace(options.output, *declared_metadata);
    }
  }
  std::pair<osm::GeoBox, osm::FeatureSet> region;
  try {
    region = read_region(options, declared);
  } catch (...) {
    if (writer) writer->discard();  // no cache for an input that cannot be read
    throw;
  }
  auto& [bbox, features] = region;
  const osm::GeoPoint centre = bbox.centre();
  const osm::RegionProjection projection(centre.lat_deg, centre.lon_deg);
  const raster::RegionGrid grid = grid_for(bbox, projection);

  PreprocessReport report = region_report(bbox, grid, features);
  report.output = options.output.string();
  report.corridor_m = options.corridor_m;
  if (!writer) {
    writer.emplace(options.output, declared_metadata ? *declared_metadata : metadata_for(options, bbox, header));
  }
  const raster::CacheMetadata& metadata = writer->metadata();

  const auto blocks = spill_features(std::move(features), projection, grid, options, *writer, report);
  report.read_seconds = seconds_since(start);
  report.start_mb = start_mb;
  report.read_peak_mb = detail::peak_rss_mb().value_or(0);
  detail::release_free_memory();  // the features' many small blocks, freed above
  detail::reset_peak_rss();
  report.render_start_mb = detail::rss_mb().value_or(0);

  const auto render_start = Clock::now();
  report.tiles_total = metadata.shard_tile_count();
  report.tiles_resumed = writer->tiles_stored();
  render_blocks(*blocks, grid, metadata, *writer, options, on_progress, report);
  const auto finish_start = Clock::now();
  writer->finish();
  report.write_seconds += seconds_since(finish_start);
  report.render_seconds = seconds_since(render_start);
  report.render_peak_mb = detail::peak_rss_mb().value_or(0);
  report.total_seconds = seconds_since(start);
  return report;
}

}  // namespace seqloc::ingest

namespace seqloc::ingest::detail {

osm::GeoBox region_keep_box(const raster::RegionGrid& grid, const osm::RegionProjection& projection, double clamp_m) {
  return keep_box_for(grid, projection, clamp_m);
}

void render_region_tiles(const raster::TileRenderer& renderer, std::vector<std::pair<std::int64_t, std::int64_t>> tiles,
                         raster::CacheWriter& writer, const PreprocessOptions& options,
                         const std::function<void(const PreprocessProgress&)>& on_progress, PreprocessReport& report) {
  render_tiles(BlockJob{renderer, 0, 0, std::move(tiles)}, writer, options, on_progress, report);
}

}  // namespace seqloc::ingest::detail
