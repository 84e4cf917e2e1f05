// Reading a region cache: metadata, tiles (decoded tiles kept in an LruCache), windows stitched across tiles.
#include "seqloc/raster/cache.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "seqloc/raster/png_codec.hpp"
#include "cache_format.hpp"
#include "sqlite.hpp"

namespace seqloc::raster {

CacheMetadata read_cache_metadata(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw CacheIoError(path.string() + ": no such cache file");
  detail::Database db(path.string(), SQLITE_OPEN_READONLY);
  try {
    return detail::metadata_from_db(db);
  } catch (const CacheIoError& e) {
    throw CacheFormatError(path.string() + ": not a seqloc region cache (" + e.what() + ")");
  }
}

CacheReader::CacheReader(const std::filesystem::path& path, std::size_t lru_tiles)
    : path_(path), lru_(std::max<std::size_t>(1, lru_tiles)) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw CacheIoError(path.string() + ": no such cache file");
  db_ = std::make_unique<detail::Database>(path.string(), SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX);
  try {
    metadata_ = detail::metadata_from_db(*db_);
  } catch (const CacheIoError& e) {
    throw CacheFormatError(path.string() + ": not a seqloc region cache (" + e.what() + ")");
  }
  if (!metadata_.complete) {
    throw CacheFormatError(path.string() + ": the cache is unfinished (its build was interrupted); rerun "
                           "`seqloc preprocess` to complete it");
  }
  if (metadata_.shard_count > 1) {
    throw CacheFormatError(path.string() + ": this is shard " + std::to_string(metadata_.shard_index) + "/" +
                           std::to_string(metadata_.shard_count) + "; merge the shards with `seqloc cache merge`");
  }
  if (metadata_.corridor_m > 0) {
    far_ = std::make_shared<const std::vector<std::uint8_t>>(std::size_t{kTilePx} * kTilePx * 3, 0);
  }
}

CacheReader::~CacheReader() = default;

std::optional<std::vector<std::uint8_t>> CacheReader::stored_blob(Layer layer, std::int64_t col, std::int64_t row) {
  const char* table = layer_table(layer);
  if (!grid().contains_tile(col, row)) {
    throw CacheRangeError(path_.string() + ": tile (" + std::to_string(col) + ", " + std::to_string(row) + ") of '" +
                          table + "' is outside the region (columns 0.." + std::to_string(grid().tiles_wide() - 1) +
                          ", rows 0.." + std::to_string(grid().tiles_high() - 1) + ")");
  }
  std::lock_guard lock(mutex_);
  auto& statement = select_tile_[layer == Layer::classes ? 0 : 1];
  if (!statement) {
    statement = std::make_unique<detail::Statement>(
        *db_, std::string("SELECT tile_data FROM ") + table + " WHERE zoom_level = 0 AND tile_column = ? AND tile_row = ?");
  }
  detail::Statement& s = *statement;
  s.reset();
  s.bind(1, col).bind(2, row);
  if (!s.step()) {
    s.reset();
    return std::nullopt;
  }
  const auto blob = s.column_blob(0);
  std::vector<std::uint8_t> out(blob.begin(), blob.end());
  s.reset();
  return out;
}

void CacheReader::throw_missing_tile(Layer layer, std::int64_t col, std::int64_t row) const {
  throw CacheRangeError(path_.string() + ": tile (" + std::to_string(col) + ", " + std::to_string(row) + ") of '" +
                        layer_table(layer) + "' is missing from the cache");
}

std::vector<std::uint8_t> CacheReader::tile_blob(Layer layer, std::int64_t col, std::int64_t row) {
  if (auto stored = stored_blob(layer, col, row)) return std::move(*stored);
  if (layer != Layer::classes || !far_) throw_missing_tile(layer, col, row);
  // Classes left out as outside the corridor: the tile every reader takes them for, encoded.
  std::lock_guard lock(mutex_);
  if (far_png_.empty()) far_png_ = encode_png_rgb8(*far_, kTilePx, kTilePx);
  return far_png_;
}

bool CacheReader::has_tile(Layer layer, std::int64_t col, std::int64_t row) {
  if (!grid().contains_tile(col, row)) return false;
  std::lock_guard lock(mutex_);
  detail::Statement s(*db_, std::string("SELECT 1 FROM ") + layer_table(layer) +
                                " WHERE zoom_level = 0 AND tile_column = ? AND tile_row = ?");
  s.bind(1, col).bind(2, row);
  return s.step();
}

CacheReader::Decoded CacheReader::load(Layer layer, std::int64_t col, std::int64_t row) {
  const Key key{static_cast<int>(layer), col, row};
  {
    std::lock_guard lock(mutex_);
    if (const Decoded* hit = lru_.find(key)) {
      ++stats_.hits;
      return *hit;
    }
    ++stats_.misses;
  }
  // Fetch under the lock (one SQLite connection), decode outside it so threads decode in parallel.
  const auto blob = stored_blob(layer, col, row);
  if (!blob) {
    if (layer != Layer::classes || !far_) throw_missing_tile(layer, col, row);
    return {far_, nullptr};  // classes left out as outside the corridor
  }
  const std::string what = path_.string() + ": tile (" + std::to_string(col) + ", " + std::to_string(row) + ") of '" +
                           layer_table(layer) + "'";
  PngImage image;
  try {
    image = decode_png(*blob, what, kTilePx);
  } catch (const PngError& e) {
    throw CacheFormatError(e.what());
  }
  if (image.width != kTilePx || image.height != kTilePx) throw CacheFormatError(what + ": not 512 x 512");
  Decoded decoded;
  if (layer == Layer::classes) {
    if (image.bit_depth != 8 || image.channels < 3) throw CacheFormatError(what + ": not an 8-bit RGB tile");
    if (image.channels == 3) {
      decoded.rgb = std::make_shared<const std::vector<std::uint8_t>>(std::move(image.pixels8));
    } else {
      std::vector<std::uint8_t> rgb(static_cast<std::size_t>(kTilePx) * kTilePx * 3);
      for (std::size_t i = 0; i < rgb.size() / 3; ++i) {
        for (int c = 0; c < 3; ++c) rgb[i * 3 + c] = image.pixels8[i * static_cast<std::size_t>(image.channels) + c];
      }
      decoded.rgb = std::make_shared<const std::vector<std::uint8_t>>(std::move(rgb));
    }
  } else {
    if (image.bit_depth != 16 || image.channels != 1) throw CacheFormatError(what + ": not a 16-bit grey tile");
    decoded.cm = std::make_shared<const std::vector<std::uint16_t>>(std::move(image.pixels16));
  }
  std::lock_guard lock(mutex_);
  if (const Decoded* won = lru_.peek(key)) return *won;  // another thread decoded it meanwhile
  lru_.insert(key, decoded);
  return decoded;
}

std::shared_ptr<const std::vector<std::uint8_t>> CacheReader::classes_tile(std::int64_t col, std::int64_t row) {
  return load(Layer::classes, col, row).rgb;
}

std::shared_ptr<const std::vector<std::uint16_t>> CacheReader::distance_tile(std::int64_t col, std::int64_t row) {
  return load(Layer::road_distance, col, row).cm;
}

CacheReader::LruStats CacheReader::lru_stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

void CacheReader::check_window(std::int64_t u0, std::int64_t v0, int width, int height, bool fill_outside,
                               Layer layer) const {
  if (width <= 0 || height <= 0) throw CacheRangeError(path_.string() + ": empty window requested");
  if (fill_outside) return;
  const auto& g = grid();
  if (u0 < 0 || v0 < 0 || u0 + width > g.width_px() || v0 + height > g.height_px()) {
    auto floor_div = [](std::int64_t a) { return a >= 0 ? a / kTilePx : -((-a + kTilePx - 1) / kTilePx); };
    const std::int64_t col = u0 < 0 ? floor_div(u0) : floor_div(u0 + width - 1);
    const std::int64_t row = v0 < 0 ? floor_div(v0) : floor_div(v0 + height - 1);
    throw CacheRangeError(path_.string() + ": window at pixel (" + std::to_string(u0) + ", " + std::to_string(v0) +
                          ") size " + std::to_string(width) + " x " + std::to_string(height) + " of '" +
                          layer_table(layer) + "' reaches tile (" + std::to_string(col) + ", " + std::to_string(row) +
                          "), outside the region (" + std::to_string(g.tiles_wide()) + " x " +
                          std::to_string(g.tiles_high()) + " tiles)");
  }
}

namespace {

// Copies the part of each tile that a window covers; `fetch(col, row)` returns the tile's data,
// `fill` is written where the window leaves the region.
template <class T, class Fetch>
void stitch(const RegionGrid& grid, std::int64_t u0, std::int64_t v0, int width, int height, int channels, T fill,
            std::vector<T>& out, Fetch&& fetch) {
  out.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * static_cast<std::size_t>(channels),
             fill);
  auto floor_div = [](std::int64_t a) { return a >= 0 ? a / kTilePx : -((-a + kTilePx - 1) / kTilePx); };
  const std::int64_t c0 = std::max<std::int64_t>(0, floor_div(u0));
  const std::int64_t c1 = std::min<std::int64_t>(grid.tiles_wide() - 1, floor_div(u0 + width - 1));
  const std::int64_t r0 = std::max<std::int64_t>(0, floor_div(v0));
  const std::int64_t r1 = std::min<std::int64_t>(grid.tiles_high() - 1, floor_div(v0 + height - 1));
  for (std::int64_t row = r0; row <= r1; ++row) {
    for (std::int64_t col = c0; col <= c1; ++col) {
      const auto tile = fetch(col, row);
      const std::int64_t tu0 = col * kTilePx, tv0 = row * kTilePx;
      const std::int64_t a0 = std::max(u0, tu0), a1 = std::min(u0 + width, tu0 + kTilePx);
      const std::int64_t b0 = std::max(v0, tv0), b1 = std::min(v0 + height, tv0 + kTilePx);
      const auto n = static_cast<std::size_t>((a1 - a0) * channels);
      for (std::int64_t v = b0; v < b1; ++v) {
        const T* src = tile->data() + static_cast<std::size_t>(((v - tv0) * kTilePx + (a0 - tu0)) * channels);
        T* dst = out.data() + static_cast<std::size_t>(((v - v0) * width + (a0 - u0)) * channels);
        std::copy(src, src + n, dst);
      }
    }
  }
}

}  // namespace

void CacheReader::read_classes(std::int64_t u0, std::int64_t v0, int width, int height, std::vector<std::uint8_t>& rgb,
                               bool fill_outside) {
  check_window(u0, v0, width, height, fill_outside, Layer::classes);
  stitch<std::uint8_t>(grid(), u0, v0, width, height, 3, 0, rgb,
                       [this](std::int64_t c, std::int64_t r) { return classes_tile(c, r); });
}

void CacheReader::read_road_distance(std::int64_t u0, std::int64_t v0, int width, int height,
                                     std::vector<std::uint16_t>& cm, bool fill_outside) {
  check_window(u0, v0, width, height, fill_outside, Layer::road_distance);
  const auto clamp = static_cast<std::uint16_t>(std::lround(metadata_.max_distance_m * 100.0));
  stitch<std::uint16_t>(grid(), u0, v0, width, height, 1, clamp, cm,
                        [this](std::int64_t c, std::int64_t r) { return distance_tile(c, r); });
}

void CacheReader::read_road_distance_m(std::int64_t u0, std::int64_t v0, int width, int height,
                                       std::vector<float>& metres, bool fill_outside) {
  std::vector<std::uint16_t> cm;
  read_road_distance(u0, v0, width, height, cm, fill_outside);
  metres.resize(cm.size());
  std::transform(cm.begin(), cm.end(), metres.begin(), road_distance_metres);
}

std::vector<RoadLine> CacheReader::roads() {
  std::lock_guard lock(mutex_);
  std::vector<RoadLine> out;
  detail::Statement s(*db_, "SELECT fid, geom, osm_id, highway FROM roads ORDER BY fid");
  while (s.step()) {
    RoadLine road{s.column_int(2), s.column_text(3), {}};
    road.points = detail::parse_linestring_blob(s.column_blob(1), path_.string() + ": roads fid " + std::to_string(s.column_int(0)));
    out.push_back(std::move(road));
  }
  return out;
}

}  // namespace seqloc::raster
