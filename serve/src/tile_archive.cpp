// PMTiles v3 and MBTiles 1.3 archives of a region's Web Mercator tiles (tile_archive.hpp).

#include "seqloc/serve/tile_archive.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include <libdeflate.h>
#include <sqlite3.h>
#include <nlohmann/json.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/serve/web_mercator.hpp"

namespace seqloc::serve {

osm::GeoBox region_geo_bounds(const raster::CacheMetadata& m) {
  const auto projection = m.projection();
  const auto& g = m.grid;
  osm::GeoBox b{180, 90, -180, -90};
  constexpr int kSamples = 16;
  for (int i = 0; i <= kSamples; ++i) {
    const double f = static_cast<double>(i) / kSamples;
    const double x = g.min_x() + f * (g.max_x() - g.min_x()), y = g.min_y() + f * (g.max_y() - g.min_y());
    for (const osm::GridPoint p : {osm::GridPoint{x, g.min_y()}, osm::GridPoint{x, g.max_y()},
                                   osm::GridPoint{g.min_x(), y}, osm::GridPoint{g.max_x(), y}}) {
      const auto q = projection.reverse(p);
      b.min_lon = std::min(b.min_lon, q.lon_deg), b.max_lon = std::max(b.max_lon, q.lon_deg);
      b.min_lat = std::min(b.min_lat, q.lat_deg), b.max_lat = std::max(b.max_lat, q.lat_deg);
    }
  }
  return b;
}

std::uint64_t pmtiles_tile_id(int z, std::uint64_t x, std::uint64_t y) {
  if (z < 0 || z > 26) throw UsageError("PMTiles: zoom " + std::to_string(z) + " is outside 0..26");
  const std::uint64_t n = std::uint64_t{1} << z;
  if (x >= n || y >= n) {
    throw UsageError("PMTiles: tile " + std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) +
                     " is outside the zoom's tiles");
  }
  std::uint64_t before = 0;  // the tiles of zooms 0 .. z - 1: (4^z - 1) / 3
  for (int t = 0; t < z; ++t) before += std::uint64_t{1} << (2 * t);
  // The Hilbert curve's index of (x, y), quadrant by quadrant from the largest; each quadrant's
  // frame turned as the specification's reference turns it (by the quadrant's own size, so that
  // coordinates may go negative: signed arithmetic, as there).
  std::int64_t tx = static_cast<std::int64_t>(x), ty = static_cast<std::int64_t>(y);
  std::uint64_t d = 0;
  for (std::int64_t s = static_cast<std::int64_t>(n / 2); s > 0; s /= 2) {
    const std::int64_t rx = (tx & s) > 0 ? 1 : 0, ry = (ty & s) > 0 ? 1 : 0;
    d += static_cast<std::uint64_t>(s) * static_cast<std::uint64_t>(s) * static_cast<std::uint64_t>((3 * rx) ^ ry);
    if (ry == 0) {
      if (rx == 1) {
        tx = s - 1 - tx;
        ty = s - 1 - ty;
      }
      std::swap(tx, ty);
    }
  }
  return before + d;
}

namespace {

void put_varint(std::string& out, std::uint64_t v) {
  while (v >= 0x80) {
    out.push_back(static_cast<char>((v & 0x7F) | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<char>(v));
}

}  // namespace

std::string serialize_pmtiles_directory(std::span<const PmtilesEntry> entries) {
  std::string out;
  put_varint(out, entries.size());
  std::uint64_t last = 0;
  for (const auto& e : entries) {
    put_varint(out, e.tile_id - last);
    last = e.tile_id;
  }
  for (const auto& e : entries) put_varint(out, e.run_length);
  for (const auto& e : entries) put_varint(out, e.length);
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const bool contiguous = i > 0 && entries[i].offset == entries[i - 1].offset + entries[i - 1].length;
    put_varint(out, contiguous ? 0 : entries[i].offset + 1);
  }
  return out;
}

namespace {

constexpr const char* kAttribution = "Map data (c) OpenStreetMap contributors, ODbL 1.0";

std::string gzip(std::string_view bytes) {
  std::unique_ptr<libdeflate_compressor, decltype(&libdeflate_free_compressor)> c(libdeflate_alloc_compressor(9),
                                                                                  &libdeflate_free_compressor);
  if (!c) throw Error(ErrorCategory::internal, "PMTiles: cannot make a gzip compressor");
  std::string out(libdeflate_gzip_compress_bound(c.get(), bytes.size()), '\0');
  const std::size_t n = libdeflate_gzip_compress(c.get(), bytes.data(), bytes.size(), out.data(), out.size());
  if (n == 0) throw Error(ErrorCategory::internal, "PMTiles: gzip failed");
  out.resize(n);
  return out;
}

void write_all(int fd, const void* data, std::size_t size, const std::filesystem::path& path) {
  const auto* p = static_cast<const char*>(data);
  while (size > 0) {
    const ssize_t n = ::write(fd, p, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw IoError(path.string() + ": cannot write: " + std::strerror(errno));
    }
    p += n;
    size -= static_cast<std::size_t>(n);
  }
}

// The tiles of one zoom that lie under the region's lon/lat box, in PMTiles tile-id order.
struct TileKey {
  std::uint64_t id;
  int z;
  std::int64_t x, y;
};

std::vector<TileKey> tiles_under(const osm::GeoBox& box, int z) {
  const double n = std::ldexp(1.0, z);
  auto column = [n](double lon) { return std::clamp(std::floor((lon + 180.0) / 360.0 * n), 0.0, n - 1); };
  auto row = [n](double lat) {
    const double r = lat * core::kPi / 180.0;
    return std::clamp(std::floor((1 - std::asinh(std::tan(r)) / core::kPi) / 2 * n), 0.0, n - 1);
  };
  std::vector<TileKey> keys;
  for (auto y = static_cast<std::int64_t>(row(box.max_lat)); y <= static_cast<std::int64_t>(row(box.min_lat)); ++y)
    for (auto x = static_cast<std::int64_t>(column(box.min_lon)); x <= static_cast<std::int64_t>(column(box.max_lon));
         ++x) {
      keys.push_back({pmtiles_tile_id(z, static_cast<std::uint64_t>(x), static_cast<std::uint64_t>(y)), z, x, y});
    }
  std::sort(keys.begin(), keys.end(), [](const TileKey& a, const TileKey& b) { return a.id < b.id; });
  return keys;
}

// One tile as the server answers it; empty when the tile does not meet the region.
std::vector<std::uint8_t> render(raster::CacheReader& cache, const ArchiveOptions& o, const TileKey& k) {
  try {
    const WebTile tile = read_web_tile(cache, o.layer, k.z, k.x, k.y, 256, o.layer_options);
    return o.styled ? encode_styled_png(tile.block, tile.covered) : encode_data_png(tile.block);
  } catch (const RequestError& e) {
    if (e.kind() == RequestError::Kind::not_found) return {};
    throw;
  }
}

// Receives tiles in tile-id order and writes an archive.
class ArchiveSink {
 public:
  virtual ~ArchiveSink() = default;
  virtual void add(const TileKey& key, std::vector<std::uint8_t> bytes) = 0;
  /// Writes what is left and closes the file; returns its statistics.
  virtual void finish(ArchiveSummary& summary) = 0;
};

// PMTiles: tile contents to an unnamed scratch file (each distinct content once), the directory
// entries in memory; at the end the header, root directory, metadata and leaves, then the tile
// data copied from the scratch file.
class PmtilesSink : public ArchiveSink {
 public:
  PmtilesSink(std::filesystem::path partial, nlohmann::ordered_json metadata, const osm::GeoBox& bounds,
              double centre_lon, double centre_lat, int min_zoom, int max_zoom, const ArchiveOptions& options)
      : root_limit_(options.pmtiles_root_bytes - std::min(options.pmtiles_root_bytes, kHeaderBytes)),
        leaf_entries_(std::max<std::size_t>(1, options.pmtiles_leaf_entries)),
        partial_(std::move(partial)),
        metadata_(std::move(metadata)),
        bounds_(bounds),
        centre_lon_(centre_lon),
        centre_lat_(centre_lat),
        min_zoom_(min_zoom),
        max_zoom_(max_zoom) {
    scratch_ = core::open_unlinked_file(partial_.parent_path().empty() ? "." : partial_.parent_path(), ".pmtiles-data");
    if (scratch_ < 0)
      throw IoError(partial_.string() + ": cannot make a scratch file beside it: " + std::strerror(errno));
  }
  ~PmtilesSink() override {
    if (scratch_ >= 0) ::close(scratch_);
  }
  PmtilesSink(const PmtilesSink&) = delete;
  PmtilesSink& operator=(const PmtilesSink&) = delete;

  void add(const TileKey& key, std::vector<std::uint8_t> bytes) override {
    ++addressed_;
    // The same content as the entry before, on the next tile id: a longer run.
    if (!entries_.empty() && key.id == entries_.back().tile_id + entries_.back().run_length && bytes == last_) {
      ++entries_.back().run_length;
      return;
    }
    // Contents seen before (the region's empty and uniform tiles): stored once. Small contents are
    // kept to be compared whole; a large one is written again (they are seldom equal), without a
    // look-up.
    const bool small = bytes.size() <= kRememberBytes;
    const std::string_view view(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    const auto seen = small ? stored_.find(std::string(view)) : stored_.end();
    std::uint64_t offset = 0;
    if (seen != stored_.end()) {
      offset = seen->second;
    } else {
      offset = data_bytes_;
      write_all(scratch_, bytes.data(), bytes.size(), partial_);
      data_bytes_ += bytes.size();
      ++contents_;
      if (small) stored_.emplace(std::string(view), offset);
    }
    entries_.push_back({key.id, offset, static_cast<std::uint32_t>(bytes.size()), 1});
    last_ = std::move(bytes);
  }

  void finish(ArchiveSummary& summary) override {
    if (entries_.empty()) throw DataError("PMTiles: no tile of the region at the zooms asked for");
    std::string root, leaves;
    make_directories(root, leaves);
    const std::string metadata = gzip(metadata_.dump());
    // Header, root, metadata, leaves, then the tile data.
    const std::uint64_t root_at = kHeaderBytes, metadata_at = root_at + root.size(),
                        leaves_at = metadata_at + metadata.size(), data_at = leaves_at + leaves.size();
    std::string header(kHeaderBytes, '\0');
    std::memcpy(header.data(), "PMTiles", 7);
    header[7] = 3;
    std::size_t at = 8;
    for (const std::uint64_t v :
         {root_at, static_cast<std::uint64_t>(root.size()), metadata_at, static_cast<std::uint64_t>(metadata.size()),
          leaves_at, static_cast<std::uint64_t>(leaves.size()), data_at, data_bytes_, addressed_,
          static_cast<std::uint64_t>(entries_.size()), contents_}) {
      put_le(header, at, v, 8);
    }
    header[96] = 1;  // clustered: contents in tile-id order, repeats pointing back
    header[97] = 2;  // internal compression: gzip
    header[98] = 1;  // tile compression: none (PNG is compressed already)
    header[99] = 2;  // tile type: PNG
    header[100] = static_cast<char>(min_zoom_);
    header[101] = static_cast<char>(max_zoom_);
    at = 102;
    for (const double deg : {bounds_.min_lon, bounds_.min_lat, bounds_.max_lon, bounds_.max_lat}) {
      put_le(header, at, static_cast<std::uint64_t>(static_cast<std::uint32_t>(e7(deg))), 4);
    }
    header[118] = static_cast<char>(std::max(min_zoom_, max_zoom_ - 1));
    at = 119;
    for (const double deg : {centre_lon_, centre_lat_}) {
      put_le(header, at, static_cast<std::uint64_t>(static_cast<std::uint32_t>(e7(deg))), 4);
    }
    const int fd = ::open(partial_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) throw IoError(partial_.string() + ": cannot create: " + std::strerror(errno));
    try {
      for (const std::string* part : std::initializer_list<const std::string*>{&header, &root, &metadata, &leaves}) {
        write_all(fd, part->data(), part->size(), partial_);
      }
      copy_data(fd);
      if (::fsync(fd) != 0) throw IoError(partial_.string() + ": cannot flush: " + std::strerror(errno));
    } catch (...) {
      ::close(fd);
      throw;
    }
    ::close(fd);
    summary.tiles = static_cast<long long>(addressed_);
    summary.unique_tiles = static_cast<long long>(contents_);
    summary.tile_bytes = static_cast<long long>(data_bytes_);
    summary.file_bytes = static_cast<long long>(data_at + data_bytes_);
    summary.leaf_directories = leaf_count_;
  }

 private:
  static constexpr std::size_t kHeaderBytes = 127, kRememberBytes = 4096;

  static void put_le(std::string& s, std::size_t& at, std::uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) s[at++] = static_cast<char>((v >> (8 * i)) & 0xFF);
  }
  static std::int32_t e7(double deg) { return static_cast<std::int32_t>(std::lround(deg * 1e7)); }

  // The root directory alone if it fits in the first 16 KB with the header; else leaves of
  // `per_leaf` entries (4,096, doubled until the root of leaf pointers fits).
  void make_directories(std::string& root, std::string& leaves) {
    root = gzip(serialize_pmtiles_directory(entries_));
    if (root.size() <= root_limit_) return;
    for (std::size_t per_leaf = leaf_entries_;; per_leaf *= 2) {
      leaves.clear();
      std::vector<PmtilesEntry> pointers;
      for (std::size_t i = 0; i < entries_.size(); i += per_leaf) {
        const std::span<const PmtilesEntry> part(entries_.data() + i, std::min(per_leaf, entries_.size() - i));
        const std::string leaf = gzip(serialize_pmtiles_directory(part));
        pointers.push_back({part.front().tile_id, leaves.size(), static_cast<std::uint32_t>(leaf.size()), 0});
        leaves += leaf;
      }
      root = gzip(serialize_pmtiles_directory(pointers));
      if (root.size() <= root_limit_ || pointers.size() == 1) {
        leaf_count_ = static_cast<long long>(pointers.size());
        return;
      }
    }
  }

  void copy_data(int fd) {
    std::vector<char> buffer(std::size_t{1} << 20);
    std::uint64_t done = 0;
    while (done < data_bytes_) {
      const auto want = static_cast<std::size_t>(std::min<std::uint64_t>(buffer.size(), data_bytes_ - done));
      const ssize_t n = ::pread(scratch_, buffer.data(), want, static_cast<off_t>(done));
      if (n <= 0) {
        if (n < 0 && errno == EINTR) continue;
        throw IoError(partial_.string() + ": cannot read its scratch file back: " + std::strerror(errno));
      }
      write_all(fd, buffer.data(), static_cast<std::size_t>(n), partial_);
      done += static_cast<std::uint64_t>(n);
    }
  }

  std::size_t root_limit_, leaf_entries_;
  std::filesystem::path partial_;
  nlohmann::ordered_json metadata_;
  osm::GeoBox bounds_;
  double centre_lon_, centre_lat_;
  int min_zoom_, max_zoom_;
  int scratch_ = -1;
  std::vector<PmtilesEntry> entries_;
  std::vector<std::uint8_t> last_;
  std::unordered_map<std::string, std::uint64_t> stored_;
  std::uint64_t data_bytes_ = 0, addressed_ = 0, contents_ = 0;
  long long leaf_count_ = 0;
};

// MBTiles 1.3 through SQLite: the tiles table (TMS rows) and the metadata table.
class MbtilesSink : public ArchiveSink {
 public:
  MbtilesSink(std::filesystem::path partial, const nlohmann::ordered_json& metadata) : partial_(std::move(partial)) {
    std::filesystem::remove(partial_);
    if (sqlite3_open_v2(partial_.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) != SQLITE_OK) {
      const std::string why = db_ != nullptr ? sqlite3_errmsg(db_) : "out of memory";
      sqlite3_close(db_);
      db_ = nullptr;
      throw IoError(partial_.string() + ": cannot create: " + why);
    }
    exec(
        "PRAGMA journal_mode = OFF; PRAGMA synchronous = OFF; PRAGMA page_size = 4096;"
        "CREATE TABLE metadata (name TEXT, value TEXT);"
        "CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, tile_data BLOB);"
        "BEGIN;");
    sqlite3_stmt* meta = prepare("INSERT INTO metadata (name, value) VALUES (?, ?)");
    for (const auto& [name, value] : metadata.items()) {
      const std::string text = value.is_string() ? value.get<std::string>() : value.dump();
      sqlite3_bind_text(meta, 1, name.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_text(meta, 2, text.c_str(), -1, SQLITE_TRANSIENT);
      step(meta);
    }
    sqlite3_finalize(meta);
    insert_ = prepare("INSERT INTO tiles (zoom_level, tile_column, tile_row, tile_data) VALUES (?, ?, ?, ?)");
  }
  ~MbtilesSink() override {
    if (insert_ != nullptr) sqlite3_finalize(insert_);
    if (db_ != nullptr) sqlite3_close(db_);
  }
  MbtilesSink(const MbtilesSink&) = delete;
  MbtilesSink& operator=(const MbtilesSink&) = delete;

  void add(const TileKey& key, std::vector<std::uint8_t> bytes) override {
    const std::int64_t tms_row = (std::int64_t{1} << key.z) - 1 - key.y;
    sqlite3_bind_int64(insert_, 1, key.z);
    sqlite3_bind_int64(insert_, 2, key.x);
    sqlite3_bind_int64(insert_, 3, tms_row);
    sqlite3_bind_blob(insert_, 4, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT);
    step(insert_);
    ++tiles_;
    bytes_ += static_cast<long long>(bytes.size());
  }

  void finish(ArchiveSummary& summary) override {
    if (tiles_ == 0) throw DataError("MBTiles: no tile of the region at the zooms asked for");
    sqlite3_finalize(insert_);
    insert_ = nullptr;
    exec("CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row); COMMIT;");
    if (sqlite3_close(db_) != SQLITE_OK) throw IoError(partial_.string() + ": cannot close: " + sqlite3_errmsg(db_));
    db_ = nullptr;
    summary.tiles = summary.unique_tiles = tiles_;
    summary.tile_bytes = bytes_;
    summary.file_bytes = static_cast<long long>(std::filesystem::file_size(partial_));
  }

 private:
  void exec(const char* sql) {
    char* message = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
      const std::string why = message != nullptr ? message : sqlite3_errmsg(db_);
      sqlite3_free(message);
      throw IoError(partial_.string() + ": " + why);
    }
  }
  sqlite3_stmt* prepare(const char* sql) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db_, sql, -1, &s, nullptr) != SQLITE_OK)
      throw IoError(partial_.string() + ": " + sqlite3_errmsg(db_));
    return s;
  }
  void step(sqlite3_stmt* s) {
    if (sqlite3_step(s) != SQLITE_DONE) throw IoError(partial_.string() + ": cannot write: " + sqlite3_errmsg(db_));
    sqlite3_reset(s);
    sqlite3_clear_bindings(s);
  }

  std::filesystem::path partial_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* insert_ = nullptr;
  long long tiles_ = 0, bytes_ = 0;
};

nlohmann::ordered_json archive_metadata(const raster::CacheMetadata& m, const ArchiveOptions& o, const osm::GeoBox& b,
                                        int min_zoom, int max_zoom) {
  std::ostringstream bounds, centre;
  bounds.precision(9);
  centre.precision(9);
  bounds << b.min_lon << "," << b.min_lat << "," << b.max_lon << "," << b.max_lat;
  centre << m.centre_lon << "," << m.centre_lat << "," << std::max(min_zoom, max_zoom - 1);
  const std::string layer = layer_name(o.layer);
  return {{"name", layer + " of " + m.source_file},
          {"description", "seqloc region cache of " + m.source_file + ": the " + layer + " layer, style " +
                              (o.styled ? "color" : "data") + ", as `seqloc serve` answers its XYZ tiles"},
          {"attribution", kAttribution},
          {"type", "overlay"},
          {"version", "1"},
          {"format", "png"},
          {"bounds", bounds.str()},
          {"center", centre.str()},
          {"minzoom", std::to_string(min_zoom)},
          {"maxzoom", std::to_string(max_zoom)},
          {"tile_size", "256"},
          {"seqloc_layer", layer},
          {"seqloc_style", o.styled ? "color" : "data"},
          {"seqloc_source_sha256", m.source_sha256}};
}

}  // namespace

ArchiveSummary export_tile_archive(raster::CacheReader& cache, const ArchiveOptions& options, ArchiveFormat format,
                                   const std::filesystem::path& path) {
  const auto& m = cache.metadata();
  const WebZooms served = web_zooms(m);
  const int min_zoom = options.min_zoom.value_or(served.min_zoom),
            max_zoom = options.max_zoom.value_or(served.max_zoom);
  if (min_zoom > max_zoom || min_zoom < served.min_zoom || max_zoom > served.max_zoom) {
    throw UsageError("--zoom " + std::to_string(min_zoom) + "-" + std::to_string(max_zoom) +
                     ": this region's tiles are served at zooms " + std::to_string(served.min_zoom) + "-" +
                     std::to_string(served.max_zoom));
  }
  options.layer_options.validate();
  const osm::GeoBox bounds = region_geo_bounds(m);
  std::vector<TileKey> keys;
  for (int z = min_zoom; z <= max_zoom; ++z) {
    const auto zoom = tiles_under(bounds, z);
    keys.insert(keys.end(), zoom.begin(), zoom.end());
  }
  std::filesystem::path partial = path;
  partial += ".partial";
  const auto metadata = archive_metadata(m, options, bounds, min_zoom, max_zoom);
  ArchiveSummary summary;
  summary.min_zoom = min_zoom;
  summary.max_zoom = max_zoom;
  try {
    std::unique_ptr<ArchiveSink> sink;
    if (format == ArchiveFormat::pmtiles) {
      sink = std::make_unique<PmtilesSink>(partial, metadata, bounds, m.centre_lon, m.centre_lat, min_zoom, max_zoom,
                                           options);
    } else {
      sink = std::make_unique<MbtilesSink>(partial, metadata);
    }
    // Batches of tiles warped side by side, written in tile-id order.
    const std::size_t batch = static_cast<std::size_t>(std::max(1, options.threads)) * 8;
    std::vector<std::vector<std::uint8_t>> rendered(batch);
    for (std::size_t start = 0; start < keys.size(); start += batch) {
      const std::size_t count = std::min(batch, keys.size() - start);
      core::run_jobs(count, options.threads,
                     [&](std::size_t i) { rendered[i] = render(cache, options, keys[start + i]); });
      for (std::size_t i = 0; i < count; ++i) {
        if (!rendered[i].empty()) sink->add(keys[start + i], std::move(rendered[i]));
      }
      if (options.progress)
        options.progress(static_cast<long long>(start + count), static_cast<long long>(keys.size()));
    }
    sink->finish(summary);
    core::commit_file(partial, path);
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(partial, ignored);
    throw;
  }
  return summary;
}

}  // namespace seqloc::serve
