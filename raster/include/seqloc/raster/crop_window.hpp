#pragma once
// Where a square crop of the region cache lies (conventions.md section 4's crop_x, crop_y): the
// one rule the HTTP service's /crop, the Python module's Cache.crop and their tests share.

#include <cstdint>
#include <stdexcept>
#include <string>

#include "seqloc/core/error.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::raster {

/// A crop that cannot be placed as asked: a bad argument, or a point outside the region.
class CropError : public Error {
 public:
  enum class Kind { bad_argument, outside };
  CropError(Kind kind, const std::string& message)
      : Error(kind == Kind::bad_argument ? ErrorCategory::usage : ErrorCategory::not_found, message), kind_(kind) {}
  [[nodiscard]] Kind kind() const { return kind_; }

 private:
  Kind kind_;
};

/// Largest crop side unless configured otherwise: 1,024 m (2,048 cells).
inline constexpr double kDefaultMaxCropM = 1024;

/// Where a crop lies: its north-west region pixel and its side in cells.
struct CropWindow {
  std::int64_t u0 = 0, v0 = 0;
  int size = 0;
};

/// The square crop of side `size_m` (rounded to whole cells) around a WGS84 point: its centre is
/// the centre of the cell holding the point (odd sides) or the cell corner nearest to it (even
/// sides), so the crop's cells are cells of the cache. Throws CropError for a size below one cell
/// or above `max_size_m`, a point that is not a coordinate (bad_argument), or a point outside the
/// region (outside).
[[nodiscard]] CropWindow locate_crop(const CacheReader& cache, double lat_deg, double lon_deg, double size_m,
                                     double max_size_m = kDefaultMaxCropM);
/// The same for a centre given in the region CRS (metres).
[[nodiscard]] CropWindow locate_crop_xy(const CacheReader& cache, double x_m, double y_m, double size_m,
                                        double max_size_m = kDefaultMaxCropM);

}  // namespace seqloc::raster
