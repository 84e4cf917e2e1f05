#pragma once
// A region's Web Mercator tiles as one static file for web maps without a server
// (docs/static-maps.md): a PMTiles v3 archive (our own writer, from the specification) or an
// MBTiles 1.3 database. Each tile holds the bytes `seqloc serve` answers for the same layer,
// style, z, x and y.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "seqloc/osm/features.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/serve/map_layers.hpp"

namespace seqloc::serve {

/// The lon/lat extent of a region's raster outline (its edges are not meridians or parallels:
/// sampled along all four).
[[nodiscard]] osm::GeoBox region_geo_bounds(const raster::CacheMetadata& metadata);

enum class ArchiveFormat { pmtiles, mbtiles };

struct ArchiveOptions {
  MapLayer layer = MapLayer::classes;
  bool styled = true;  ///< the picture for people ('color', the server's default), else the data PNG ('data')
  std::optional<int> min_zoom, max_zoom;  ///< default: the server's XYZ zooms (web_zooms)
  LayerOptions layer_options;
  int threads = 1;  ///< tiles warped side by side; written in tile-id order whatever the count
  /// Called after each batch of tiles with (tiles done, tiles to do).
  std::function<void(long long, long long)> progress;
  /// PMTiles: the budget of the header and root directory (the specification's 16,384 bytes) and
  /// the entries of a leaf directory when the root alone would pass it (doubled until the root of
  /// leaves fits). Tests make them small to have leaves on a small region.
  std::size_t pmtiles_root_bytes = 16384;
  std::size_t pmtiles_leaf_entries = 4096;
};

/// What an export wrote.
struct ArchiveSummary {
  int min_zoom = 0, max_zoom = 0;
  long long tiles = 0;             ///< tiles addressed (those that meet the region)
  long long unique_tiles = 0;      ///< distinct tile contents stored
  long long tile_bytes = 0;        ///< of the stored contents
  long long file_bytes = 0;        ///< of the archive
  long long leaf_directories = 0;  ///< PMTiles only
};

/// Writes `layer`'s XYZ tiles at every zoom of the range into `path` (FILE.partial, renamed when
/// complete). Tiles go to an unnamed scratch file as they are made and the directories are written
/// at the end, so that memory holds the directory entries (a few dozen bytes a tile) and one batch
/// of tiles, whatever the region. Throws UsageError for a zoom range outside what the region
/// serves (web_zooms: the archive holds what the server answers), IoError for the file.
ArchiveSummary export_tile_archive(raster::CacheReader& cache, const ArchiveOptions& options, ArchiveFormat format,
                                   const std::filesystem::path& path);

/// The PMTiles v3 tile id of (z, x, y): the tiles of the zooms above it, then the position along
/// the zoom's Hilbert curve. Throws UsageError beyond zoom 26 or outside the zoom's tiles.
[[nodiscard]] std::uint64_t pmtiles_tile_id(int z, std::uint64_t x, std::uint64_t y);

/// One PMTiles directory entry (spec section "Entries"): run_length 0 points to a leaf directory.
struct PmtilesEntry {
  std::uint64_t tile_id = 0, offset = 0;
  std::uint32_t length = 0, run_length = 0;
};

/// A directory serialized as the specification says (the count, then each column as varints: tile
/// ids delta-encoded, run lengths, lengths, offsets as 0 when contiguous with the entry before,
/// else offset + 1), before compression.
[[nodiscard]] std::string serialize_pmtiles_directory(std::span<const PmtilesEntry> entries);

}  // namespace seqloc::serve
