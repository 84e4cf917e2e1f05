#include "seqloc/pipeline/region_catalog.hpp"

#include <algorithm>
#include <sstream>

#include "seqloc/core/error.hpp"

namespace seqloc::pipeline {
std::vector<std::filesystem::path> region_cache_files(const std::vector<std::filesystem::path>& paths) {
  std::vector<std::filesystem::path> files;
  for (const auto& path : paths) {
    std::error_code ec;
    if (!std::filesystem::is_directory(path, ec)) {
      files.push_back(path);
      continue;
    }
    std::vector<std::filesystem::path> found;
    for (const auto& entry : std::filesystem::directory_iterator(path)) {
      if (entry.is_regular_file() && entry.path().extension() == ".gpkg") found.push_back(entry.path());
    }
    if (found.empty()) throw UsageError(path.string() + ": a folder with no region cache (*.gpkg) in it");
    std::sort(found.begin(), found.end());
    files.insert(files.end(), found.begin(), found.end());
  }
  return files;
}

RegionCatalog::RegionCatalog(const std::vector<std::filesystem::path>& paths, std::size_t lru_tiles) {
  for (const auto& file : region_cache_files(paths)) {
    const std::string name = file.stem().string();
    if (std::find(names_.begin(), names_.end(), name) != names_.end()) {
      throw UsageError(file.string() + ": a second region named '" + name + "' (regions are named after their files)");
    }
    owned_.push_back(std::make_unique<raster::CacheReader>(file, lru_tiles));
    caches_.push_back(owned_.back().get());
    names_.push_back(name);
    projections_.push_back(caches_.back()->metadata().projection());
  }
  if (caches_.empty()) throw UsageError("no region cache given");
}

RegionCatalog::RegionCatalog(raster::CacheReader& cache)
    : caches_{&cache}, names_{cache.path().stem().string()}, projections_{cache.metadata().projection()} {}

double RegionCatalog::depth_m(std::size_t i, osm::GeoPoint p) const {
  const auto g = projections_[i].forward(p);
  const auto& grid = caches_[i]->grid();
  return std::min({g.x_m - grid.min_x(), grid.max_x() - g.x_m, g.y_m - grid.min_y(), grid.max_y() - g.y_m});
}

std::optional<std::size_t> RegionCatalog::locate(osm::GeoPoint p, std::optional<std::size_t> current,
                                                 double margin_m) const {
  if (current && depth_m(*current, p) >= margin_m) return current;
  std::optional<std::size_t> best;
  double best_depth = 0;
  for (std::size_t i = 0; i < size(); ++i) {
    const double d = depth_m(i, p);
    if (d >= 0 && (!best || d > best_depth)) {
      best = i;
      best_depth = d;
    }
  }
  return best;
}

std::vector<std::size_t> route_regions(const io::Route& route, const RegionCatalog& catalog, double margin_m) {
  std::vector<std::size_t> regions;
  regions.reserve(route.frames.size());
  std::optional<std::size_t> current;
  for (const io::RouteFrame& f : route.frames) {
    auto where = [&] { return (route.dir / "frames.csv").string() + ":" + std::to_string(f.line) + ": "; };
    if (catalog.size() == 1) {
      regions.push_back(0);  // one region: check_crops judges the crops
      continue;
    }
    if (!f.crop_geo) {
      throw DataError(where() + "the crop is given in region-grid coordinates (crop_x, crop_y), which belong to "
                      "one region; with several regions give crop_lat, crop_lon");
    }
    current = catalog.locate(*f.crop_geo, current, margin_m);
    if (!current) {
      std::ostringstream s;
      s.precision(9);
      s << where() << "the crop at lat " << f.crop_geo->lat_deg << ", lon " << f.crop_geo->lon_deg
        << " lies in none of the " << catalog.size() << " regions (";
      for (std::size_t i = 0; i < catalog.size(); ++i) s << (i ? ", " : "") << catalog.name(i);
      s << ")";
      throw DataError(s.str());
    }
    regions.push_back(*current);
  }
  return regions;
}

}  // namespace seqloc::pipeline
