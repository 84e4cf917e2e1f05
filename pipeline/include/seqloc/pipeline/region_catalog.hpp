#pragma once
// Several region caches used together: a country cut into regions side by side (each with its own
// CRS, docs/preprocess.md), which `seqloc localize` and `seqloc serve` take as one. A point is
// located in the region whose grid holds it farthest from an edge; a route stays in its region
// while it is well inside it and crosses into the next one near the edge (docs/localize.md).

#include <cstddef>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "seqloc/io/route.hpp"
#include "seqloc/osm/projection.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::pipeline {

/// The cache files of `paths`: a file as it is, a folder as the `.gpkg` files in it (sorted by
/// name). Throws UsageError for a folder with none.
[[nodiscard]] std::vector<std::filesystem::path> region_cache_files(const std::vector<std::filesystem::path>& paths);

class RegionCatalog {
 public:
  /// Opens every cache given; a folder stands for the `.gpkg` files in it (sorted by name). A
  /// region is named after its file's stem; names must be unique. Throws UsageError for an empty
  /// folder or a repeated name, and raster::CacheError for a file that is not a complete cache.
  explicit RegionCatalog(const std::vector<std::filesystem::path>& paths, std::size_t lru_tiles = 64);
  /// One cache the caller owns (and keeps alive).
  explicit RegionCatalog(raster::CacheReader& cache);

  [[nodiscard]] std::size_t size() const { return caches_.size(); }
  [[nodiscard]] raster::CacheReader& cache(std::size_t i) const { return *caches_[i]; }
  [[nodiscard]] const std::string& name(std::size_t i) const { return names_[i]; }
  [[nodiscard]] const osm::RegionProjection& projection(std::size_t i) const { return projections_[i]; }

  /// How far inside region i's grid a point lies (metres to the nearest edge; negative outside).
  [[nodiscard]] double depth_m(std::size_t i, osm::GeoPoint p) const;
  /// The region of a point: `current` while the point is at least `margin_m` inside it, else the
  /// region whose grid holds it deepest; nothing when no grid holds it.
  [[nodiscard]] std::optional<std::size_t> locate(osm::GeoPoint p, std::optional<std::size_t> current,
                                                  double margin_m) const;

 private:
  std::vector<std::unique_ptr<raster::CacheReader>> owned_;
  std::vector<raster::CacheReader*> caches_;
  std::vector<std::string> names_;
  std::vector<osm::RegionProjection> projections_;
};

/// The region of each frame of a route (its crop centre), staying in a region while the crop is
/// at least `margin_m` inside it. Throws DataError "DIR/frames.csv:LINE: ..." for a crop that no
/// region holds, and for crops given in region-grid coordinates (crop_x, crop_y) with more than one
/// region (they belong to the region they were made for; give crop_lat, crop_lon).
[[nodiscard]] std::vector<std::size_t> route_regions(const io::Route& route, const RegionCatalog& catalog,
                                                     double margin_m);

}  // namespace seqloc::pipeline
