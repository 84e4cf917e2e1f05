#include "seqloc/raster/crop_window.hpp"

#include <cmath>
#include <cstdio>

namespace seqloc::raster {
namespace {

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// The crop side in cells, after checking it.
int crop_cells(double size_m, double max_size_m) {
  using Kind = CropError::Kind;
  if (!std::isfinite(size_m) || size_m < kCellM) throw CropError(Kind::bad_argument, "size_m: must be at least one cell (0.5 m)");
  if (size_m > max_size_m) {
    throw CropError(Kind::bad_argument,
                    "size_m: " + number(size_m) + " m is above the limit of " + number(max_size_m) + " m");
  }
  return static_cast<int>(std::lround(size_m / kCellM));
}

bool inside(const RegionGrid& grid, double x_m, double y_m) {
  return x_m >= grid.min_x() && x_m < grid.max_x() && y_m >= grid.min_y() && y_m < grid.max_y();
}

// Region pixel coordinates are integral at cell centres: an odd side centres on the cell holding
// the point, an even side on the cell corner nearest to it (corner c lies at c - 0.5).
CropWindow window_around(const RegionGrid& grid, double x_m, double y_m, int n) {
  const double u = grid.region_u(x_m), v = grid.region_v(y_m);
  const auto centre = [n](double t) {
    return n % 2 ? static_cast<std::int64_t>(std::floor(t + 0.5)) : static_cast<std::int64_t>(std::floor(t + 1.0));
  };
  return {centre(u) - n / 2, centre(v) - n / 2, n};
}

}  // namespace

CropWindow locate_crop(const CacheReader& cache, double lat_deg, double lon_deg, double size_m, double max_size_m) {
  using Kind = CropError::Kind;
  if (!std::isfinite(lat_deg) || !std::isfinite(lon_deg) || std::abs(lat_deg) > 90 || std::abs(lon_deg) > 180) {
    throw CropError(Kind::bad_argument, "lat/lon: not a WGS84 coordinate");
  }
  const int n = crop_cells(size_m, max_size_m);
  const osm::GridPoint p = cache.metadata().projection().forward({lat_deg, lon_deg});
  if (!inside(cache.grid(), p.x_m, p.y_m)) {
    throw CropError(Kind::outside, "the point (lat " + number(lat_deg) + ", lon " + number(lon_deg) +
                                       ") is outside the region of " + cache.path().filename().string());
  }
  return window_around(cache.grid(), p.x_m, p.y_m, n);
}

CropWindow locate_crop_xy(const CacheReader& cache, double x_m, double y_m, double size_m, double max_size_m) {
  using Kind = CropError::Kind;
  if (!std::isfinite(x_m) || !std::isfinite(y_m)) throw CropError(Kind::bad_argument, "x/y: not finite");
  const int n = crop_cells(size_m, max_size_m);
  if (!inside(cache.grid(), x_m, y_m)) {
    throw CropError(Kind::outside, "the point (x " + number(x_m) + " m, y " + number(y_m) +
                                       " m) is outside the region of " + cache.path().filename().string());
  }
  return window_around(cache.grid(), x_m, y_m, n);
}

}  // namespace seqloc::raster
