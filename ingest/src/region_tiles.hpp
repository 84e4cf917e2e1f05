#pragma once
// What `seqloc update` shares with preprocessing, so that the tiles it renders are preprocessing's
// to the byte: the box features are read from, and the renderer-to-cache loop (corridor decision,
// encoding, writing).

#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/tile_renderer.hpp"

namespace seqloc::ingest::detail {

/// The geographic box whose features can reach the grid's tiles (roads up to `clamp_m` outside).
[[nodiscard]] osm::GeoBox region_keep_box(const raster::RegionGrid& grid, const osm::RegionProjection& projection,
                                          double clamp_m);

/// Renders `tiles` ((col, row) of the renderer's grid) on the options' threads and writes them,
/// as preprocess_region does; adds to the report's stage times and counts.
void render_region_tiles(const raster::TileRenderer& renderer, std::vector<std::pair<std::int64_t, std::int64_t>> tiles,
                         raster::CacheWriter& writer, const PreprocessOptions& options,
                         const std::function<void(const PreprocessProgress&)>& on_progress, PreprocessReport& report);

}  // namespace seqloc::ingest::detail
