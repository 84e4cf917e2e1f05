#pragma once
// The raster grid of a region (conventions.md section 2): 0.5 m cells, north-up rows, 512 x 512
// tiles aligned to multiples of 256 m in the region CRS.
//
// Three coordinate systems appear in this module:
// - grid metres (x east, y north) of the region CRS;
// - global pixels (U, V): U = floor(2 x), V = floor(-2 y), so V grows southward and the cell
//   (U, V) has its centre at x = (U + 0.5) / 2, y = -(V + 0.5) / 2. They do not depend on the
//   region's extent, which makes every tile's rasterization independent of how the region is cut;
// - region pixels (u, v) of the region raster whose north-west corner is (xmin, ymax).

#include <cmath>
#include <cstdint>

#include "seqloc/core/units.hpp"

namespace seqloc::raster {

using core::kCellM;  // 0.5 m, the one resolution of every raster (core/units.hpp)
inline constexpr double kPixelsPerMetre = 2.0;
inline constexpr int kTilePx = 512;
inline constexpr double kTileM = kTilePx * kCellM;

/// A cell in global pixels.
struct Pixel {
  std::int64_t u = 0;
  std::int64_t v = 0;
  friend constexpr bool operator==(Pixel, Pixel) = default;
};

/// Continuous global pixel coordinates of a point: integral at cell centres (as OrienterNet's
/// Canvas.to_uv, which subtracts half a pixel).
inline double pixel_u(double x_m) { return x_m * kPixelsPerMetre - 0.5; }
inline double pixel_v(double y_m) { return -y_m * kPixelsPerMetre - 0.5; }
inline double centre_x(std::int64_t u) { return (static_cast<double>(u) + 0.5) * kCellM; }
inline double centre_y(std::int64_t v) { return -(static_cast<double>(v) + 0.5) * kCellM; }

/// The rectangle of tiles that makes up a region: global tile indices tx in [tx0, tx1),
/// ty in [ty0, ty1); tile (tx, ty) covers x in [256 tx, 256 tx + 256), y in [256 ty, 256 ty + 256).
/// GeoPackage tile (col, row) counts from the north-west: col = tx - tx0, row = ty1 - 1 - ty.
struct RegionGrid {
  std::int64_t tx0 = 0, ty0 = 0, tx1 = 0, ty1 = 0;

  [[nodiscard]] std::int64_t tiles_wide() const { return tx1 - tx0; }
  [[nodiscard]] std::int64_t tiles_high() const { return ty1 - ty0; }
  [[nodiscard]] std::int64_t tile_count() const { return tiles_wide() * tiles_high(); }
  [[nodiscard]] std::int64_t width_px() const { return tiles_wide() * kTilePx; }
  [[nodiscard]] std::int64_t height_px() const { return tiles_high() * kTilePx; }
  [[nodiscard]] double min_x() const { return static_cast<double>(tx0) * kTileM; }
  [[nodiscard]] double max_x() const { return static_cast<double>(tx1) * kTileM; }
  [[nodiscard]] double min_y() const { return static_cast<double>(ty0) * kTileM; }
  [[nodiscard]] double max_y() const { return static_cast<double>(ty1) * kTileM; }

  /// Continuous region pixel coordinates of a point in the region CRS: integral at cell centres,
  /// (0, 0) the north-west cell.
  [[nodiscard]] double region_u(double x_m) const { return (x_m - min_x()) / kCellM - 0.5; }
  [[nodiscard]] double region_v(double y_m) const { return (max_y() - y_m) / kCellM - 0.5; }

  /// Global pixel of the region pixel (0, 0) (its north-west cell).
  [[nodiscard]] Pixel origin() const { return {tx0 * kTilePx, -ty1 * kTilePx}; }
  /// Global pixel of the north-west cell of GeoPackage tile (col, row).
  [[nodiscard]] Pixel tile_origin(std::int64_t col, std::int64_t row) const {
    return {(tx0 + col) * kTilePx, (row - ty1) * kTilePx};
  }
  [[nodiscard]] bool contains_tile(std::int64_t col, std::int64_t row) const {
    return col >= 0 && row >= 0 && col < tiles_wide() && row < tiles_high();
  }

  /// The smallest grid of whole tiles that covers [min_x, max_x] x [min_y, max_y].
  static RegionGrid covering(double min_x, double min_y, double max_x, double max_y) {
    RegionGrid g;
    g.tx0 = static_cast<std::int64_t>(std::floor(min_x / kTileM));
    g.ty0 = static_cast<std::int64_t>(std::floor(min_y / kTileM));
    g.tx1 = static_cast<std::int64_t>(std::floor(max_x / kTileM)) + 1;
    g.ty1 = static_cast<std::int64_t>(std::floor(max_y / kTileM)) + 1;
    return g;
  }
  friend constexpr bool operator==(const RegionGrid&, const RegionGrid&) = default;
};

}  // namespace seqloc::raster
