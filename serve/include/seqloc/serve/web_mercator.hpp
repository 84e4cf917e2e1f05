#pragma once
// XYZ tiles in Web Mercator (EPSG:3857) for web maps (docs/serve.md): a region's layers warped
// from the region CRS by GDAL's warper (the code of gdalwarp, not a resampler of ours), at the
// zooms the 0.5 m cells support.

#include <cstdint>
#include <vector>

#include "seqloc/raster/cache.hpp"
#include "seqloc/serve/map_layers.hpp"

namespace seqloc::serve {

/// The zooms a region's XYZ tiles are served at: the highest is the one whose 256 px tiles have
/// pixels closest to the 0.5 m cells (in log scale) at the region's centre latitude; the lowest,
/// three below it, reads at most 8 x 8 cells per tile pixel.
struct WebZooms {
  int min_zoom = 0, max_zoom = 0;
};
[[nodiscard]] WebZooms web_zooms(const raster::CacheMetadata& metadata);

/// The EPSG:3857 bounds of XYZ tile (z, x, y): west, south, east, north in metres.
struct WebBounds {
  double west = 0, south = 0, east = 0, north = 0;
};
[[nodiscard]] WebBounds web_tile_bounds(int z, std::int64_t x, std::int64_t y);

/// One warped tile: the layer's bands, tile_px x tile_px, and where the region covers each pixel
/// (255) or not (0; the bands hold 0 there).
struct WebTile {
  MapBlock block;
  std::vector<std::uint8_t> covered;
};

/// Warps XYZ tile (z, x, y) of `layer`, `tile_px` pixels a side (256, or 512 for @2x): class codes
/// by nearest neighbour, distances and priors bilinearly. Throws RequestError (not found) for a
/// zoom outside web_zooms(), a tile index outside the zoom's range, or a tile that does not meet
/// the region.
[[nodiscard]] WebTile read_web_tile(raster::CacheReader& cache, MapLayer layer, int z, std::int64_t x, std::int64_t y,
                                    int tile_px, const LayerOptions& options);

}  // namespace seqloc::serve
