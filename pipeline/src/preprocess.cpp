#include "seqloc/pipeline/preprocess.hpp"

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include "seqloc/osm/reader.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/tile_renderer.hpp"
#include "stopwatch.hpp"

namespace seqloc::pipeline {
namespace {

using detail::Clock;
using detail::seconds_since;

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
    for (osm::GridPoint p : {osm::GridPoint{x, y0}, osm::GridPoint{x, y1}, osm::GridPoint{x0, y}, osm::GridPoint{x1, y}}) {
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

// The region's box (explicit, else the .osm.pbf header's, else the data's, which needs the data
// first) and its features, read once.
std::pair<osm::GeoBox, osm::FeatureSet> read_region(const PreprocessOptions& options) {
  std::optional<osm::GeoBox> bbox = options.bbox;
  if (!bbox) {
    const auto header = osm::read_osm_header(options.input);
    if (header.box && header.box->valid() && header.box->min_lon < header.box->max_lon) bbox = header.box;
  }
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

// Renders the tiles of `todo` on the options' threads while the calling thread writes them to
// the cache in the order they come; adds the stage times to the report.
void render_tiles(const raster::TileRenderer& renderer, const std::vector<std::pair<std::int64_t, std::int64_t>>& todo,
                  raster::CacheWriter& writer, const PreprocessOptions& options,
                  const std::function<void(const PreprocessProgress&)>& on_progress, PreprocessReport& report) {
  const int threads =
      options.threads > 0 ? options.threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
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
        for (std::size_t i = next++; i < todo.size(); i = next++) {
          const auto [col, row] = todo[i];
          auto t0 = Clock::now();
          const bool any_class = renderer.render_classes(col, row, scratch, rgb);
          times.classes += seconds_since(t0);
          t0 = Clock::now();
          renderer.render_road_distance(col, row, scratch, cm);
          times.distance += seconds_since(t0);
          t0 = Clock::now();
          auto tile = encoder.encode(col, row, rgb, !any_class, cm);
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
  PreprocessProgress progress{report.tiles_resumed, report.tiles_total};
  try {
    while (auto tile = queue.pop()) {
      const auto t0 = Clock::now();
      writer.write_tile(*tile);
      report.write_seconds += seconds_since(t0);
      ++report.tiles_written;
      ++progress.tiles_done;
      if (on_progress) on_progress(progress);
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

}  // namespace

PreprocessReport preprocess_region(const PreprocessOptions& options,
                                   const std::function<void(const PreprocessProgress&)>& on_progress) {
  const auto start = Clock::now();
  options.validate();
  std::error_code ec;
  if (std::filesystem::exists(options.output, ec) && !options.overwrite) {
    throw UsageError(options.output.string() + ": already exists; pass --overwrite to replace it");
  }
  const auto out_dir = options.output.has_parent_path() ? options.output.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(out_dir, ec)) {
    throw UsageError(options.output.string() + ": output directory '" + out_dir.string() + "' does not exist");
  }

  const auto [bbox, features] = read_region(options);
  const osm::GeoPoint centre = bbox.centre();
  const osm::RegionProjection projection(centre.lat_deg, centre.lon_deg);
  const raster::RegionGrid grid = grid_for(bbox, projection);
  const double width_m = grid.max_x() - grid.min_x(), height_m = grid.max_y() - grid.min_y();
  if (width_m > kMaxRegionExtentM || height_m > kMaxRegionExtentM) {
    std::ostringstream s;
    s << "bbox " << describe(bbox) << " spans " << width_m / 1000 << " x " << height_m / 1000
      << " km; a region may span at most " << kMaxRegionExtentM / 1000 << " km each way (cut it into several regions)";
    throw UsageError(s.str());
  }

  PreprocessReport report;
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
  report.read_seconds = seconds_since(start);

  raster::CacheMetadata metadata;
  metadata.source_file = options.input.filename().string();
  metadata.source_sha256 = osm::file_sha256(options.input);
  metadata.osm_replication_timestamp = features.replication_timestamp;
  metadata.centre_lat = centre.lat_deg;
  metadata.centre_lon = centre.lon_deg;
  metadata.bbox = bbox;
  metadata.max_distance_m = options.max_distance_m;
  metadata.grid = grid;
  metadata.shard_index = options.shard_index;
  metadata.shard_count = options.shard_count;

  raster::CacheWriter writer(options.output, metadata);
  const raster::RegionFeatures pixels = raster::project_features(features, projection);
  report.roads = pixels.roads.size();
  writer.write_roads(pixels.roads);
  const raster::TileRenderer renderer(pixels, grid, options.max_distance_m);

  // The tiles of this shard still to render.
  std::vector<std::pair<std::int64_t, std::int64_t>> todo;
  for (std::int64_t row = 0; row < grid.tiles_high(); ++row) {
    for (std::int64_t col = 0; col < grid.tiles_wide(); ++col) {
      if (!metadata.shard_owns(col, row)) continue;
      ++report.tiles_total;
      if (writer.has_tile(col, row)) {
        ++report.tiles_resumed;
      } else {
        todo.emplace_back(col, row);
      }
    }
  }

  const auto render_start = Clock::now();
  render_tiles(renderer, todo, writer, options, on_progress, report);
  const auto finish_start = Clock::now();
  writer.finish();
  report.write_seconds += seconds_since(finish_start);
  report.render_seconds = seconds_since(render_start);
  report.total_seconds = seconds_since(start);
  return report;
}


}  // namespace seqloc::pipeline
