#pragma once
// Which tiles of a region cache an edit of the OSM data can change (issue 44's `seqloc update`):
// the tiles whose renderer bins name a feature that differs between the data before and after,
// in its old or its new geometry. A tile's pixels are a function of the features its bins name
// (raster::TileRenderer: the features whose pixel box meets the tile, roads grown by the distance
// halo), so every other tile renders to the same bytes from either state.
//
// Features are compared, not OSM objects: a way whose node moved, or a multipolygon whose member
// changed, yields a feature of different geometry under the same id, however the change file
// named it.

#include <cstdint>
#include <utility>
#include <vector>

#include "seqloc/osm/features.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::ingest {

struct ChangeFootprint {
  std::size_t features_changed = 0;  ///< features in either state without an equal one in the other
  std::vector<std::pair<std::int64_t, std::int64_t>> tiles;  ///< (col, row), sorted, of the cache's grid
};

/// The tiles of the cache described by `metadata` that the change from `before` to `after` can
/// alter, in either layer (classes, and road distance with its halo of max_distance_m).
[[nodiscard]] ChangeFootprint change_footprint(const raster::CacheMetadata& metadata, const osm::FeatureSet& before,
                                               const osm::FeatureSet& after);

}  // namespace seqloc::ingest
